"""A field on the bench: its route in the simulator's frame, the start pose, the truth against the route.

The simulator's frame (x, y in m, directions counter-clockwise from x; :mod:`hil.truth.dynamics`)
is the frame the field's route is defined in: :meth:`gnss.field.Field.route` gives one
tangent-continuous :class:`~gnss.curve.ArcPath` of all the passes and the headland U-turns
between them, planned within this tractor's steering limits at the run's speed
(:func:`turn_limits`). :class:`~gnss.field.FieldGeometry` places that frame on the
Earth, so the vehicle loop follows the same route in ENU
(:meth:`~gnss.field.FieldGeometry.place`) with its own tracker, while the bench
scores the true CG against the route in the simulator's frame (:class:`RouteTruth`), with a
tracker of its own (the same local search, never the vehicle's).

The simulator's equations hold at any heading; of its disturbances, none depends on the
position ``X``: soil forces, the disker's pull and the ripper's forces act in the body frame,
and the side-slope roll is a random process along the distance travelled (mean
``field.roll_mean``, default 0) in the body frame too, so a field with a steady slope across it
(which would flip sign on the way back) is not modelled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gnss.curve import ArcPath
from gnss.field import Field, Route
from gnss.field_io import load_field
from gnss.track import PathTracker
from gnss.uturn import TurnLimits

from hil.devices.plant import SimulatedTractor
from hil.errors import SimulatorConfigError
from hil.truth.params import SimParams

#: Smallest change of curvature inside a pass that counts as a curve entry, 1/m.
ENTRY_KAPPA_STEP = 1e-4
#: Largest lateral acceleration of a planned headland turn, m/s^2 (assumption: the bench keeps the
#: gear's speed through the turn, where a driver would slow down; at 2.91 m/s the tightest turn the
#: wheel angle allows, 5.4 m, needs 1.6 m/s^2 and the disker's tractor slides off it).
MAX_TURN_LATERAL_ACCELERATION = 1.0
#: Fraction of the wheel-angle stop and of the steering rate a turn may use (TurnLimits.margin; assumption:
#: 0.8 left a controller without curvature feed-forward at full lock in a bulb turn, radius 7.4 m at 0.6).
TURN_MARGIN = 0.6


def turn_limits(params: SimParams, speed: float, max_rate: float = 0.35) -> TurnLimits:
    """The U-turn planner's limits for this tractor at ``speed`` m/s: its wheelbase and wheel-angle stop,
    the slower of its two steering directions capped at the loop's rate limit ``max_rate`` rad/s, and a
    margin that keeps the turn's curvature within :data:`MAX_TURN_LATERAL_ACCELERATION` at that speed."""
    st, wb = params.steering, params.vehicle.wheelbase
    rate = min(st.max_rate, st.max_rate * st.right_gain, max_rate)
    # kappa_max = tan(margin * stop) / wheelbase <= a_lat / V^2
    lateral = math.atan(wb * MAX_TURN_LATERAL_ACCELERATION / speed ** 2) / st.max_wheel_angle
    return TurnLimits(wheelbase=wb, max_wheel_angle=st.max_wheel_angle, max_steer_rate=rate, speed=speed,
                      margin=max(min(TURN_MARGIN, lateral), 0.05))


