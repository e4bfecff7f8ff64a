"""The MPC's own measured window, when the robust controller's leaves it short of its specifications.

``hil commission`` designs the robust controller first (``design robust --weights auto --past auto``
keeps the window that reaches the most aggressive weights *of the robust law*) and then the MPC on
that window, since the MPC's fall-back law must be a robust design on the same measured state. On
random-19 (artefact-free models) the robust search kept the one-sample window (scale
4.33; 4.03 with two samples), where no MPC weights meet the specifications: the MPC's search relaxed
the delay reserve to 0 s and the disk margin to 0.45, chose scale 0.62, and that MPC held 6 of 15
HIL cells within the commissioning bounds (worst 1.78x the oracle). With a window of three samples the MPC
meets every specification at scale 2.27.

So when the MPC's automatic weights relaxed a specification, the recipe searches them again with the
other windows of :data:`WINDOWS` (the MPC's search alone: 10-40 s each), keeps the window with the
fewest relaxed specifications, then the largest scale, then the shortest (:func:`best_window`, the
rule of the robust design's own window choice), designs a robust law on that window as the MPC's
fall-back only (``controllers/windows/robust-past<W>.json``; the robust controller keeps its own
window) and designs the MPC there with it. Every search is recorded (``window_search`` of the MPC's
design in ``result.json``, and the report). When the MPC relaxed nothing, nothing of this runs.
"""

from __future__ import annotations

from pathlib import Path

from design.core.limits import MAX_FILE_BYTES
from autosteer.checks import finite, positive
from autosteer.bounded import read_json
from typing import Callable, Sequence

#: Measured windows (samples of past outputs and commands) the MPC's weights are searched with.
WINDOWS = (1, 2, 3)

Run = Callable[[str, str, Callable[[], object]], object | None]
#: ``mpc_design(fallback, past, out)``: designs the MPC with automatic weights on that window, with the robust law
#: of ``fallback`` as its fall-back (``None``: none, the weights search alone), writes it to ``out`` and returns its
#: record (``file``, ``result``, ``settings``: :class:`hil.commissioning.designs.Designer`); raises when no
#: design is found.
MPCDesigner = Callable[[Path | None, int, Path], dict]
#: ``robust_design(past, out)``: the robust law on that window, written to ``out``; its record, or raises.
RobustDesigner = Callable[[int, Path], dict]


def auto_record(path: str | Path) -> tuple[int, list[str], float]:
    """The measured window, the relaxed specifications and the chosen scale of an MPC file's automatic weights.

    Raises
    ------
    ValueError
        The file has no valid record of automatic weights (designed with explicit weights, or damaged).
    """
    body = read_json(path, MAX_FILE_BYTES, "controller file", ValueError)
    try:
        past = body["estimator"]["past"]
        aw = body["design"]["auto_weights"]
        relaxed, scale = aw["relaxed"], aw["chosen_scale"]
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{path}: no record of automatic weights ({exc})") from None
    finite(past, f"{path}: measured window", lo=1, hi=40, integer=True, unit="samples", error=ValueError)
    if not isinstance(relaxed, list) or not all(isinstance(r, str) for r in relaxed):
        raise ValueError(f"{path}: relaxed specifications must be a list of text, got {relaxed!r}")
    positive(scale, f"{path}: chosen scale", error=ValueError)
    return past, list(relaxed), float(scale)


def best_window(tries: Sequence[dict]) -> int | None:
    """The window of the try with the fewest relaxed specifications, then the largest scale, then the
    shortest window; ``None`` when every try failed (``{"past": W, "error": ...}``)."""
    done = [t for t in tries if "error" not in t]
    if not done:
        return None
    return min(done, key=lambda t: (len(t["relaxed"]), -t["scale"], t["past"]))["past"]


def own_window(run: Run, mpc_design: MPCDesigner, robust_design: RobustDesigner, current: Path, work: Path,
               windows: Sequence[int] = WINDOWS) -> dict:
    """Search the MPC's weights on the other windows and redesign it on the best one (module docstring).

    Parameters
    ----------
    run
        Runs one named step and returns its value, or ``None`` if it failed (the recipe's step runner).
    mpc_design, robust_design
        Design the MPC and the robust law on a window (:data:`MPCDesigner`, :data:`RobustDesigner`).
    current
        The MPC file designed on the robust controller's window; replaced only by a successful design.
    work
        Folder of the searches' files.
    windows
        Windows tried (samples).

    Returns
    -------
    dict
        ``tries`` (per window: ``past``, ``relaxed``, ``scale`` or ``error``), ``kept`` (the MPC's window
        now), and when it changed ``fallback`` (the fall-back's file), ``result`` and ``settings`` of the
        MPC's design; ``note`` when a better window was found but its designs failed.
    """
    past, relaxed, scale = auto_record(current)
    tries: list[dict] = [{"past": past, "relaxed": relaxed, "scale": scale}]
    rec: dict = {"tries": tries, "kept": past, "windows": list(windows)}
    if not relaxed:
        return rec
    tries += search_windows(run, mpc_design, past, work, windows, "mpc",
                            "", f" (with {past} it relaxed {'; '.join(relaxed)})")
    best = best_window(tries)
    if best is None or best == past:
        return rec
    return {**rec, **redesign_on(run, mpc_design, robust_design, current, work, best, "suits the MPC better")}


def search_windows(run: Run, mpc_design: MPCDesigner, past: int, work: Path,
                   windows: Sequence[int], name: str, label: str, why: str) -> list[dict]:
    """The MPC's weights searched alone (no fall-back) on each of ``windows`` but ``past``, into
    ``work/<name>-past<W>.json``; per window ``past``, ``relaxed``, ``scale`` and ``file``, or ``error``.
    ``label`` and ``why`` complete each step's name and description."""
    tries: list[dict] = []
    for w in windows:
        if w == past:
            continue
        out = work / f"{name}-past{w}.json"
        if run(f"design mpc (window {w}{label})", f"design mpc with a window of {w} samples{why}",
               lambda w=w, out=out: mpc_design(None, w, out)) is None:
            tries.append({"past": w, "error": "design failed (see its step)"})
            continue
        _, rel, sc = auto_record(out)
        tries.append({"past": w, "relaxed": rel, "scale": sc, "file": out.name})
    return tries


def redesign_on(run: Run, mpc_design: MPCDesigner, robust_design: RobustDesigner, current: Path, work: Path,
                window: int, why: str) -> dict:
    """A robust law on ``window`` as the MPC's fall-back (``work/robust-past<W>.json``), then the MPC there with it,
    written over ``current``.

    Returns
    -------
    dict
        ``kept`` (the window), ``fallback``, ``result`` and ``settings`` of the MPC's design; or ``note`` (why
        ``current`` was left as it was: "window W <why>, but ...").
    """
    fallback = work / f"robust-past{window}.json"
    if run(f"design robust (window {window}, the MPC's fall-back)", f"design robust with a window of {window} "
           "samples, the MPC's fall-back law", lambda: robust_design(window, fallback)) is None:
        return {"note": f"window {window} {why}, but no robust fall-back law was found there"}
    rec = run(f"design mpc (window {window})", f"design mpc with a window of {window} samples and that fall-back",
              lambda: mpc_design(fallback, window, current))
    if rec is None:
        return {"note": f"window {window} {why}, but its design with the fall-back failed"}
    return {"kept": window, "fallback": str(fallback), "result": rec["result"], "settings": rec["settings"]}
