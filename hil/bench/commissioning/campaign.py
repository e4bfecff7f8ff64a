"""Many tractors commissioned one after the other (the commissioning acceptance): ``hil commission-campaign``.

Every tractor is commissioned by :func:`hil.bench.commissioning.recipe.commission` under ``OUT/<tractor>/``;
after each tractor the aggregate (``campaign.json``, ``campaign.md``, ``campaign_ratios.png``,
:mod:`hil.bench.commissioning.campaign_report`) is written again, so the results come as they are made.

* **Resume**: a tractor whose ``result.json`` is complete (it parses, every field read is valid, and
  it was made for the same tractor and the same options) is not redone; anything else is redone.
* **Failures**: a tractor whose recipe raises is recorded with its reason (``failure.json`` and
  the aggregate), never dropped, and the campaign goes on; it is redone on resume. A tractor whose
  recipe ran but produced no robust controller or no MPC is a result, with the failed step's error
  as its reason.
* **Code**: every tractor records the commit of the code that made it (``campaign_code.json``); the
  aggregate lists the commits, so numbers of two commits are never read as one campaign.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Callable, Sequence

from identification.outputs import check_name

from autosteer.bounded import read_json
from identification.outputs import atomic_write
from hil.bench.commissioning.campaign_report import summarise_tractor, write_campaign_report
from hil.bench.commissioning.recipe import CommissionOptions, commission, options_dict
from hil.bench.commissioning.table import CONTROLLERS
from hil.errors import SimulatorConfigError
from hil.truth.conditions import IMPLEMENTS
from hil.truth.tractors import Tractor

__all__ = ["commission_campaign", "load_result", "code_version"]

_ROW_KEYS = {"implement": str, "speed": float, "controller": str, "disengagements": int, "passes": int}


def code_version() -> dict:
    """The commit of the code running (``git rev-parse HEAD`` where this package lives), and whether
    files tracked by git differ from it (``dirty``); ``"unknown"`` outside a git checkout."""
    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=20, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=20, check=True).stdout.strip() != ""
    except (OSError, subprocess.SubprocessError):
        return {"commit": "unknown", "dirty": None}
    return {"commit": sha, "dirty": dirty}


def _number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_rows(rows: object) -> None:
    if not isinstance(rows, list):
        raise SimulatorConfigError(f"'hil' must be a list of rows, got {type(rows).__name__}")
    for i, r in enumerate(rows):
        if not isinstance(r, dict):
            raise SimulatorConfigError(f"hil row {i}: expected an object, got {type(r).__name__}")
        for key, kind in _ROW_KEYS.items():
            v = r.get(key)
            ok = _number(v) if kind is float else isinstance(v, kind) and not isinstance(v, bool)
            if not ok:
                raise SimulatorConfigError(f"hil row {i}: {key} must be {kind.__name__}, got {v!r}")
        if r["implement"] not in IMPLEMENTS or r["controller"] not in CONTROLLERS:
            raise SimulatorConfigError(f"hil row {i}: unknown implement or controller "
                                       f"({r['implement']!r}, {r['controller']!r})")
        if not (0.5 <= r["speed"] <= 6.0) or r["disengagements"] < 0 or r["passes"] < 1:
            raise SimulatorConfigError(f"hil row {i}: speed 0.5-6 m/s, counts >= 0 expected, got {r!r}"[:300])
        for key in ("sigma_m", "bias_m", "max_abs_cross_track_m"):
            if key in r and not (r[key] is None or _number(r[key])):
                raise SimulatorConfigError(f"hil row {i}: {key} must be a number, got {r[key]!r}")
        why = r.get("disengage_reasons", {})
        if not (isinstance(why, dict) and all(isinstance(k, str) and isinstance(n, int) and not isinstance(n, bool)
                                              and n >= 0 for k, n in why.items())):
            raise SimulatorConfigError(f"hil row {i}: disengage_reasons must map reasons to counts, got {why!r}"[:300])
        if not (isinstance(r.get("diverging"), int) and not isinstance(r["diverging"], bool) and r["diverging"] >= 0):
            raise SimulatorConfigError(f"hil row {i}: diverging must be a count >= 0, got {r.get('diverging')!r} "
                                       "(a result.json older than the diverging count: redo it)")


def _check_steps(steps: object) -> None:
    if not isinstance(steps, list) or not steps:
        raise SimulatorConfigError("'steps' must be a non-empty list")
    for i, s in enumerate(steps):
        if not (isinstance(s, dict) and isinstance(s.get("step"), str) and isinstance(s.get("ok"), bool)
                and _number(s.get("seconds")) and (s["ok"] or isinstance(s.get("error"), str))):
            raise SimulatorConfigError(f"step {i}: expected step (text), ok (bool), seconds and an error when "
                                       f"not ok, got {s!r}"[:300])


def load_result(path: Path, tractor: Tractor, options: CommissionOptions) -> tuple[dict | None, str]:
    """A tractor's ``result.json`` if it is complete and was made for ``tractor`` with ``options``.

    Returns
    -------
    (dict or None, str)
        The result (``None`` when it must be redone) and why it is taken or redone.
    """
    if not path.is_file():
        return None, "no result.json yet"
    try:
        res = read_json(path, 64 * 2**20, "commissioning result", SimulatorConfigError)
        if not isinstance(res, dict):
            raise SimulatorConfigError(f"expected a JSON object, got {type(res).__name__}")
        if res.get("tractor") != tractor.to_dict():
            return None, "result.json was made for another tractor (or other parameters): redone"
        if res.get("options") != json.loads(json.dumps(options_dict(options))):
            return None, "result.json was made with other options: redone"
        _check_steps(res.get("steps"))
        _check_rows(res.get("hil"))
        if not isinstance(res.get("designs"), dict) or not set(res["designs"]) <= set(CONTROLLERS):
            raise SimulatorConfigError("'designs' must map controller names to their designs")
    except (OSError, ValueError) as exc:     # JSONDecodeError and SimulatorConfigError are ValueErrors
        return None, f"result.json unreadable or incomplete ({str(exc)[:200]}): redone"
    return res, "complete result.json: not redone"


def _write_json(path: Path, data: object) -> None:
    with atomic_write(path, "w") as fh:
        fh.write(json.dumps(data, indent=2, default=str) + "\n")


def _code_of(folder: Path) -> dict:
    try:
        d = read_json(folder / "campaign_code.json", 2**16, "campaign code record", SimulatorConfigError)
    except (OSError, ValueError):
        return {"commit": "unknown", "dirty": None}
    sha = d.get("commit") if isinstance(d, dict) else None
    ok = isinstance(sha, str) and (sha == "unknown" or (len(sha) == 40 and all(c in "0123456789abcdef" for c in sha)))
    return {"commit": sha if ok else "unknown", "dirty": d.get("dirty") if ok and isinstance(d.get("dirty"), bool)
            else None}


def commission_campaign(tractors: Sequence[Tractor], out: str | Path, options: CommissionOptions | None = None,
                        say: Callable[[str], None] | None = None,
                        progress: Callable[[str, int, int], None] | None = None) -> dict:
    """Commission every tractor under ``out/<name>/`` and write the aggregate after each one.

    Parameters
    ----------
    tractors
        The tractors, in order (names unique; each becomes a folder name, so letters, digits, ``_``,
        ``-``, at most 64 characters).
    out
        Output directory of the campaign.
    options
        The recipe's settings, the same for every tractor.
    say
        Called with one line per step, prefixed with ``[k/N tractor]`` (default: stderr).
    progress
        Called as ``progress(step, done, total)`` inside the long steps.

    Returns
    -------
    dict
        The aggregate (``campaign.json``): one row per tractor, the overall line, the files.
    """
    opts = options or CommissionOptions()
    say = say or (lambda line: print(line, file=sys.stderr, flush=True))
    names = [check_name(t.name, "tractor name") for t in tractors]
    if not names:
        raise SimulatorConfigError("no tractor given: expected --random SEEDS and/or --tractor NAME|FILE")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise SimulatorConfigError(f"tractor names must be unique (each is a folder), got {dup} more than once")
    if not opts.hil_seeds:
        raise SimulatorConfigError("a campaign compares the controllers on every tractor: give --hil-seeds (e.g. 0-2), "
                                   "or commission one tractor without the comparison with hil commission "
                                   "--hil-seeds 0")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    code = code_version()
    rows: list[dict] = []
    result: dict = {}
    for k, tractor in enumerate(tractors, 1):
        folder = out / tractor.name
        tag = f"[{k}/{len(tractors)} {tractor.name}]"
        res, why = load_result(folder / "result.json", tractor, opts)
        failure = None
        if res is not None:
            say(f"{tag} {why}")
        else:
            say(f"{tag} commissioning ({why})")
            try:
                folder.mkdir(parents=True, exist_ok=True)
                (folder / "failure.json").unlink(missing_ok=True)
                _write_json(folder / "campaign_code.json", code)
                res = commission(tractor, folder, opts, say=lambda line, tag=tag: say(f"{tag} {line.strip()}"),
                                 progress=progress)
            except Exception as exc:  # noqa: BLE001 - one tractor failing is a result of the campaign
                failure = f"{type(exc).__name__}: {exc}"
                try:
                    _write_json(folder / "failure.json", {"tractor": tractor.name, "error": failure, **code})
                except OSError:   # the folder itself is what failed: the aggregate still records it
                    pass
                say(f"{tag} FAILED: {failure}")
        rows.append(summarise_tractor(tractor.name, res, failure, code if failure else _code_of(folder)))
        result = write_campaign_report(rows, out, opts, [t.name for t in tractors])
    return result
