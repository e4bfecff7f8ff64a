"""``hil drive --excite FOLDER``: the field procedure's next identification pass, driven by the runtime.

:func:`drive_next_pass` reads the procedure's folder (:class:`hil.vehicle.procedure.Procedure`: the plan,
the valve test's ``commissioning.json``, the passes recorded and spoiled), drives the first planned pass
that has no good log on the tractor's ports (:func:`hil.vehicle.drive.drive`) with the excitation law
(:class:`hil.vehicle.excitation.ExcitationController`) in its corridor through the commissioned loop,
writes the pass log with the receivers' epochs as they arrived into ``logs/``, reviews it (a spoiled pass
goes to ``spoiled/`` with the reason and is driven again next time) and returns what comes next.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from identification.passlog import PassLog

from hil.vehicle.bridge_spec import parse_bridge
from hil.vehicle.commissioning import load_commissioning, save_commissioning
from hil.vehicle.drive import DriveConfig, drive
from hil.vehicle.excitation import ExcitationController, ExcitationSettings
from hil.vehicle.isobus.link import controller_commissioning
from hil.vehicle.procedure import Procedure, ProcedureError, status_text

__all__ = ["drive_next_pass", "wheel_angle_between_reports"]


def wheel_angle_between_reports(t: np.ndarray, channels: dict, meta: dict) -> tuple[dict, dict]:
    """The pass's wheel angle drawn between the cycles at which a new steering report arrived.

    An ISO 11783 steering controller reports its wheel angle every 0.1 s (Guidance Machine Info) and the loop
    runs at 20 Hz, so the loop holds every report for two cycles or so: recorded as it is, the angle is a
    staircase at the loop's rate whose steps identification fits with a pole near -1 (10 Hz, the grid's
    Nyquist frequency). :func:`identification.modes.sampling_artefact` refuses every model that has one, so
    the order was chosen among the few free of it, and on short passes those did not predict (3 s fits of
    -40 to -290 %) and no robust controller stabilised them. Here each report's angle is placed at the cycle
    that first received it (``bridge_received`` changed) and the angle is interpolated linearly between
    reports, as the receivers' epochs are between theirs; before the first report and after the last it is
    held. The loop's own values are kept as ``loop_wheel_angle``.

    Parameters
    ----------
    t
        The loop's cycle times, s.
    channels
        The run log's channels (``wheel_angle`` and ``bridge_received`` on ``t``); a log without
        ``bridge_received`` is returned as it is.
    meta
        Its metadata (``extra_channels`` gains ``loop_wheel_angle``).

    Returns
    -------
    tuple
        The channels and the metadata.
    """
    if "bridge_received" not in channels or "loop_wheel_angle" in channels:
        return channels, meta
    held = np.asarray(channels["wheel_angle"], dtype=float)
    received = np.asarray(channels["bridge_received"], dtype=float)
    new = np.r_[received[:1] >= 0, (np.diff(received) != 0) & (received[1:] >= 0)]
    if np.count_nonzero(new) < 2:
        return channels, meta
    out = {**channels, "wheel_angle": np.interp(t, t[new], held[new]), "loop_wheel_angle": held}
    extra = {**(meta.get("extra_channels") or {}), "loop_wheel_angle": {"time": "t", "unit": "rad"}}
    return out, {**meta, "extra_channels": extra,
                 "wheel_angle_samples": "interpolated between the cycles at which each steering report arrived; "
                                        "the loop's held value is loop_wheel_angle"}


def drive_next_pass(folder: str | Path, cfg: DriveConfig, settings: ExcitationSettings | None = None,
                    seed: int | None = None, progress: Callable[[float, float], None] | None = None,
                    duration: float | None = None, **drive_options) -> dict:
    """Drive the procedure's next identification pass on the tractor.

    Parameters
    ----------
    folder
        The procedure's folder (``plan.json``, ``commissioning.json``, ``logs/``, ``spoiled/``). Through an
        ISO 11783 steering controller, which takes no valve test, a missing ``commissioning.json`` is written
        from :func:`hil.vehicle.isobus.link.controller_commissioning`.
    cfg
        The tractor's ports and geometry (an AB line: the pass runs along it; no field route). Its
        ``commissioning`` is replaced by the folder's.
    settings
        The excitation and its corridor (default :class:`ExcitationSettings`).
    seed
        Seed of the slews (default: fresh entropy, recorded in the log).
    progress
        Called as ``progress(t, duration)`` during the pass.
    duration
        Seconds to drive (default: the plan's; a shorter pass is spoiled as stopped early).
    drive_options
        Passed to :func:`hil.vehicle.drive.drive` (``open_port``).

    Returns
    -------
    dict
        ``pass`` (its label), ``file`` (the log), ``faults`` (empty when it is good), ``status``
        (:meth:`Procedure.status`) and ``text`` (the operator's screen, :func:`status_text`).

    Raises
    ------
    ProcedureError
        The folder has no plan or no valve test yet, every pass is recorded, or the run is on a field route.
    """
    settings = settings or ExcitationSettings()
    folder = Path(folder)
    if not (folder / "plan.json").is_file():
        raise ProcedureError(f"{folder} holds no procedure (plan.json); start it with `hil procedure {folder}`")
    proc = Procedure.open(folder)
    com_file = folder / "commissioning.json"
    if not com_file.is_file() and parse_bridge(cfg.bridge_port).kind == "isobus":
        # a steering controller closes its own loop (no valve test): its commissioning is the controller's
        save_commissioning(controller_commissioning(), com_file)
    if not com_file.is_file():
        raise ProcedureError(f"{folder} has no commissioning.json: run the valve test first "
                             f"(hil valve-test --bridge PORT --out {folder})")
    if cfg.route is not None:
        raise ProcedureError("identification passes run along the AB line (--line), not a field route (--field)")
    remaining = proc.remaining()
    if not remaining:
        raise ProcedureError(f"{folder}: {proc.status()['next']}")
    p = remaining[0]
    com = load_commissioning(com_file)
    loop = settings.loop_config(com.loop_config(cfg.loop))
    run_cfg = replace(cfg, commissioning=com, loop=loop)
    ss = np.random.SeedSequence(seed)
    ctl = ExcitationController(settings, np.random.default_rng(ss), p.speed, p.duration, cfg.wheelbase,
                               com.valve.max_rate, dt=1.0 / loop.rate)
    length = p.duration if duration is None else duration
    if isinstance(length, bool) or not isinstance(length, (int, float)) or not (math.isfinite(length) and length > 0):
        raise ProcedureError(f"duration must be a finite number of seconds > 0, got {length!r}")
    log = drive(run_cfg, ctl, float(length), implement=p.implement, nominal_speed=p.speed, progress=progress,
                epochs=True, **drive_options)
    meta = {**log.meta, "pass_index": p.index, "excitation": dict(settings.__dict__), "excitation_seed": str(ss.entropy),
            "source": "hil.vehicle.excite_run (identification pass driven by the runtime)"}
    channels = dict(log.channels)
    if parse_bridge(cfg.bridge_port).kind == "isobus":
        channels, meta = wheel_angle_between_reports(log.times["t"], channels, meta)
    proc.logs.mkdir(parents=True, exist_ok=True)
    path = PassLog(times=dict(log.times), channels=channels, meta=meta).save(proc.logs / p.file_name)
    moved = proc.review()
    faults = next((m["faults"] for m in moved if Path(m["file"]).name.startswith(Path(p.file_name).stem)), [])
    status = proc.status()
    return {"pass": p.label(), "file": str(path if not faults else moved[-1]["file"]), "faults": faults,
            "status": status, "text": status_text(status)}
