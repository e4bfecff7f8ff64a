"""GNSS front-end: receiver protocols, geodesy, attitude, guidance lines and integrity.

No imports from the other project packages.  Units are SI (m, s, rad, m/s); frames and angle
conventions are in :mod:`gnss.frames` (ENU about a field origin; yaw 0 = north, clockwise).

Main entry points
-----------------
- :class:`gnss.frontend.GnssFrontEnd` / :class:`gnss.frontend.FrontEndConfig` /
  :class:`gnss.frontend.NavSolution`: what the vehicle loop calls each tick.
- :class:`gnss.reader.GnssReader`, :class:`gnss.reader.StreamDecoder`: mixed NMEA/UBX/RTCM streams.
- :mod:`gnss.nmea_encode`, :mod:`gnss.ubx`, :mod:`gnss.rtcm`: encoders (SI in, bytes out).
- :class:`gnss.guidance.ABLine`, :class:`gnss.guidance.ParallelLines`, :class:`gnss.guidance.CurvedLine`;
  :class:`gnss.curve.ArcPath` (straight and circular-arc segments, exact curvature preview).
- :class:`gnss.geodesy.LocalFrame`, :func:`gnss.attitude.solve_attitude`,
  :func:`gnss.lever_arm.control_point_enu`.
"""

from .frontend import FrontEndConfig, GnssFrontEnd, NavSolution
from .geodesy import LocalFrame
from .guidance import ABLine, CurvedLine, ParallelLines, TrackErrors
from .integrity import FixQuality, Integrity, IntegrityConfig, IntegrityState
from .reader import GnssReader, Received, StreamDecoder

__all__ = [
    "FrontEndConfig",
    "GnssFrontEnd",
    "NavSolution",
    "LocalFrame",
    "ABLine",
    "CurvedLine",
    "ParallelLines",
    "TrackErrors",
    "FixQuality",
    "Integrity",
    "IntegrityConfig",
    "IntegrityState",
    "GnssReader",
    "Received",
    "StreamDecoder",
]
