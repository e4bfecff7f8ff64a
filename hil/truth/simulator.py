"""The truth simulator: a batch of tractors stepped together on one time grid.

Each tractor in the batch has its own condition and its own random streams (one
``numpy.random.SeedSequence`` each), so a tractor's run does not depend on what
else is in the batch. The simulator owns time: :meth:`TractorSimulator.step`
advances every tractor by ``dt`` with the PWM duty last set, records the GPS
epochs that fall on the grid, and :meth:`~TractorSimulator.wheel_angle_counts` samples the
potentiometer's ADC now.

Typical use (one tractor, as the emulated bridge drives it)::

    sim = TractorSimulator([condition_for("disker", 1.79)], duration=60.0, seeds=[7])
    sim.set_duty(np.array([0.5]))
    sim.step()
    counts = sim.wheel_angle_counts()
"""

from __future__ import annotations

import math
from array import array
from typing import Sequence

import numpy as np

from autosteer.checks import finite
from hil.truth import disturbances, dynamics as vehicle, gps_errors as gps
from hil.truth.conditions import Condition
from hil.errors import SimulatorConfigError
from hil.truth.params import SimParams
from hil.truth.steering import sensor_counts, sensor_counts_float, valve_rate
from hil.truth.dynamics import DEL, N_STATE, PSI, X, Y

SeedLike = int | np.random.SeedSequence

#: Exogenous channels that come from an implement in the soil: zero while it is raised.
SOIL_CHANNELS = ("ripper_force", "ripper_moment", "draft", "gang_pull")


def _seed_sequence(seed: SeedLike) -> np.random.SeedSequence:
    if isinstance(seed, np.random.SeedSequence):
        return seed
    finite(seed, "a seed", lo=0, integer=True, error=SimulatorConfigError)
    return np.random.SeedSequence(int(seed))


