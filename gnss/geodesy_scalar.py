"""ENU <-> geodetic for one point on Python floats (the per-message path of the front-end and receivers).

:class:`~gnss.geodesy.LocalFrame` goes through :mod:`pymap3d` on numpy arrays, which costs about
40 microseconds a point to ENU and 200 back, in call overhead: at 5 Hz in the emulated receiver and
the front-end that is about 1.2 ms of CPU per simulated second, a third of the whole lockstep pass
(``benchmarks/bench_gnss.py`` case 5). :class:`ScalarFrame` evaluates the same formulas (pymap3d's
``geodetic2ecef``, ``enu2uvw``/``uvw2enu`` and You (2000)'s closed-form ``ecef2geodetic`` on
WGS-84) with :mod:`math`, one point at a time, about 20 times faster. It is tested against
``LocalFrame`` to a tolerance (1e-8 m, 1e-15 rad; the two may differ in the last bits, where numpy
and libm round differently). Latitudes and longitudes in rad, heights ellipsoidal (WGS-84) in m,
ENU in m.
"""

from __future__ import annotations

import math

from .geodesy import LocalFrame

__all__ = ["ScalarFrame"]

_A = 6378137.0            # WGS-84 semi-major axis, m (pymap3d's value)
_B = 6356752.31424518     # WGS-84 semi-minor axis, m (pymap3d's value)
_E = math.sqrt(_A**2 - _B**2)
_E2 = _E**2
_BA2 = (_B / _A) ** 2
_HALF_PI = math.pi / 2
_hypot, _sin, _cos, _sqrt = math.hypot, math.sin, math.cos, math.sqrt


def _geodetic2ecef(lat: float, lon: float, alt: float) -> tuple[float, float, float]:
    n = _A**2 / _hypot(_A * _cos(lat), _B * _sin(lat))
    return ((n + alt) * _cos(lat) * _cos(lon), (n + alt) * _cos(lat) * _sin(lon), (n * _BA2 + alt) * _sin(lat))


class ScalarFrame:
    """A :class:`~gnss.geodesy.LocalFrame` evaluated on floats, one point per call.

    Parameters
    ----------
    frame : LocalFrame
        The field origin.
    """

    def __init__(self, frame: LocalFrame) -> None:
        self.frame = frame
        lat0, lon0 = frame.lat0, frame.lon0
        self._x0, self._y0, self._z0 = _geodetic2ecef(lat0, lon0, frame.h0)
        self._sl, self._cl = _sin(lat0), _cos(lat0)
        self._so, self._co = _sin(lon0), _cos(lon0)

    def to_enu(self, lat: float, lon: float, h: float) -> tuple[float, float, float]:
        """Geodetic (rad, rad, m) to (east, north, up), m."""
        x1, y1, z1 = _geodetic2ecef(lat, lon, h)
        u, v, w = x1 - self._x0, y1 - self._y0, z1 - self._z0
        sl, cl, so, co = self._sl, self._cl, self._so, self._co
        t = co * u + so * v
        return -so * u + co * v, -sl * t + cl * w, cl * t + sl * w

    def to_geodetic(self, east: float, north: float, up: float) -> tuple[float, float, float]:
        """(east, north, up), m, to geodetic latitude, longitude (rad) and ellipsoidal height (m)."""
        sl, cl, so, co = self._sl, self._cl, self._so, self._co
        t = cl * up - sl * north
        w = sl * up + cl * north
        x = self._x0 + (co * t - so * east)
        y = self._y0 + (so * t + co * east)
        z = self._z0 + w
        r2 = x * x + y * y + z * z
        u = _sqrt(0.5 * (r2 - _E2) + 0.5 * _hypot(r2 - _E2, 2 * _E * z))
        hxy = _hypot(x, y)
        hue = _hypot(u, _E)
        try:
            beta = math.atan(hue / u * z / hxy)
            beta += ((_B * u - _A * hue + _E2) * _sin(beta)) / (_A * hue * 1 / _cos(beta) - _E2 * _cos(beta))
        except ZeroDivisionError:   # on the axis or at the centre, as pymap3d's fallback
            beta = 0.0 if math.isclose(z, 0, abs_tol=1e-8) else math.copysign(_HALF_PI, z)
        lat = math.atan(_A / _B * math.tan(beta))
        lon = math.atan2(y, x)
        alt = _hypot(z - _B * _sin(beta), hxy - _A * _cos(beta))
        if x * x / _A**2 + y * y / _A**2 + z * z / _B**2 < 1:
            alt = -alt
        return lat, lon, alt
