"""WGS-84 geodetic coordinates to a local east-north-up frame about a field origin, and back.

Thin, typed wrapper over :mod:`pymap3d`; latitudes and longitudes are in rad, heights are
ellipsoidal (WGS-84) in m, ENU coordinates in m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymap3d
from numpy.typing import ArrayLike, NDArray

from .errors import ConfigError

__all__ = ["LocalFrame"]


@dataclass(frozen=True, slots=True)
class LocalFrame:
    """A local tangent (ENU) frame about a field origin.

    Attributes
    ----------
    lat0, lon0 : float
        Origin latitude / longitude, rad (WGS-84).
    h0 : float
        Origin ellipsoidal height, m.
    """

    lat0: float
    lon0: float
    h0: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lat0) and math.isfinite(self.lon0) and math.isfinite(self.h0)):
            raise ConfigError(f"LocalFrame: expected finite origin, got {self.lat0!r}, {self.lon0!r}, {self.h0!r}")
        if abs(self.lat0) > math.pi / 2 or abs(self.lon0) > math.pi:
            raise ConfigError(
                f"LocalFrame: expected lat0 in [-pi/2, pi/2] and lon0 in [-pi, pi] rad, got {self.lat0!r}, {self.lon0!r}; "
                "use LocalFrame.from_degrees for degrees"
            )

    @classmethod
    def from_degrees(cls, lat0_deg: float, lon0_deg: float, h0: float = 0.0) -> "LocalFrame":
        """Build from an origin in degrees (deg, deg, m)."""
        return cls(math.radians(lat0_deg), math.radians(lon0_deg), float(h0))

    def to_enu(self, lat: ArrayLike, lon: ArrayLike, h: ArrayLike = 0.0) -> NDArray[np.float64]:
        """Geodetic (rad, rad, m) to ENU (m).

        Returns
        -------
        ndarray, shape (..., 3)
            East, north, up of each point, m.
        """
        e, n, u = pymap3d.geodetic2enu(
            np.asarray(lat, dtype=float), np.asarray(lon, dtype=float), np.asarray(h, dtype=float),
            self.lat0, self.lon0, self.h0, deg=False,
        )
        return np.stack(np.broadcast_arrays(e, n, u), axis=-1)

    def to_geodetic(self, enu: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """ENU (m, shape (..., 3)) to geodetic latitude, longitude (rad) and ellipsoidal height (m)."""
        p = np.asarray(enu, dtype=float)
        if p.shape[-1:] != (3,):
            raise ConfigError(f"to_geodetic: expected ENU points of shape (..., 3), got {p.shape}")
        lat, lon, h = pymap3d.enu2geodetic(p[..., 0], p[..., 1], p[..., 2], self.lat0, self.lon0, self.h0, deg=False)
        return np.asarray(lat, dtype=float), np.asarray(lon, dtype=float), np.asarray(h, dtype=float)