class TractorSimulator:
    """A batch of ``B`` simulated tractors.

    Parameters
    ----------
    conditions
        One :class:`~hil.truth.conditions.Condition` per tractor.
    duration
        Longest time the batch will be run, s (> 0); exogenous inputs and GPS
        errors are drawn for it up front.
    seeds
        One seed (int or ``SeedSequence``) per tractor.
    params
        Simulator parameters (defaults: :class:`~hil.truth.params.SimParams`).
    initial
        Optional initial values ``{"Y": m, "PSI": rad, "DEL": rad}`` per tractor, shape ``(B,)``.
    scalar
        Integrate a one-tractor batch with the compiled stepper (:class:`hil.truth.dynamics.Stepper`)
        and keep its state as one row of 8 values (many times faster for ``B == 1``, the HIL case; agrees with the
        array path to rounding). The GPS epochs are recorded by the same array functions either way.
    """

    def __init__(self, conditions: Sequence[Condition], duration: float, seeds: Sequence[SeedLike],
                 params: SimParams | None = None, initial: dict[str, np.ndarray] | None = None,
                 scalar: bool = False) -> None:
        if len(conditions) == 0:
            raise SimulatorConfigError("at least one condition is needed")
        if len(seeds) != len(conditions):
            raise SimulatorConfigError(f"{len(conditions)} conditions but {len(seeds)} seeds; give one each")
        if not isinstance(duration, (int, float)) or not np.isfinite(duration) or duration <= 0:
            raise SimulatorConfigError(f"duration must be a finite number of seconds > 0, got {duration!r}")
        self.params = p = params or SimParams()
        self.conditions = tuple(conditions)
        self.B = B = len(conditions)
        self.n_steps = int(np.ceil(duration / p.dt - 1e-9))
        self.duration = self.n_steps * p.dt
        n = self.n_steps + 1
        exo, errs, sens = [], [], []
        for cond, seed in zip(conditions, seeds):
            s_exo, s_gps, s_sensor = _seed_sequence(seed).spawn(3)
            exo.append(disturbances.generate(cond, p, n, np.random.default_rng(s_exo)))
            errs.append(gps.draw_errors(p.gps, self.duration, np.random.default_rng(s_gps)))
            sens.append(np.random.default_rng(s_sensor).standard_normal(n) * p.sensor.noise)
        self.exo = disturbances.stack(exo)
        self.gps_errors = gps.stack_errors(errs)
        self._sensor_noise = np.stack(sens)
        self._disker = np.array([c.implement == "disker" for c in conditions], dtype=float)
        # front load with the implement raised: its static weight transfer, without the hop of the draft
        self._raised_front_load = np.array([p.ripper.front_load_factor if c.implement == "ripper" else
                                            p.disker.front_load_factor if c.implement == "disker" else 1.0
                                            for c in conditions])
        self._in_soil: dict[str, np.ndarray] | None = None   # the drawn soil channels, kept while raised
        self.implement_raised = False
        self._x: np.ndarray | None = None   # the one-tractor path's state (8 values), see `state`
        self.state = np.zeros((B, N_STATE))
        for name, values in (initial or {}).items():
            if name not in vehicle.STATE_NAMES:
                raise SimulatorConfigError(f"unknown initial state {name!r}; use {vehicle.STATE_NAMES}")
            arr = np.broadcast_to(np.asarray(values, dtype=float), (B,))
            if not np.all(np.isfinite(arr)):
                raise SimulatorConfigError(f"initial {name} must be finite")
            self._state[:, vehicle.STATE_NAMES.index(name)] = arr
        dmax = p.steering.max_wheel_angle
        self._state[:, DEL] = np.clip(self._state[:, DEL], -dmax, dmax)
        self.k = 0
        self.duty = np.zeros(B)
        self._rate_cmd = valve_rate(self.duty, p.steering)
        if scalar and B != 1:
            raise SimulatorConfigError(f"the scalar path integrates one tractor, this batch has {B}")
        # the one-tractor path reads speed and roll per step as floats (truth, GPS epochs)
        self._scalar_exo = {f: _doubles(getattr(self.exo, f)[0]) for f in ("speed", "roll")} if scalar else None
        if scalar:
            # the one-tractor path: the compiled stepper over the run's table of inputs, the state as one row
            self._stepper = vehicle.stepper(p)
            self._inputs = np.ascontiguousarray(
                np.column_stack([getattr(self.exo, f)[0] for f in vehicle.STEP_INPUTS]), dtype=np.float64)
            self._valve_rates: dict[float, float] = {}   # valve_rate by duty (a pure function of it), kept
            self._x = self._state[0].copy()
            self._disker0 = float(self._disker[0])
            self._rate0 = float(self._rate_cmd[0])
            self._noise0 = _doubles(self._sensor_noise[0])
        g = p.gps
        self._pos_every = int(round(1.0 / (g.position_rate * p.dt)))
        self._att_every = int(round(1.0 / (g.attitude_rate * p.dt)))
        self._next_epoch = min(self._pos_every, self._att_every)   # the one-tractor path's next epoch step
        n_pos = self.gps_errors.pos_lost.shape[1]
        n_att = self.gps_errors.att_lost.shape[1]
        self.pos = {k: np.zeros((B, n_pos)) for k in ("x", "y", "fix", "t_arrival", "speed")}
        self.pos["lost"] = np.zeros((B, n_pos), dtype=bool)
        self.att = {k: np.zeros((B, n_att)) for k in ("yaw", "roll", "pitch", "t_arrival")}
        self.att["lost"] = np.zeros((B, n_att), dtype=bool)
        self.n_pos = self.n_att = 0
        self._record_epochs()

    @property
    def state(self) -> np.ndarray:
        """State of every tractor, shape ``(B, 8)`` (columns :data:`hil.truth.dynamics.STATE_NAMES`); a copy
        on the one-tractor path, which keeps the state as one row of its own."""
        return self._state if self._x is None else np.array([self._x])

    @state.setter
    def state(self, value: np.ndarray) -> None:
        if self._x is not None:
            raise SimulatorConfigError("the one-tractor path owns its state; it cannot be assigned")
        self._state = value

    # -- time ---------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulation time, s."""
        return self.k * self.params.dt

    def set_duty(self, duty: np.ndarray) -> None:
        """Set the valve PWM duty of every tractor, in [-1, 1], + = left; held until changed."""
        d = np.broadcast_to(np.asarray(duty, dtype=float), (self.B,))
        if not np.all(np.isfinite(d)):
            raise SimulatorConfigError("valve duty must be finite")
        self.duty = np.clip(d, -1.0, 1.0).copy()
        self._rate_cmd = valve_rate(self.duty, self.params.steering)
        if self._scalar_exo is not None:
            self._rate0 = float(self._rate_cmd[0])

    def set_duty_scalar(self, duty: float) -> None:
        """:meth:`set_duty` for a one-tractor batch, from a float (no arrays on the scalar path)."""
        if self._scalar_exo is None:
            self.set_duty(np.array([duty]))
            return
        if not math.isfinite(duty):
            raise SimulatorConfigError("valve duty must be finite")
        d = min(max(float(duty), -1.0), 1.0)
        self.duty[0] = d
        rate = self._valve_rates.get(d) if d != 0.0 else None   # (0.0 and -0.0 are one key: not kept)
        if rate is None:
            rate = float(valve_rate(d, self.params.steering))
            if d != 0.0 and len(self._valve_rates) < 1 << 16:
                self._valve_rates[d] = rate
        self._rate0 = rate
        self._rate_cmd[0] = rate

    def set_implement_raised(self, raised: bool) -> None:
        """Raise (``True``: at a headland) or lower every tractor's implement from the current step on.

        Raised, an implement is out of the soil: its soil forces (:data:`SOIL_CHANNELS`: the ripper's
        lateral force and moment, the disker's draft and gang pull) are zero and the front load is
        its static weight transfer without hop; a towed disker still trails on its hitch. Lowered,
        the drawn sequences apply again from the current step.
        """
        raised = bool(raised)
        if raised == self.implement_raised:
            return
        k = self.k
        if self._in_soil is None:
            self._in_soil = {f: getattr(self.exo, f).copy() for f in (*SOIL_CHANNELS, "front_load")}
        for f, drawn in self._in_soil.items():
            arr = getattr(self.exo, f)
            if not raised:
                arr[:, k:] = drawn[:, k:]
            elif f == "front_load":
                arr[:, k:] = self._raised_front_load[:, None]
            else:
                arr[:, k:] = 0.0
            if self._scalar_exo is not None:
                self._inputs[k:, vehicle.STEP_INPUTS.index(f)] = arr[0, k:len(self._inputs)]
        self.implement_raised = raised

    def step(self) -> None:
        """Advance every tractor by one integration step ``dt``."""
        self.steps(1)

    def steps(self, n: int) -> None:
        """Advance every tractor by ``n`` integration steps with the duties held, recording the GPS
        epochs on the way."""
        if self.k + n > self.n_steps:
            raise SimulatorConfigError(f"the simulator was built for {self.duration:.2f} s and has reached it")
        if self._scalar_exo is None:
            for _ in range(n):
                self._batch_step()
            return
        k0 = self.k
        end = k0 + n
        states = self._stepper.steps(self._x, self._rate0, self._disker0, self._inputs[k0:end])
        while self._next_epoch <= end:   # the steps that record an epoch, from the states at those steps
            k = self._next_epoch
            self._x, self.k = states[k - k0 - 1], k
            self._record_epochs()
            self._next_epoch = min((k // self._pos_every + 1) * self._pos_every,
                                   (k // self._att_every + 1) * self._att_every)
        self._x, self.k = states[-1], end

    def _batch_step(self) -> None:
        k, e = self.k, self.exo
        u = vehicle.Inputs(rate_cmd=self._rate_cmd, speed=e.speed[:, k],
                           roll=e.roll[:, k], force_y=e.force_y[:, k], ripper_force=e.ripper_force[:, k],
                           ripper_moment=e.ripper_moment[:, k], draft=e.draft[:, k],
                           gang_pull=e.gang_pull[:, k], front_load=e.front_load[:, k], disker=self._disker)
        self.state = vehicle.rk4_step(self.state, u, self.params)
        self.k += 1
        self._record_epochs()

    # -- sensors ------------------------------------------------------------------
    def wheel_angle_counts(self) -> np.ndarray:
        """Potentiometer read by the 8-bit ADC now: int counts 0..255, shape ``(B,)``."""
        p = self.params
        return sensor_counts(self.state[:, DEL], self._sensor_noise[:, self.k], p.sensor, p.steering)

    def wheel_angle_count(self) -> int:
        """:meth:`wheel_angle_counts` of a one-tractor batch as an int (floats on the scalar path)."""
        if self._scalar_exo is None:
            return int(self.wheel_angle_counts()[0])
        p = self.params
        counts = sensor_counts_float(float(self._x[DEL]), p.sensor, p.steering) + self._noise0[self.k]
        return int(min(max(round(counts), 0), 255))   # sensor_counts's rint and clip, on a float

    def truth_scalar(self) -> dict[str, float]:
        """:meth:`truth` of a one-tractor batch, as floats."""
        if self._scalar_exo is None:
            return {k: float(v[0]) for k, v in self.truth().items()}
        x, k, e = self._x.tolist(), self.k, self._scalar_exo
        return {"cross_track": x[Y], "heading_error": x[PSI], "wheel_angle": x[DEL], "speed": e["speed"][k],
                "roll": e["roll"][k], "along_track": x[X], "hitch_angle": x[vehicle.PHI]}

    def truth(self) -> dict[str, np.ndarray]:
        """True values now: ``cross_track`` [m, CG, + left], ``heading_error`` [rad],
        ``wheel_angle`` [rad], ``speed`` [m/s], ``roll`` [rad], ``along_track`` [m],
        ``hitch_angle`` [rad]."""
        s, k = self.state, self.k
        return {"cross_track": s[:, Y].copy(), "heading_error": s[:, PSI].copy(),
                "wheel_angle": s[:, DEL].copy(), "speed": self.exo.speed[:, k].copy(),
                "roll": self.exo.roll[:, k].copy(), "along_track": s[:, X].copy(),
                "hitch_angle": s[:, vehicle.PHI].copy()}

    def _record_epochs(self) -> None:
        p, k, s = self.params, self.k, self.state
        roll = self.exo.roll[:, k]
        if k % self._pos_every == 0 and self.n_pos < self.pos["lost"].shape[1]:
            i = self.n_pos
            m = gps.position_epoch(s[:, X], s[:, Y], s[:, PSI], roll, i, self.gps_errors, p.gps, p.vehicle)
            ground = np.hypot(self.exo.speed[:, k], s[:, vehicle.V])
            m["speed"] = np.maximum(ground + self.gps_errors.speed_noise[:, i], 0.0)
            for key, arr in self.pos.items():
                arr[:, i] = m[key]
            self.n_pos += 1
        if k % self._att_every == 0 and self.n_att < self.att["lost"].shape[1]:
            i = self.n_att
            m = gps.attitude_epoch(s[:, PSI], roll, i, self.gps_errors, p.gps)
            for key, arr in self.att.items():
                arr[:, i] = m[key]
            self.n_att += 1

    #: How many of the newest epochs :meth:`latest_position` / :meth:`latest_attitude` look at.
    LOOKBACK = 50

    @classmethod
    def _latest(cls, block: dict[str, np.ndarray], count: int, now: float) -> np.ndarray:
        """Index of the newest epoch that arrived by ``now`` and was not lost; -1 if none of
        the last :attr:`LOOKBACK` epochs qualifies (the data is then stale)."""
        lo = max(0, count - cls.LOOKBACK)
        arrived = (block["t_arrival"][:, lo:count] <= now) & ~block["lost"][:, lo:count]
        idx = np.where(arrived, np.arange(lo, count), -1)
        return idx.max(axis=1) if count > lo else np.full(block["lost"].shape[0], -1)

    def latest_position(self, now: float) -> np.ndarray:
        """Per tractor, index into ``pos`` of the newest position that arrived by ``now`` [s]."""
        return self._latest(self.pos, self.n_pos, now)

    def latest_attitude(self, now: float) -> np.ndarray:
        """Per tractor, index into ``att`` of the newest attitude that arrived by ``now`` [s]."""
        return self._latest(self.att, self.n_att, now)


def _doubles(values: np.ndarray) -> array:
    """``values`` as an ``array.array`` of C doubles: indexed like the list ``tolist()`` gives (the
    same floats), far cheaper to build for a whole run, and nothing for the garbage collector."""
    return array("d", np.asarray(values, dtype=np.float64).tobytes())
