"""Integrity of the navigation solution: an explicit state with its reason.

The vehicle loop engages only on :attr:`IntegrityState.RTK_FIXED` (``Integrity.healthy``)
and disengages on any other state.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from .errors import ConfigError

__all__ = ["FixQuality", "IntegrityState", "IntegrityConfig", "Integrity", "assess_integrity", "fix_from_gga", "fix_from_nav_pvt"]


class FixQuality(enum.IntEnum):
    """Receiver fix quality, normalised across protocols."""

    NONE = 0
    AUTONOMOUS = 1
    DGPS = 2
    DEAD_RECKONING = 3
    RTK_FLOAT = 5
    RTK_FIXED = 4


class IntegrityState(enum.Enum):
    """Integrity states, best first."""

    RTK_FIXED = "rtk_fixed"
    RTK_FLOAT = "rtk_float"
    DEGRADED = "degraded"
    STALE = "stale"
    LOST = "lost"


_GGA = {0: FixQuality.NONE, 1: FixQuality.AUTONOMOUS, 2: FixQuality.DGPS, 3: FixQuality.AUTONOMOUS,
        4: FixQuality.RTK_FIXED, 5: FixQuality.RTK_FLOAT, 6: FixQuality.DEAD_RECKONING}


def fix_from_gga(quality: int) -> FixQuality:
    """GGA quality indicator (0-8) to :class:`FixQuality` (7 manual and 8 simulator map to NONE)."""
    return _GGA.get(int(quality), FixQuality.NONE)


def fix_from_nav_pvt(fix_type: int, gnss_fix_ok: bool, diff_soln: bool, carr_soln: int) -> FixQuality:
    """UBX NAV-PVT fix fields to :class:`FixQuality`."""
    if not gnss_fix_ok or fix_type in (0, 5):
        return FixQuality.NONE
    if fix_type == 1:
        return FixQuality.DEAD_RECKONING
    if carr_soln == 2:
        return FixQuality.RTK_FIXED
    if carr_soln == 1:
        return FixQuality.RTK_FLOAT
    return FixQuality.DGPS if diff_soln else FixQuality.AUTONOMOUS


@dataclass(frozen=True, slots=True)
class IntegrityConfig:
    """Thresholds of the integrity monitor.

    Attributes
    ----------
    stale_after : float
        s without a new position (by arrival time) before the state is STALE; choose about
        1.5 receiver periods (0.3 s for 5 Hz).
    lost_after : float
        s without a new position before the state is LOST.
    attitude_stale_after : float
        s without a new heading before the state is STALE (``inf`` if no attitude receiver).
    max_correction_age : float
        s; older RTK corrections make the state DEGRADED.
    max_hdop : float
        Larger HDOP makes the state DEGRADED.
    max_h_acc : float
        m; a larger horizontal accuracy estimate (when the receiver gives one) makes it DEGRADED.
    """

    stale_after: float = 0.3
    lost_after: float = 1.0
    attitude_stale_after: float = 0.3
    max_correction_age: float = 10.0
    max_hdop: float = 2.5
    max_h_acc: float = 0.10

    def __post_init__(self) -> None:
        for name in ("stale_after", "lost_after", "attitude_stale_after", "max_correction_age", "max_hdop", "max_h_acc"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v > 0):
                raise ConfigError(f"IntegrityConfig.{name}: expected a positive number, got {v!r}")
        if self.lost_after < self.stale_after:
            raise ConfigError(
                f"IntegrityConfig: lost_after ({self.lost_after} s) must be >= stale_after ({self.stale_after} s)"
            )


@dataclass(frozen=True, slots=True)
class Integrity:
    """Integrity state with a human-readable reason."""

    state: IntegrityState
    reason: str

    @property
    def healthy(self) -> bool:
        """True only for RTK fixed: the single state in which the vehicle loop may engage."""
        return self.state is IntegrityState.RTK_FIXED


def assess_integrity(
    config: IntegrityConfig,
    *,
    position_age: float,
    fix: FixQuality,
    attitude_age: float = 0.0,
    correction_age: float | None = None,
    hdop: float | None = None,
    h_acc: float | None = None,
) -> Integrity:
    """Integrity state from the data ages and the receiver's quality indicators.

    Parameters
    ----------
    config : IntegrityConfig
    position_age : float
        s since the last position arrived (``inf`` if none yet).
    fix : FixQuality
        Fix quality of the last position.
    attitude_age : float
        s since the last valid heading arrived (``inf`` if none).
    correction_age : float, optional
        Age of differential corrections, s.
    hdop : float, optional
    h_acc : float, optional
        Horizontal accuracy estimate, m.

    Returns
    -------
    Integrity
        The first failing check, in order: lost, stale position, stale attitude, no fix,
        correction age, HDOP, accuracy, fix kind.
    """
    return assess(config, position_age, fix, attitude_age, correction_age, hdop, h_acc)


def assess(config: IntegrityConfig, position_age: float, fix: FixQuality, attitude_age: float,
           correction_age: float | None, hdop: float | None, h_acc: float | None) -> Integrity:
    """:func:`assess_integrity` with every argument positional (the front-end's once-a-tick call)."""
    S = IntegrityState
    if not math.isfinite(position_age):
        return Integrity(S.LOST, "no position received yet")
    if position_age > config.lost_after:
        return Integrity(S.LOST, f"no position for {position_age:.2f} s (limit {config.lost_after:.2f} s)")
    if position_age > config.stale_after:
        return Integrity(S.STALE, f"position is {position_age:.2f} s old (limit {config.stale_after:.2f} s)")
    if attitude_age > config.attitude_stale_after:
        what = "no heading received yet" if not math.isfinite(attitude_age) else f"heading is {attitude_age:.2f} s old"
        return Integrity(S.STALE, f"{what} (limit {config.attitude_stale_after:.2f} s)")
    if fix is FixQuality.NONE:
        return Integrity(S.LOST, "receiver reports no fix")
    if correction_age is not None and correction_age > config.max_correction_age:
        return Integrity(S.DEGRADED, f"corrections are {correction_age:.1f} s old (limit {config.max_correction_age:.1f} s)")
    if hdop is not None and hdop > config.max_hdop:
        return Integrity(S.DEGRADED, f"HDOP {hdop:.1f} exceeds {config.max_hdop:.1f}")
    if h_acc is not None and h_acc > config.max_h_acc:
        return Integrity(S.DEGRADED, f"horizontal accuracy {h_acc:.3f} m exceeds {config.max_h_acc:.3f} m")
    if fix is FixQuality.RTK_FIXED:
        return _RTK_FIXED
    if fix is FixQuality.RTK_FLOAT:
        return _RTK_FLOAT
    return Integrity(S.DEGRADED, f"fix quality {fix.name} is not RTK")


# The verdicts whose reason has no numbers: one (immutable) instance each.
_RTK_FIXED = Integrity(IntegrityState.RTK_FIXED, "RTK fixed")
_RTK_FLOAT = Integrity(IntegrityState.RTK_FLOAT, "RTK float: carrier ambiguities not fixed")
