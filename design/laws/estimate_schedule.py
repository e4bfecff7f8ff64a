"""Where the disturbance estimate acts: a speed schedule between two certified laws.

Why: on the heavy tractor (slow valve, 0.15 s latency) the estimate of :mod:`design.laws.disturbance`
takes 5-10 % off the 1-sigma at 1.00-2.24 m/s, but at 2.91 m/s it drives the command into the
valve's rate limit 20-35 % of the time and the 1-sigma grows to 1.4-1.8x the oracle (ripper:
robust 9.9 cm with it, 5.9 cm without; MPC 7.8 against 6.1; three seeds). The MPC without it
misses the paper's method at 1.00 m/s. No one setting is right at every speed, and which
speeds want it off depends on the tractor (the estimate off at 2.91 m/s on every tractor of the
family was better in 22 of 66 cells, worse in the rest), so the choice is measured on the
tractor, per speed, by a trial drive (:mod:`hil.bench.commissioning.estimate_trial`), and recorded here.

The two laws. With the estimate ``dh`` (states ``s`` and ``dp`` of
:func:`design.laws.disturbance.estimate_compensator`), the command is ``u = u_w + u_d``, with
``u_d = K_d dh = C_d xc + D_d y``: ``C_d`` is the compensator's output row on the ``s`` and
``dp`` states, ``D_d = -C_c[s]`` (``dh = dp + L (y - s)``). The law *without* the estimate is
the same compensator with ``u_d`` taken out of the command and out of the memory the
compensator keeps of its own command (``Ac - Ec C_d``, ``Bc - Ec D_d``): its command is exactly
the window law's, and the filter keeps running on the command actually sent, so switching the
estimate back on is bumpless. Both laws are certified on every model the file lists (the file's
certificate, and ``design["estimate_schedule"]["certificate_off"]``), so a schedule may select
either at any speed; the loop switches only between bands, at speeds between the design's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from design.core.compensator import Compensator
from design.core.errors import ControllerFileError, DesignInputError

#: Key of the schedule's record in a controller file's ``design`` object.
RECORD = "estimate_schedule"
#: Fastest speed a band may name, m/s (a tractor in the field; beyond it a band is a typo).
SPEED_MAX = 20.0


def check_bands(bands: Sequence[Any], what: str) -> tuple[tuple[float, float], ...]:
    """Speed bands ``(low, high)``, m/s, checked and sorted: ``0 <= low < high <= SPEED_MAX`` (``high`` may
    be ``inf``), no two overlapping; ``what`` names them in the error (``DesignInputError``)."""
    out = []
    for b in bands:
        if not isinstance(b, (tuple, list)) or len(b) != 2:
            raise DesignInputError(f"an {what} band must be (low, high) m/s, got {b!r}")
        lo, hi = b
        for v in (lo, hi):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v):
                raise DesignInputError(f"an {what} band must be two speeds in m/s, got {b!r}")
        if not (0.0 <= lo < hi and lo <= SPEED_MAX and (hi <= SPEED_MAX or math.isinf(hi))):
            raise DesignInputError(f"an {what} band must have 0 <= low < high <= {SPEED_MAX:g} m/s "
                                   f"(or high = inf), got {b!r}")
        out.append((float(lo), float(hi)))
    out.sort()
    for (_, h0), (l1, _) in zip(out, out[1:]):
        if l1 < h0:
            raise DesignInputError(f"{what} bands overlap: {out!r}")
    return tuple(out)


@dataclass(frozen=True)
class EstimateSchedule:
    """Speed bands in which the disturbance estimate is off (it acts at every other speed).

    Attributes
    ----------
    off
        ``((low, high), ...)`` speeds, m/s, ``0 <= low < high``; ``high`` may be ``inf``. A speed
        ``v`` is in a band when ``low <= v < high``. Bands do not overlap.
    """

    off: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "off", check_bands(self.off, "estimate-off"))

    def acts_at(self, speed: float) -> bool:
        """True if the estimate acts at ``speed`` (m/s)."""
        return not any(lo <= speed < hi for lo, hi in self.off)

    def to_dict(self) -> dict:
        """JSON-ready: ``{"off_speed_bands": [[low, high], ...]}`` (``high`` null for no upper end)."""
        return {"off_speed_bands": [[lo, None if math.isinf(hi) else hi] for lo, hi in self.off]}

    @classmethod
    def from_record(cls, rec: Any) -> "EstimateSchedule":
        """Parse a file's record (:meth:`to_dict`, plus its certificate); ``ControllerFileError`` if malformed."""
        if not isinstance(rec, Mapping) or not isinstance(rec.get("off_speed_bands"), list):
            raise ControllerFileError(f"design.{RECORD} must be an object with a list off_speed_bands, got {rec!r}")
        try:
            return cls(tuple((b[0], math.inf if b[1] is None else b[1]) if isinstance(b, list) and len(b) == 2 else b
                             for b in rec["off_speed_bands"]))
        except DesignInputError as exc:
            raise ControllerFileError(f"design.{RECORD}: {exc}") from None


