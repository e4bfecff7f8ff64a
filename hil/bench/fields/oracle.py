"""The oracle on a field's route: the truth-model LQG on the passes, a turn law over the headlands.

:class:`hil.bench.runs.oracle.OracleLQG` is designed about a straight line; on a field it is the bound
that the pass-to-pass spacing of the other controllers is measured against. On a
route it gets the path's curvature exactly as the linear controllers get it
(:class:`design.laws.curvature.Reference`: the cross-track, heading error and wheel angle relative
to the kinematic equilibrium on the curvature at the nearest point, the reference wheel angle's
change over the next step fed forward as a rate; no approach path, the oracle acquires its line
itself as on engage). Where the reference moves (a change of curvature) the oracle's prediction is
moved with it (``OracleLQG.step``'s ``reference_shift``), so its filter does not take the
reference's step for a disturbance. What the kinematic equilibrium leaves (tyre slip on a curve) is the
oracle's disturbance states' and integral's, as a pull is.

Over a headland turn (the loop's ``enter_part("turn")``, :data:`design.laws.curvature.ROUTE_PART_METHOD`)
the oracle hands the wheel to a turn law, by default the bench's pure pursuit
(:class:`design.laws.baselines.PurePursuitController`, its integral reset at the turn's start): a 7-9 m
U-turn is far outside the straight-line linearisation the oracle's model and filter are made on
and is not what it bounds. Leaving the turn, the oracle starts afresh as on engage (its filter from
the measurement, integral zero). With ``turn_law=None`` the oracle drives the turns too, with the
curvature feed-forward, and starts afresh at each pass likewise.

The spec ``oracle`` of a field run (:func:`hil.bench.fields.runs.field_controller`) is this
controller, designed for the run's condition with the options the AB-line campaign uses
(``OracleOptions(invert_valve=False)``); ``oracle?cross_track=0.025`` sets its LQR weights
(:class:`~hil.bench.runs.oracle.OracleWeights`).
"""

from __future__ import annotations

from design.laws.baselines import PurePursuitController
from design.laws.controller import Controller, Measurement
from design.laws.curvature import HEADLAND_KIND, Reference

from hil.bench.runs.oracle import OracleLQG, OracleOptions
from hil.errors import SimulatorConfigError
from hil.truth.conditions import Condition
from hil.truth.params import SimParams

#: Marker for "the default turn law" (pure pursuit with its default gains).
DEFAULT_TURN_LAW = "pure-pursuit"


class FieldOracle:
    """The oracle of one condition on a field's route (implements :class:`design.laws.controller.Controller`).

    Parameters
    ----------
    condition
        The condition it is designed for.
    params
        The simulator's parameters (defaults if ``None``).
    options
        The oracle's design options (default: ``OracleOptions(invert_valve=False)``, as the
        AB-line campaign's oracle).
    turn_law
        Controller that steers over the headland turns; :data:`DEFAULT_TURN_LAW` (pure pursuit),
        or ``None``: the oracle steers them too.
    """

    name = "oracle"

    def __init__(self, condition: Condition, params: SimParams | None = None, options: OracleOptions | None = None,
                 turn_law: Controller | str | None = DEFAULT_TURN_LAW) -> None:
        self.oracle = OracleLQG(condition, params, options or OracleOptions(invert_valve=False))
        self.dt = self.oracle.dt
        if isinstance(turn_law, str):
            if turn_law != DEFAULT_TURN_LAW:
                raise SimulatorConfigError(f"FieldOracle: turn_law must be a controller, None or "
                                           f"{DEFAULT_TURN_LAW!r}, got {turn_law!r}")
            turn_law = PurePursuitController(dt=self.dt)
        if turn_law is not None and not callable(getattr(turn_law, "step", None)):
            raise SimulatorConfigError(f"FieldOracle: turn_law must have step(measurement), got {type(turn_law).__name__}")
        self.turn_law = turn_law
        p = params or SimParams()
        self.reference = Reference(self.dt, p.steering.max_rate, latency=0.0, approach=False)
        n_ref, _ = self.reference.preview_request
        n_turn, dt_turn = getattr(turn_law, "preview_request", (0, self.dt)) if turn_law is not None else (0, self.dt)
        if n_turn and abs(dt_turn - self.dt) > 1e-12:
            raise SimulatorConfigError(f"FieldOracle: the turn law's preview step {dt_turn} s is not the oracle's "
                                       f"{self.dt} s")
        #: The curvature preview: the reference's (two stretches) or the turn law's, whichever is longer.
        self.preview_request = (max(n_ref, n_turn), self.dt)
        #: Headland turns the turn law has steered (over the run; not reset on engage).
        self.handovers = 0
        self.reset()

    @property
    def on_turn(self) -> bool:
        """The loop's station is on a headland turn (the turn law steers when there is one)."""
        return self._turn

    def reset(self) -> None:
        """Forget everything (the loop calls this on every engage)."""
        self.oracle.reset()
        self.reference.reset()
        if self.turn_law is not None and callable(getattr(self.turn_law, "reset", None)):
            self.turn_law.reset()
        self._turn = False
        self._ref: tuple[float, float] | None = None      # the reference's heading and wheel angle last step

    def enter_part(self, kind: str) -> None:
        """The loop's station entered a part of kind ``kind`` (:data:`design.laws.curvature.ROUTE_PART_METHOD`)."""
        on = kind == HEADLAND_KIND
        if on and not self._turn:
            if self.turn_law is not None:
                if callable(getattr(self.turn_law, "reset", None)):
                    self.turn_law.reset()
                self.handovers += 1
        elif self._turn and not on:
            self.oracle.reset()             # the next pass is acquired as on engage
            self._ref = None
        self._turn = on

    def step(self, m: Measurement) -> float:
        """The rate command, rad/s, + left: the turn law's on a headland turn, else the oracle's."""
        if self._turn and self.turn_law is not None:
            self.reference.track(m)          # keeps the reference in step (no approach path: stateless)
            return float(self.turn_law.step(m))
        dev, ff = self.reference.track(m)
        ref = (m.heading_error - dev.heading_error, m.wheel_angle - dev.wheel_angle)
        shift = None if self._ref is None else (0.0, ref[0] - self._ref[0], ref[1] - self._ref[1])
        self._ref = ref
        return self.oracle.step(dev, feedforward=ff, reference_shift=shift)

    def estimate(self) -> tuple[float, ...]:
        """The oracle's estimate of the undelayed physical states (SI, deviations from the trim)."""
        return self.oracle.estimate()
