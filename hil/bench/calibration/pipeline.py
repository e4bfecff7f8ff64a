"""The paper's method on the bench, for the calibration: passes -> OKID central model -> one LQR.

:func:`papers_controller` does what ``python3 tasks.py demo`` does with the CLIs
(``hil sysid``, ``identification okid``, ``design lqr --model central.npz --verify-on
local_*.npz``), in-process and at given simulator parameters: the open-loop
identification passes, OKID/ERA-DC local and central models, and one LQR with the
central model's Kalman predictor, verified on every local model. :func:`confirm`
re-runs it at the calibrated parameters and evaluates the new controller, so the
calibration (made with a controller identified once, at the reference parameters)
is checked against the method as a user would run it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Mapping

from design.synthesis.robust import design_lqr
from identification.model import Model
from identification.workflow import identify_logs

from hil.bench.calibration.calibrate import CalibrationOptions, Evaluator, calibrated_params
from hil.truth.params import SimParams
from hil.bench.runs.sysid import SysidPlan, make_passes


def papers_controller(params: SimParams, out: str | Path, seed: int = 1997, passes: int = 3,
                      duration: float = 120.0, progress: Callable[[int, int], None] | None = None) -> Path:
    """Identification passes, OKID models and the central LQR at ``params``; return the controller file.

    Parameters
    ----------
    params
        Simulator parameters of the identification passes.
    out
        Directory for ``logs/``, ``models/`` and ``central-lqr.json``.
    seed, passes, duration
        As ``hil sysid`` (the demo uses seed 1997, 3 passes of 120 s per condition).
    """
    out = Path(out)
    for name, log in make_passes(SysidPlan(passes=passes, duration=duration, seed=seed), params, progress=progress):
        log.save(out / "logs" / f"{name}.npz")
    identify_logs([out / "logs"], out / "models", kinds=("local", "central"))
    central = Model.load(out / "models" / "central.npz")
    local = [Model.load(f) for f in sorted((out / "models").glob("local_*.npz"))]
    file, _cert = design_lqr(central, local, name="central-lqr")
    path = out / "central-lqr.json"
    file.save(path)
    return path


def confirm(log2_scales: Mapping[str, float], out: str | Path, options: CalibrationOptions,
            workers: int | None = None, progress: Callable[[int, int], None] | None = None) -> dict:
    """Re-identify at the calibrated parameters and evaluate that controller with ``options``' seeds.

    Returns the evaluation record (as :class:`~hil.bench.calibration.calibrate.Evaluator` gives it) with the
    controller file's path.
    """
    out = Path(out)
    ctrl = papers_controller(calibrated_params(log2_scales), out / "identification")
    rec = Evaluator(str(ctrl), out, options, workers, progress)(log2_scales)
    return {**rec, "controller": str(ctrl), "seeds": list(options.seeds)}


def run_calibration(out: str | Path, options: CalibrationOptions, controller: str | None = None,
                    confirm_seeds: tuple[int, ...] | None = (10, 11), workers: int | None = None,
                    report: Callable[[int, dict, bool], None] | None = None,
                    progress: Callable[[int, int], None] | None = None) -> dict:
    """The whole procedure: the paper's controller, the search, the confirmation, the report.

    Parameters
    ----------
    out
        Directory of the calibration (evaluations are kept there, so a rerun resumes).
    options
        Search options.
    controller
        The paper's controller file; default: made by :func:`papers_controller` at the
        reference parameters in ``out/reference/``.
    confirm_seeds
        Seeds of the confirmation (re-identified controller); ``None`` skips it.
    report, progress
        Callbacks of :func:`hil.bench.calibration.calibrate.search` and of each evaluation's campaign.

    Returns
    -------
    dict
        The result document (also written with the report into ``out``).
    """
    from dataclasses import replace

    from hil.bench.calibration.calibrate import reference_params, result_document, search
    from hil.bench.calibration.report import write
    out = Path(out)
    if controller is None:
        ref = out / "reference" / "central-lqr.json"
        controller = str(ref if ref.exists() else papers_controller(reference_params(), out / "reference"))
    found = search(Evaluator(controller, out, options, workers, progress), options, report)
    confirmation = None
    if confirm_seeds is not None:
        confirmation = confirm(found["best"]["log2_scales"], out / "confirmation",
                               replace(options, seeds=tuple(confirm_seeds)), workers, progress)
    result = result_document(found, controller, confirmation)
    write(result, out)
    return result