def bands_for(speeds: Sequence[float], off: Sequence[float]) -> EstimateSchedule:
    """The schedule that turns the estimate off at the design speeds ``off`` (each one of ``speeds``, m/s).

    A design speed's band reaches half-way to its neighbours (from 0 below the slowest, to no upper end
    above the fastest), so the loop switches between two speeds the passes were driven at.
    """
    sp = _design_speeds(speeds)
    bands = []
    for v in off:
        if not any(abs(v - s) < 1e-9 for s in sp):
            raise DesignInputError(f"estimate-off speed {v!r} m/s is not one of the design speeds {sp}")
        bands.append(reach_band(sp, v))
    merged: list[tuple[float, float]] = []
    for lo, hi in sorted(bands):
        if merged and abs(merged[-1][1] - lo) < 1e-12:
            merged[-1] = (merged[-1][0], hi)
        else:
            merged.append((lo, hi))
    return EstimateSchedule(tuple(merged))


def _design_speeds(speeds: Sequence[float]) -> list[float]:
    """The design speeds, sorted, once each; ``DesignInputError`` unless each is finite and > 0 m/s."""
    sp = sorted({float(v) for v in speeds})
    if not sp or any(not (math.isfinite(v) and v > 0) for v in sp):
        raise DesignInputError(f"design speeds must be finite and > 0 m/s, got {list(speeds)!r}")
    return sp


#: How far towards a neighbouring design speed, as a fraction of the way, a band law runs when it is not
#: certified on that speed's models (:func:`reach_band`); half-way when it is.
REACH_FRACTION = 0.25


def reach_band(speeds: Sequence[float], v: float, below: bool = True, above: bool = True) -> tuple[float, float]:
    """The band, m/s, of design speed ``v`` (one of ``speeds``) whose law runs half-way to a neighbouring design
    speed when ``below`` / ``above`` say it is certified on that speed's models as well, and only
    :data:`REACH_FRACTION` of the way when not; from 0 below the slowest, to no upper end above the fastest.

    Why: a law certified on the models of one design speed only is checked at that speed; at a speed between
    two design speeds the tractor's dynamics lie between theirs, so a law that runs there should be stable on
    the models of both. The speeds left between two bands are the file's own law's (certified on every model).
    """
    sp = _design_speeds(speeds)
    i = min(range(len(sp)), key=lambda j: abs(sp[j] - v))
    if abs(sp[i] - v) > 1e-9:
        raise DesignInputError(f"speed {v!r} m/s is not one of the design speeds {sp}")
    lo = 0.0 if i == 0 else 0.5 * (sp[i - 1] + sp[i]) if below else sp[i] - REACH_FRACTION * (sp[i] - sp[i - 1])
    hi = math.inf if i == len(sp) - 1 else 0.5 * (sp[i] + sp[i + 1]) if above \
        else sp[i] + REACH_FRACTION * (sp[i + 1] - sp[i])
    return (lo, hi)


def estimate_command_rows(comp: Compensator, dp_states: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """``(C_d, D_d)``: the estimate's part ``u_d = C_d xc + D_d y`` of the command (module docstring).

    ``dp_states`` are the estimate's carried states (a file's ``design["disturbance_estimate"]["states"]``);
    the prediction states ``s`` are the ``q`` states just before them.
    """
    dp = [int(i) for i in dp_states]
    q = comp.n_measurements
    if not dp or dp != list(range(dp[0], dp[0] + len(dp))) or dp[0] < q or dp[-1] >= comp.order:
        raise DesignInputError(f"estimate states must be consecutive compensator states after its {q} prediction "
                               f"states, got {list(dp_states)!r} for a compensator of order {comp.order}")
    s = list(range(dp[0] - q, dp[0]))
    cd = np.zeros_like(comp.Cc)
    cd[:, s + dp] = comp.Cc[:, s + dp]
    dd = -comp.Cc[:, s]
    return cd, dd


def trailing_states(law: Compensator, n_estimate: int) -> tuple[int, ...]:
    """The estimate's carried states of a law built by :func:`design.laws.disturbance.estimate_compensator` with
    ``n_estimate`` channels: its last ``n_estimate`` states (an MPC file's unconstrained law)."""
    return tuple(range(law.order - n_estimate, law.order)) if n_estimate > 0 else ()


def law_without_estimate(comp: Compensator, dp_states: Sequence[int]) -> Compensator:
    """The compensator whose command leaves the disturbance estimate out (module docstring): certified apart."""
    cd, dd = estimate_command_rows(comp, dp_states)
    return Compensator(comp.Ac - comp.Ec @ cd, comp.Bc - comp.Ec @ dd, comp.Cc - cd, comp.Dc - dd, comp.dt,
                       comp.Ec, comp.X0)


def schedule_record(law: Compensator, dp_states: Sequence[int], models: Sequence[Any],
                    names: Sequence[str] | None = None, schedule: EstimateSchedule | None = None) -> dict:
    """The file's ``design["estimate_schedule"]``: the schedule (default: the estimate acts everywhere) and
    the certificate of :func:`law_without_estimate` on ``models`` (a failed one is recorded as such: a schedule
    that turns the estimate off then cannot be set, :func:`design.files.certificate.check_estimate_schedule`)."""
    from design.core.verify import certify
    cert = certify(law_without_estimate(law, dp_states), models, names)
    return {**(schedule or EstimateSchedule()).to_dict(), "certificate_off": cert.to_dict()}
