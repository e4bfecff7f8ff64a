"""The commissioning recipe's designs, made through the design library (:mod:`design.recipes`).

A :class:`Designer` holds what every design of one tractor shares: the valve's measured rate (the
command limit and the actuator's rate in the specifications), the pass logs whose latency the
margins must cover, integral action and the disturbance estimate. Each of its methods designs one
controller, writes its file and returns the record ``result.json`` keeps: ``file``, ``result`` (what
``design ... --json`` prints for the same design) and ``settings`` (what it was designed with).

A :class:`DesignTry` is one attempt of the recipe's sequence: automatic or default weights, the
window from observability (``past=None``) or a given one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from design.disturbance import DisturbanceSpec
from design.mpc.problem import MPCLimits
from design.recipes import (MPCOptions, RobustOptions, WeightSearch, design_mpc_controller, design_robust_controller,
                            load_models)
from design.robust import RobustSpec, design_lqr
from design.specs import Specifications
from identification.model import Model

__all__ = ["DesignTry", "Designer", "settings_text"]


@dataclass(frozen=True)
class DesignTry:
    """One attempt: automatic weights or the design's defaults, and the measured window (None: automatic)."""

    auto: bool
    past: int | None = None

    @property
    def label(self) -> str:
        """``weights auto, past 6``: how the report names the attempt."""
        return f"weights {'auto' if self.auto else 'default'}, past {'auto' if self.past is None else self.past}"


@dataclass(frozen=True)
class Designer:
    """The recipe's designs for one tractor.

    Attributes
    ----------
    rate_limit
        The valve's measured steering-rate limit, rad/s: every design's command limit, and with automatic
        weights the actuator's rate of the specifications.
    logs
        Pass logs whose recorded latency the automatic weights' margins must cover (None: the models').
    latency
        The latency per output, s, when it is known otherwise (it then replaces the logs').
    disk_margin, delay_reserve
        The automatic weights' specifications (:class:`design.specs.Specifications`; delay reserve in s).
    integral
        Integral action in the robust design.
    estimate
        The disturbance estimate in the robust controller and the MPC.
    """

    rate_limit: float
    logs: Path | None = None
    latency: tuple[float, ...] | None = None
    disk_margin: float = Specifications.disk_margin
    delay_reserve: float = Specifications.delay_reserve
    integral: bool = True
    estimate: bool = True

    def search(self, attempt: DesignTry) -> WeightSearch:
        """The weights' mode and specifications of ``attempt``."""
        if not attempt.auto:
            return WeightSearch()
        if self.latency is not None:
            source = {"latency": self.latency}
        else:
            source = {"latency_from_logs": (self.logs,) if self.logs is not None else ()}
        return WeightSearch(mode="auto", disk_margin=self.disk_margin, delay_reserve=self.delay_reserve,
                            actuator_rate=self.rate_limit, **source)

    def _settings(self, kind: str, models: str, attempt: DesignTry | None, **more) -> dict:
        rec = {"design": kind, "models": models, "command_limit_rad_s": self.rate_limit}
        if attempt is not None:
            rec.update(weights="auto" if attempt.auto else "default",
                       past="auto" if attempt.past is None else attempt.past)
            if attempt.auto:
                rec["latency"] = (f"{', '.join(f'{v:g}' for v in self.latency)} s" if self.latency is not None else
                                  f"from the logs in {self.logs}" if self.logs is not None else "from the models")
        return {**rec, **more}

    def lqr(self, models_dir: Path, out: Path) -> dict:
        """The paper's method: one LQR on the central model, certified on that model only (as in the paper; a
        certificate failed on the local models would make the loader refuse the reference)."""
        model = Model.load(models_dir / "central.npz")
        file, cert = design_lqr(model, (), command_limit=self.rate_limit, require=True)
        file.save(out)
        return {"file": str(out), "result": {"out": str(out), "certificate": cert.to_dict()},
                "settings": self._settings("lqr", "central.npz", None)}

    def robust(self, models_dir: Path, attempt: DesignTry, out: Path, candidates_dir: Path | None = None,
               progress: Callable[[str], None] | None = None) -> dict:
        """The robust controller on the local models of ``models_dir``; with ``candidates_dir`` (automatic
        weights and the estimate) the window laws its back-off made and did not keep are written there."""
        local = sorted(models_dir.glob("local_*.npz"))
        keep = candidates_dir is not None and attempt.auto and self.estimate
        options = RobustOptions(RobustSpec(integral=self.integral, past=attempt.past, command_limit=self.rate_limit),
                                self.search(attempt), DisturbanceSpec() if self.estimate else None, candidates=keep)
        res = design_robust_controller(load_models(local), options, progress=progress)
        res.save(out, candidates_dir if keep else None)
        return {"file": str(out), "result": {"out": str(out), **res.summary()},
                "settings": self._settings("robust", f"{models_dir.name}/local_*.npz", attempt,
                                           integral=self.integral, disturbance_estimate=self.estimate)}

    def mpc(self, models_dir: Path, attempt: DesignTry, out: Path, fallback: Path | None,
            progress: Callable[[str], None] | None = None) -> dict:
        """The MPC on the models of ``models_dir`` (the central one predicts), with the robust law of
        ``fallback`` as its fall-back (None: none, for a search of the weights alone)."""
        options = MPCOptions(limits=MPCLimits(rate=self.rate_limit), past=attempt.past,
                             disturbance=DisturbanceSpec() if self.estimate else None, search=self.search(attempt),
                             fallback=fallback)
        res = design_mpc_controller(load_models([models_dir]), options, progress=progress)
        res.save(out)
        return {"file": str(out), "result": {"out": str(out), **res.summary()},
                "settings": self._settings("mpc", f"{models_dir.name}/*.npz", attempt,
                                           fallback=None if fallback is None else str(fallback),
                                           disturbance_estimate=self.estimate)}


def settings_text(settings: dict) -> str:
    """One line of a design's settings for the report: ``design robust on models/local_*.npz: weights auto, ...``."""
    rest = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in settings.items() if k not in ("design", "models"))
    return f"design {settings.get('design')} on {settings.get('models')}: {rest}"