@dataclass(frozen=True)
class FieldRun:
    """A field as one run drives it.

    Attributes
    ----------
    field
        The field (passes, width).
    route
        Its route within the tractor's limits, in the simulator's frame.
    limits
        The limits the turns were planned with.
    """

    field: Field
    route: Route
    limits: TurnLimits

    @property
    def path(self) -> ArcPath:
        """The route's path, simulator frame."""
        return self.route.path

    def curve_entries(self) -> list[float]:
        """Stations (m) inside the passes where the curvature changes (curve entries and exits)."""
        out = []
        spans = self.route.pass_spans
        s = 0.0
        segs = self.path.segments
        for a, b in zip(segs, segs[1:]):
            s += a.length
            inside = any(lo + 1e-6 < s < hi - 1e-6 for lo, hi in spans)
            if inside and abs(b.curvature - a.curvature) > ENTRY_KAPPA_STEP:
                out.append(s)
        return out

    def start_state(self, station: float, cross_track: float, heading: float) -> dict[str, float]:
        """The simulator's initial ``X``, ``Y`` (m) and ``PSI`` (rad) for a start ``cross_track`` m to the left of
        the route at ``station`` m, heading ``heading`` rad counter-clockwise from the route's direction."""
        if not (math.isfinite(station) and -50.0 <= station <= self.path.length):
            raise SimulatorConfigError(f"start station must be within -50 m and the route's end "
                                       f"({self.path.length:.1f} m), got {station!r}")
        e, n, th = (float(v) for v in self.path.pose(station))
        return {"X": e - cross_track * math.sin(th), "Y": n + cross_track * math.cos(th), "PSI": th + heading}

    def describe(self) -> dict:
        """JSON-ready summary for a run's metadata."""
        return {"name": self.field.name, "width_m": float(self.field.width), "passes": list(self.route.pass_indices),
                "route_length_m": float(self.path.length),
                "parts": [{"start": p.start, "end": p.end, "pass_index": p.pass_index, "kind": p.kind}
                          for p in self.route.parts],
                "curve_entries_m": self.curve_entries(),
                "turn_limits": {"wheelbase_m": self.limits.wheelbase, "max_wheel_angle_rad": self.limits.max_wheel_angle,
                                "max_steer_rate_rad_s": self.limits.max_steer_rate, "speed_m_s": self.limits.speed,
                                "margin": self.limits.margin, "min_radius_m": self.limits.min_radius}}


def field_run(name_or_file: str, params: SimParams, speed: float, passes: int | None = None) -> FieldRun:
    """Load a named field or a field file and plan its route for this tractor at ``speed`` m/s
    (``passes``: only the first that many passes)."""
    fld = load_field(name_or_file)
    if passes is not None and not (isinstance(passes, int) and 1 <= passes <= fld.passes):
        raise SimulatorConfigError(f"passes must be 1-{fld.passes} for field {fld.name!r}, got {passes!r}")
    limits = turn_limits(params, speed)
    return FieldRun(fld, fld.route(limits, count=passes), limits)


class RouteTruth:
    """The simulated tractor's truth against the route, as the loop's ``truth`` callable.

    ``cross_track`` [m, + left], ``heading_error`` [rad], ``along_track`` (the station, m) and ``curvature``
    [1/m] of the CG against the route (simulator frame, local search from the start station),
    the plant's ``wheel_angle``, ``speed``, ``roll``, ``hitch_angle``, the CG's ``x``, ``y``
    [m] and heading ``psi`` [rad] in the simulator's frame, and ``implement_raised`` (1 or 0).

    With ``raise_in_turns`` the implement is raised while the CG is on a headland turn of the
    route and lowered when it reaches the next pass, as a driver does at the headland
    (:meth:`hil.truth.simulator.TractorSimulator.set_implement_raised`): a disker in the soil
    through a 5 m turn jackknifes its tractor off the path.
    """

    def __init__(self, plant: SimulatedTractor, route: Route, station: float, raise_in_turns: bool = True) -> None:
        self.plant = plant
        self.route = route
        self.tracker = PathTracker(route.path, station=station)
        self.raise_in_turns = raise_in_turns
        self._turns = [(p.start, p.end) for p in route.parts if p.kind == "turn"]
        self._t = plant.sim.time

    def __call__(self) -> dict[str, float]:
        raw = self.plant.truth()
        x, y, psi = raw["along_track"], raw["cross_track"], raw["heading_error"]
        now = self.plant.sim.time
        xte, he, station, kappa = self.tracker.update(x, y, math.pi / 2 - psi, max(now - self._t, 0.0))
        self._t = now
        sim = self.plant.sim
        if self.raise_in_turns:
            sim.set_implement_raised(any(a <= station < b for a, b in self._turns))
        return {"cross_track": xte, "heading_error": he, "along_track": station, "curvature": kappa,
                "wheel_angle": raw["wheel_angle"], "speed": raw["speed"], "roll": raw["roll"],
                "hitch_angle": raw["hitch_angle"], "x": x, "y": y, "psi": psi,
                "implement_raised": float(sim.implement_raised)}
