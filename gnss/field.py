"""A field: parallel passes one implement width apart, joined by headland U-turns, as one route.

A :class:`Field` is a reference pass (an :class:`~gnss.curve.ArcPath`: straight, curved, an
S-curve or an arc fit of a recorded contour), an implement width and a number of passes.
Pass ``i`` is the reference offset by ``(i - reference_pass) * width`` m to the **left**
(:meth:`ArcPath.offset`, exact), so the passes are numbered from right to left::

    field = load_field("gentle-curves")                  # gnss.field_io; or Field(...)
    route = field.route(TurnLimits(speed=1.5))           # all passes, alternately both ways
    route.path                                           # ONE tangent-continuous ArcPath
    for part in route.parts:                             # station intervals of route.path
        part.start, part.end, part.pass_index, part.kind # kind: "straight" | "curve" | "turn"

Pass ``first`` is driven along the reference direction, the next one back the other way,
and so on; a turn's ``pass_index`` is that of the pass it leaves. A pass's stretches with
``|curvature| < STRAIGHT_CURVATURE`` are ``"straight"``, the others ``"curve"``; in a pass
with curves, a straight shorter than ``MIN_STRAIGHT_LENGTH`` (20 m, e.g. a contour's
inflection) counts as curve.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from autosteer.checks import finite

from .curve import ArcPath
from .errors import GeometryError
from .geodesy import LocalFrame
from .guidance import ABLine
from .uturn import TurnLimits, plan_uturn

__all__ = ["STRAIGHT_CURVATURE", "MIN_STRAIGHT_LENGTH", "KINDS", "RoutePart", "Route", "Field", "FieldGeometry",
           "line_to_enu", "place_on_line"]

#: Below this ``|curvature|`` (1/m; radius 1 km) a stretch of a pass counts as straight.
STRAIGHT_CURVATURE = 1e-3
#: ... if it is at least this long (m) in a pass that has curves; shorter ones count as curve.
MIN_STRAIGHT_LENGTH = 20.0
KINDS = ("straight", "curve", "turn")
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}\Z")


def line_to_enu(x: float, y: float, line_yaw: float) -> tuple[float, float]:
    """A point of a guidance line's frame (x along the line from A towards B, y to its left, m) as local ENU
    east, north about A, m (``line_yaw``: heading of A to B, rad, 0 = north, clockwise)."""
    s, c = math.sin(line_yaw), math.cos(line_yaw)
    return x * s - y * c, x * c + y * s


def place_on_line(path: ArcPath, line_yaw: float) -> ArcPath:
    """A path given in a guidance line's frame (x along the line from A towards B, y to its left, m; directions
    CCW from x) in the local ENU frame about A (east, north, m): the same segments from the placed start point
    and direction.

    Parameters
    ----------
    path
        The path in the line's frame (a field's route, its passes).
    line_yaw
        Heading of the line A to B, rad, 0 = north, clockwise.
    """
    start = line_to_enu(float(path.start[0]), float(path.start[1]), line_yaw)
    # the line frame's x axis points at ENU angle pi/2 - line_yaw
    return ArcPath(start, path.start_angle + math.pi / 2 - line_yaw, path.segments)


@dataclass(frozen=True)
class FieldGeometry:
    """Where a guidance line's frame (x along the line from A towards B, y to its left) lies on the Earth.

    The emulated receivers place the simulated tractor with it, and a field's route, defined in that
    frame, is placed in the vehicle's ENU frame by :meth:`place`.

    Attributes
    ----------
    origin
        Field origin (point A of the line), WGS-84.
    line_yaw
        Heading of the line A to B, rad, 0 = north, clockwise.
    utc_start
        UTC time of day at time 0 of the run, s (time tags of the receivers' messages).
    """

    origin: LocalFrame = field(default_factory=lambda: LocalFrame.from_degrees(37.4275, -122.1697, 30.0))
    line_yaw: float = math.radians(20.0)
    utc_start: float = 12 * 3600.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.line_yaw) and math.isfinite(self.utc_start) and 0 <= self.utc_start < 86400):
            raise GeometryError(f"FieldGeometry: line_yaw must be finite (rad) and utc_start in [0, 86400) s, got "
                                f"{self.line_yaw!r:.30}, {self.utc_start!r:.30}")

    def line_to_enu(self, x: float, y: float) -> tuple[float, float]:
        """Line frame (x along, y left; m) to ENU east, north (m)."""
        return line_to_enu(x, y, self.line_yaw)

    def yaw(self, psi: float) -> float:
        """Vehicle yaw (rad, 0 = north, clockwise) from heading relative to the line (rad, CCW +)."""
        return (self.line_yaw - psi) % (2 * math.pi)

    def ab_line(self, length: float = 1000.0) -> ABLine:
        """The guidance line as the vehicle computer knows it (A at the origin, B ``length`` m along), ENU."""
        return ABLine(np.zeros(2), np.array(self.line_to_enu(length, 0.0)))

    def place(self, path: ArcPath) -> ArcPath:
        """A path given in the line's frame (x, y in m; directions CCW from x) as the vehicle
        computer knows it: the same segments from the start point and direction in ENU."""
        return place_on_line(path, self.line_yaw)


@dataclass(frozen=True, slots=True)
class RoutePart:
    """One stretch of a route.

    Attributes
    ----------
    start, end
        Stations on :attr:`Route.path`, m (``start < end``).
    pass_index
        The field's pass (for a turn: the pass it leaves).
    kind
        ``"straight"``, ``"curve"`` or ``"turn"``.
    """

    start: float
    end: float
    pass_index: int
    kind: str


@dataclass(frozen=True)
class Route:
    """Passes and turns of a field as one path, with the table of its parts.

    Attributes
    ----------
    path
        The whole route, one tangent-continuous :class:`ArcPath` (station 0 = start of the first pass).
    parts
        :class:`RoutePart` in order, covering ``[0, path.length]`` without gaps.
    pass_indices
        The field's passes in the order driven.
    pass_spans
        ``(start, end)`` stations of each driven pass on :attr:`path`, m, in the same order.
    passes
        Each pass as driven (its own :class:`ArcPath`, station 0 at its start).
    """

    path: ArcPath
    parts: tuple[RoutePart, ...]
    pass_indices: tuple[int, ...]
    pass_spans: tuple[tuple[float, float], ...]
    passes: tuple[ArcPath, ...]

    def part_at(self, station: float) -> RoutePart:
        """The part that holds ``station`` m (the first before the start, the last past the end)."""
        starts = [p.start for p in self.parts]
        i = int(np.searchsorted(starts, station, side="right")) - 1
        return self.parts[min(max(i, 0), len(self.parts) - 1)]


@dataclass(frozen=True)
class Field:
    """Parallel passes one implement width apart.

    Attributes
    ----------
    name
        ``[A-Za-z0-9][A-Za-z0-9_-]{0,63}``.
    reference
        The reference pass.
    width
        Implement width = pass-to-pass spacing, m (0.5-60).
    passes
        Number of passes (1-500).
    reference_pass
        Index of the pass that is the reference itself (0 = the rightmost).
    """

    name: str
    reference: ArcPath
    width: float
    passes: int
    reference_pass: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise GeometryError(f"Field.name: expected [A-Za-z0-9][A-Za-z0-9_-]{{0,63}}, got {self.name!r}")
        if not isinstance(self.reference, ArcPath):
            raise GeometryError(f"Field.reference: expected an ArcPath, got {type(self.reference).__name__}")
        finite(self.width, "width", where="Field", lo=0.5, hi=60.0, unit="m", noun="an implement width",
               error=GeometryError)
        finite(self.passes, "passes", where="Field", lo=1, hi=500, integer=True, error=GeometryError)
        finite(self.reference_pass, "reference_pass", where="Field", lo=0, hi=self.passes - 1, integer=True,
               error=GeometryError)
        for i in range(self.passes):       # every pass must exist (offset refuses a cusp)
            self.pass_path(i)

    def offset_of(self, index: int) -> float:
        """Offset of pass ``index`` from the reference, m, + = left."""
        return (index - self.reference_pass) * float(self.width)

    def pass_path(self, index: int) -> ArcPath:
        """Pass ``index`` along the reference direction."""
        finite(index, "index", where="Field.pass_path", lo=0, hi=self.passes - 1, integer=True, noun="a pass index",
               error=GeometryError)
        d = self.offset_of(int(index))
        return self.reference if d == 0 else self.reference.offset(d)

    def route(self, limits: TurnLimits = TurnLimits(), first: int = 0, count: int | None = None) -> Route:
        """Passes ``first .. first + count - 1`` (default: to the last), alternately both ways, with U-turns.

        Each U-turn is :func:`gnss.uturn.plan_uturn` within ``limits``; the route is checked to
        be tangent-continuous (:meth:`ArcPath.chain`). Refused: a pass tighter than the
        tractor's minimum radius, or a curvature step from a pass into its turn (or out of it)
        faster than ``limits.sigma``.
        """
        finite(first, "first", where="Field.route", lo=0, hi=self.passes - 1, integer=True, noun="a pass index",
               error=GeometryError)
        last = self.passes - first if count is None else count
        finite(last, "count", where="Field.route", lo=1, hi=self.passes - first, integer=True,
               noun="an integer number of passes", error=GeometryError)
        indices = tuple(range(first, first + last))
        driven = [self.pass_path(i) if k % 2 == 0 else self.pass_path(i).reversed() for k, i in enumerate(indices)]
        pieces: list[ArcPath] = []
        kinds: list[tuple[float, int, str]] = []       # (length, pass, kind) in order
        for k, (i, p) in enumerate(zip(indices, driven)):
            tightest = max(abs(seg.curvature) for seg in p.segments)
            if tightest > limits.kappa_max:
                raise GeometryError(f"Field.route: pass {i} has a radius of {1 / tightest:.2f} m, below the tractor's "
                                    f"{limits.min_radius:.2f} m; use fewer passes or larger radii")
            for seg in p.segments:
                kinds.append((seg.length, i, "straight" if abs(seg.curvature) < STRAIGHT_CURVATURE else "curve"))
            pieces.append(p)
            if k + 1 < len(driven):
                nxt = driven[k + 1]
                turn = plan_uturn(p.end, p.end_angle, nxt.start, nxt.start_angle, limits)
                for a, b in ((p.segments[-1], turn.segments[0]), (turn.segments[-1], nxt.segments[0])):
                    rate = abs(b.curvature - a.curvature) / (0.5 * (a.length + b.length))
                    if rate > limits.sigma * (1 + 1e-9):
                        raise GeometryError(
                            f"Field.route: pass {i if a is p.segments[-1] else indices[k + 1]} ends on a curve "
                            f"(curvature {a.curvature if a is p.segments[-1] else b.curvature:.4f} 1/m) too short "
                            f"to steer out of at {limits.speed:g} m/s; end the reference pass with a straight")
                pieces.append(turn)
                kinds.append((turn.length, i, "turn"))
        path = ArcPath.chain(pieces, tolerance=1e-6)
        runs: list[list] = []            # [start, end, pass, kind], merged by (pass, kind)
        s = 0.0
        for length, i, kind in kinds:
            if runs and runs[-1][2] == i and runs[-1][3] == kind:
                runs[-1][1] = s + length
            else:
                runs.append([s, s + length, i, kind])
            s += length
        # a short straight between curves (a contour's inflection) belongs to the curve
        curved = {r[2] for r in runs if r[3] == "curve"}
        for r in runs:
            if r[3] == "straight" and r[2] in curved and r[1] - r[0] < MIN_STRAIGHT_LENGTH:
                r[3] = "curve"
        parts: list[RoutePart] = []
        for start, end, i, kind in runs:
            if parts and parts[-1].pass_index == i and parts[-1].kind == kind:
                parts[-1] = RoutePart(parts[-1].start, end, i, kind)
            else:
                parts.append(RoutePart(start, end, i, kind))
        parts[-1] = RoutePart(parts[-1].start, path.length, parts[-1].pass_index, parts[-1].kind)
        spans, s = [], 0.0
        for k, p in enumerate(driven):
            spans.append((s, s + p.length))
            s += p.length + (pieces[2 * k + 1].length if k + 1 < len(driven) else 0.0)
        return Route(path, tuple(parts), indices, tuple(spans), tuple(driven))

    @property
    def rows_length(self) -> float:
        """Sum of the passes' lengths, m."""
        return float(sum(self.pass_path(i).length for i in range(self.passes)))

