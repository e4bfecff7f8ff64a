"""A steering-rate command integrated into a wheel-angle setpoint: what a driver does for a steering device that
takes an angle (the AgOpenGPS module) or a curvature (an ISO 11783 steering controller) instead of a rate.

One copy of the law both drivers use: the rate is limited, integrated over the time since the last command
(at most ``max_dt``, so a stalled loop does not jump the setpoint), held within ``max_windup`` of the measured
angle (anti-windup: a wheel that cannot follow does not wind the setpoint away) and within ``limit``.
"""

from __future__ import annotations

__all__ = ["setpoint_step"]


def _clip(x: float, low: float, high: float) -> float:
    return min(max(x, low), high)


def setpoint_step(setpoint: float, rate: float, elapsed: float, measured: float, *, max_dt: float, max_rate: float,
                  max_windup: float, limit: float) -> tuple[float, float, bool]:
    """The next setpoint after a rate command.

    Parameters
    ----------
    setpoint
        The setpoint so far, rad, + = left.
    rate
        The rate commanded, rad/s.
    elapsed
        Seconds since the previous command (clipped to ``0 .. max_dt``).
    measured
        The measured wheel angle, rad.
    max_dt, max_rate, max_windup, limit
        Longest integration step, s; rate limit, rad/s; largest distance of the setpoint from the measured
        angle, rad; largest setpoint, rad.

    Returns
    -------
    tuple
        ``(setpoint, rate applied, limited)``: ``limited`` when the rate or the setpoint was clipped.
    """
    u = _clip(float(rate), -max_rate, max_rate)
    wanted = setpoint + u * _clip(elapsed, 0.0, max_dt)
    new = _clip(_clip(wanted, measured - max_windup, measured + max_windup), -limit, limit)
    return new, u, new != wanted or u != rate
