"""Open-loop identification passes like the paper's (its Figure 5).

A driver, through the control computer, slews the steering left or right at the
maximum rate and in between commands zero rate, choosing each slew's direction
so as to stay roughly on the line: a ternary, pseudo-random, maximum-power input.
Slew and hold lengths and the direction's randomness are drawn from the pass's
own generator; the direction rule uses only what the computer measured (latest
GPS cross-track and heading, calibrated wheel angle), so the same rule can run
against real devices.

Time bases of the resulting logs (DESIGN section 4): the bridge samples the
potentiometer every 50 ms and its report reaches the host ``sensor.latency``
later; ``t`` is that arrival time, when the host also issues its command.
Position and speed are stamped with their arrival (5 Hz), attitude likewise
(10 Hz); lost epochs are missing. Truth channels on ``t`` are added for
evaluation (``truth_*``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from identification.passlog import PassLog

from hil.truth.conditions import GEAR_SPEEDS, IMPLEMENTS, Condition, condition_for
from hil.errors import SimulatorConfigError
from hil.truth.gps_errors import control_point_from_antenna
from hil.truth.params import SimParams
from hil.truth.simulator import TractorSimulator
from hil.vehicle.valve_map import ValveCurve
from hil.truth.steering import nominal_duty
from hil.devices.technician import two_point_calibration


@dataclass(frozen=True)
class DriverExcitation:
    """How the identification driver steers (all assumptions, shaped on the paper's Figure 5).

    Attributes
    ----------
    slew_min, slew_max
        Range of one slew's length, s (uniform).
    hold_min, hold_max
        Range of one zero-rate stretch, s (uniform).
    soft_limit
        Wheel angle at which a slew is cut short, rad.
    direction_noise
        1-sigma randomness added to the wanted wheel-angle change when picking a direction, rad.
    settle
        Zero-rate time at the start of a pass, s.
    """

    slew_min: float = 0.2
    slew_max: float = 0.5
    hold_min: float = 0.3
    hold_max: float = 1.2
    soft_limit: float = 0.2
    direction_noise: float = 0.04
    settle: float = 2.0

    def __post_init__(self) -> None:
        for k, v in self.__dict__.items():
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise SimulatorConfigError(f"DriverExcitation.{k} must be a finite number >= 0, got {v!r}")
        if self.slew_min > self.slew_max or self.hold_min > self.hold_max or self.slew_max == 0:
            raise SimulatorConfigError("DriverExcitation: need 0 < slew_min <= slew_max and hold_min <= hold_max")


@dataclass(frozen=True)
class SysidPlan:
    """Which passes to make.

    Parameters
    ----------
    speeds
        Nominal speeds, m/s (default: the paper's five gears).
    implements
        Implements (default: none, disker, ripper).
    passes
        Passes per condition (>= 1).
    duration
        Length of each pass, s (> 0).
    seed
        Master seed (>= 0); pass ``i`` of a condition gets its own stream derived from it.
    """

    speeds: tuple[float, ...] = tuple(GEAR_SPEEDS.values())
    implements: tuple[str, ...] = IMPLEMENTS
    passes: int = 3
    duration: float = 120.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.speeds or not self.implements:
            raise SimulatorConfigError("need at least one speed and one implement")
        for v in self.speeds:
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0.2 <= v <= 6.0):
                raise SimulatorConfigError(f"speed {v!r} m/s is outside the identification range 0.2..6 m/s")
        for i in self.implements:
            if i not in IMPLEMENTS:
                raise SimulatorConfigError(f"unknown implement {i!r}; expected one of {list(IMPLEMENTS)}")
        if isinstance(self.passes, bool) or not isinstance(self.passes, int) or self.passes < 1:
            raise SimulatorConfigError(f"passes must be an integer >= 1, got {self.passes!r}")
        if not (isinstance(self.duration, (int, float)) and math.isfinite(self.duration)
                and 5.0 <= self.duration <= 3600.0):
            raise SimulatorConfigError(f"duration must be between 5 and 3600 s, got {self.duration!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise SimulatorConfigError(f"seed must be an integer >= 0, got {self.seed!r}")

    def conditions(self) -> list[Condition]:
        return [condition_for(i, float(v)) for i in self.implements for v in self.speeds]


def pass_seed(seed: int, cond: Condition, index: int) -> np.random.SeedSequence:
    """The random stream of pass ``index`` of a condition: independent of the rest of the plan."""
    speed_mm = int(round(cond.speed * 1000))
    return np.random.SeedSequence(seed, spawn_key=(IMPLEMENTS.index(cond.implement), speed_mm, index))


def pass_name(cond: Condition, index: int) -> str:
    """File stem of a pass log, e.g. ``ripper_9th_pass0``."""
    return f"{cond.name}_pass{index}"


def make_passes(plan: SysidPlan, params: SimParams | None = None,
                driver: DriverExcitation | None = None,
                progress: Callable[[int, int], None] | None = None,
                valve: ValveCurve | None = None) -> list[tuple[str, PassLog]]:
    """Simulate every pass of ``plan`` (as one batch) and return ``(name, log)`` pairs.

    Parameters
    ----------
    plan
        Conditions, passes per condition, duration and seed.
    params
        Simulator parameters.
    driver
        Excitation rule.
    progress
        Called as ``progress(done_steps, total_steps)`` now and then.
    valve
        A commissioned tractor's measured valve: the driver slews at its ``max_rate`` and the
        duty is that of its inverse map for the bridge's full scale (as the commissioned loop
        drives it; ``meta["valve_map"]``). ``None``: the nominal duty of :func:`nominal_duty`.
    """
    params = params or SimParams()
    driver = driver or DriverExcitation()
    jobs = [(c, i) for c in plan.conditions() for i in range(plan.passes)]
    conds = [c for c, _ in jobs]
    seeds = [pass_seed(plan.seed, c, i) for c, i in jobs]
    # the driver's own random draws come from a stream separate from the simulator's
    sim_seeds, drv_seeds = zip(*(s.spawn(2) for s in seeds))
    sim = TractorSimulator(conds, plan.duration, list(sim_seeds), params)
    logs = _run_driver(sim, driver, [np.random.default_rng(s) for s in drv_seeds], progress, valve)
    out = []
    for (cond, i), seed_seq, channels in zip(jobs, seeds, logs):
        meta = _meta(cond, i, plan, params, driver)
        if valve is not None:
            meta["valve_map"] = valve.to_dict()
        out.append((pass_name(cond, i), PassLog(times=channels[0], channels=channels[1], meta=meta)))
    return out


def _run_driver(sim: TractorSimulator, drv: DriverExcitation, rngs: Sequence[np.random.Generator],
                progress: Callable[[int, int], None] | None, valve: ValveCurve | None = None):
    p = sim.params
    B = sim.B
    sub = int(round(1.0 / (p.sensor.rate * p.dt)))           # integration steps per report
    lag = int(round(p.sensor.latency / p.dt))                 # report latency in steps
    n_ticks = (sim.n_steps - lag) // sub
    cal = two_point_calibration(p.sensor, p.steering)
    max_rate = p.steering.max_rate if valve is None else valve.max_rate
    wheelbase = p.vehicle.wheelbase
    n_dec = int(sim.duration / min(drv.slew_min, drv.hold_min, 0.05) + 16)
    u_len = np.stack([r.random(n_dec) for r in rngs])
    u_dir = np.stack([r.standard_normal(n_dec) for r in rngs])
    nominal = np.array([c.speed for c in sim.conditions])
    lookahead = np.maximum(4.0, 3.0 * nominal)               # the driver looks further ahead when faster
    mode = np.zeros(B)
    t_end = np.full(B, drv.settle)
    n_made = np.zeros(B, dtype=int)
    rows = np.arange(B)
    rec = {k: np.zeros((B, n_ticks)) for k in ("t", "wheel_angle", "steer_rate_cmd", "truth_cross_track",
                                               "truth_heading_error", "truth_wheel_angle", "truth_speed")}
    for j in range(n_ticks):
        while sim.k < j * sub:
            sim.step()
        counts = sim.wheel_angle_counts()                   # sampled now, arrives `lag` steps later
        for _ in range(lag):
            sim.step()
        now = sim.time
        delta_m = cal.to_angle(counts)
        ip, ia = sim.latest_position(now), sim.latest_attitude(now)
        yaw = np.where(ia >= 0, sim.att["yaw"][rows, ia], 0.0)
        roll = np.where(ia >= 0, sim.att["roll"][rows, ia], 0.0)
        y_ant = np.where(ip >= 0, sim.pos["y"][rows, ip], 0.0)
        y_m = control_point_from_antenna(y_ant, yaw, roll, p.vehicle)
        # end a slew early at the soft limit; then choose the next stretch when one ends
        mode = np.where((mode > 0) & (delta_m >= drv.soft_limit), 0.0, mode)
        mode = np.where((mode < 0) & (delta_m <= -drv.soft_limit), 0.0, mode)
        due = now >= t_end
        if np.any(due):
            idx = np.minimum(n_made, n_dec - 1)
            ul, ud = u_len[rows, idx], u_dir[rows, idx]
            want = np.clip(-(2.0 * wheelbase / lookahead ** 2) * (y_m + lookahead * yaw),
                           -drv.soft_limit, drv.soft_limit)
            direction = np.sign(want - delta_m + drv.direction_noise * ud)
            slew_len = drv.slew_min + ul * (drv.slew_max - drv.slew_min)
            hold_len = drv.hold_min + ul * (drv.hold_max - drv.hold_min)
            start_slew = due & (mode == 0)
            new_mode = np.where(start_slew, direction, 0.0)
            mode = np.where(due, new_mode, mode)
            t_end = np.where(due, now + np.where(start_slew, slew_len, hold_len), t_end)
            n_made = n_made + due
        rate_cmd = mode * max_rate
        if valve is None:
            sim.set_duty(nominal_duty(rate_cmd, p.steering))
        else:
            sim.set_duty(np.array([valve.command_for(float(r)) for r in rate_cmd]) / valve.full_scale)
        tr = sim.truth()
        for key, val in (("t", now), ("wheel_angle", delta_m), ("steer_rate_cmd", rate_cmd),
                         ("truth_cross_track", tr["cross_track"]), ("truth_heading_error", tr["heading_error"]),
                         ("truth_wheel_angle", tr["wheel_angle"]), ("truth_speed", tr["speed"])):
            rec[key][:, j] = val
        if progress is not None and j % 100 == 0:
            progress(sim.k, sim.n_steps)
    if progress is not None:
        progress(sim.n_steps, sim.n_steps)
    return [_channels(sim, b, rec) for b in range(B)]


def _channels(sim: TractorSimulator, b: int, rec: dict[str, np.ndarray]):
    p = sim.params
    pos, att = sim.pos, sim.att
    keep_p = ~pos["lost"][b, :sim.n_pos]
    keep_a = ~att["lost"][b, :sim.n_att]
    t_pos = pos["t_arrival"][b, :sim.n_pos][keep_p]
    t_att_all = att["t_arrival"][b, :sim.n_att]
    # lever-arm/roll compensation with the newest attitude whose valid time is not after the fix's
    valid_pos = np.flatnonzero(keep_p) / p.gps.position_rate
    valid_att = np.flatnonzero(keep_a) / p.gps.attitude_rate
    ia = np.searchsorted(valid_att, valid_pos + 1e-9, side="right") - 1
    yaw_a = att["yaw"][b, :sim.n_att][keep_a]
    roll_a = att["roll"][b, :sim.n_att][keep_a]
    yaw_c = np.where(ia >= 0, yaw_a[np.maximum(ia, 0)], 0.0)
    roll_c = np.where(ia >= 0, roll_a[np.maximum(ia, 0)], 0.0)
    xt = control_point_from_antenna(pos["y"][b, :sim.n_pos][keep_p], yaw_c, roll_c, p.vehicle)
    times = {"t": rec["t"][b], "t_cross_track": t_pos, "t_heading_error": t_att_all[keep_a],
             "t_speed": t_pos}
    chans = {"wheel_angle": rec["wheel_angle"][b], "steer_rate_cmd": rec["steer_rate_cmd"][b],
             "cross_track": xt, "heading_error": yaw_a, "speed": pos["speed"][b, :sim.n_pos][keep_p],
             "fix_quality": pos["fix"][b, :sim.n_pos][keep_p], "roll": roll_a}
    for k in ("truth_cross_track", "truth_heading_error", "truth_wheel_angle", "truth_speed"):
        chans[k] = rec[k][b]
    return times, chans


_EXTRA = {"fix_quality": {"time": "t_cross_track", "unit": "1", "doc": "GGA fix quality, 4 fixed, 5 float"},
          "roll": {"time": "t_heading_error", "unit": "rad", "doc": "measured roll, + = left side up"},
          "truth_cross_track": {"time": "t", "unit": "m", "doc": "true cross-track of the control point"},
          "truth_heading_error": {"time": "t", "unit": "rad", "doc": "true heading error"},
          "truth_wheel_angle": {"time": "t", "unit": "rad", "doc": "true wheel angle"},
          "truth_speed": {"time": "t", "unit": "m/s", "doc": "true longitudinal speed"}}


def _meta(cond: Condition, index: int, plan: SysidPlan, params: SimParams, drv: DriverExcitation) -> dict:
    g = params.gps
    return {
        "implement": cond.implement, "nominal_speed": cond.speed, "gear": cond.gear,
        "condition": cond.name, "pass_index": index, "seed": plan.seed,
        "source": "hil.bench.sysid (simulated open-loop identification pass)",
        "sample_rates_hz": {"wheel_angle": params.sensor.rate, "steer_rate_cmd": params.sensor.rate,
                            "cross_track": g.position_rate, "speed": g.position_rate,
                            "heading_error": g.attitude_rate},
        "latency_s": {"wheel_angle": params.sensor.latency, "steer_rate_cmd": 0.0,
                      "cross_track": g.position_latency, "speed": g.position_latency,
                      "heading_error": g.attitude_latency},
        "time_stamps": "arrival at the host, s since the start of the pass",
        "control_point": "CG on the ground",
        "extra_channels": _EXTRA,
        "simulator": params.to_dict(),
        "driver": dict(drv.__dict__),
    }
