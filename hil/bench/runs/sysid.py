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

from autosteer.checks import finite
from identification.passlog import PassLog

from hil.truth.conditions import GEAR_SPEEDS, IMPLEMENTS, Condition, condition_for
from hil.errors import SimulatorConfigError
from hil.truth.gps_errors import control_point_from_antenna
from hil.truth.params import SimParams
from hil.truth.simulator import TractorSimulator
from hil.vehicle.valve_map import ValveCurve
from hil.vehicle.excitation import ExcitationSettings, SlewRule
from hil.truth.steering import nominal_duty
from hil.devices.wheel_calibration import two_point_calibration
from hil.devices.plant import SimulatedTractor
from hil.bench.benches.agio import AgioLockstepBench
from hil.bench.benches.isobus import IsobusLockstepBench
from hil.vehicle.agio.driver import AgioDriverConfig
from hil.vehicle.isobus.driver import ANGLE_CALIBRATION as ISOBUS_CALIBRATION, IsobusDriverConfig, IsobusReport
from hil.vehicle.isobus.link import isobus_driver_config
from hil.vehicle.isobus.protocol import Lockout, Readiness, ResetStatus
from hil.devices.steer_module import SteerModuleConfig

#: Bridges an identification pass can steer through.
BRIDGES = ("hc11", "agopengps", "isobus")

SYSID_MODULE_DRIVER = AgioDriverConfig(max_lead=0.3, max_windup=0.3)
"""The host driver's settings for identification passes through a steer module: the loop's
(:class:`AgioDriverConfig`) with the setpoint and its integral allowed 0.3 rad from the measured angle
instead of 0.1 and 0.03 (``max_lead``, ``max_windup``), so the excitation sees the module's own angle
loop and not the loop's protective limits (with the loop's limits, 624-829 of 760-813 non-zero commands of
a 120 s pass were limited, none with 0.3).
A slew at full rate puts the integral about ``max_rate x`` the module's lag (0.25 s) ahead of the wheel, and
the lead adds ``lead_time x max_rate`` more (0.0875 rad): about 0.175 rad, so with the loop's 0.1 the limit
cut the setpoint in nearly every slew (768 of 2400 commands a pass, 15 conditions x 3 passes of 120 s,
seed 1997; 0 with 0.3). The models then saw a module slower than its small-signal self, and the robust
controller designed on them (the README's recipe) tracked at 11.1 / 15.4 cm (none, 2.91 m/s, seeds 0 / 1)
against 4.0 / 5.5 cm with 0.3. The limit only guards against wind-up when the wheel cannot follow; the
excitation's slews are bounded (``slew_max`` at ``max_rate``), so it has nothing to guard here."""


#: The open-loop passes have no corridor: one far beyond any field (m), so the rule never steers back itself.
OPEN_LOOP_CORRIDOR = 1e9


@dataclass(frozen=True)
class DriverExcitation(ExcitationSettings):
    """How the identification driver steers the open-loop passes: the runtime's slews
    (:class:`hil.vehicle.excitation.ExcitationSettings`, shaped on the paper's Figure 5) without the servo, the
    offset or the corridor, so only each slew's direction steers back towards the line."""

    servo: float = 0.0
    offset: float = 0.0
    predict: bool = False
    return_at: float = OPEN_LOOP_CORRIDOR / 2
    corridor: float = OPEN_LOOP_CORRIDOR


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
    first_index
        Index of the first pass of each condition (>= 0): passes ``first_index .. first_index + passes - 1``
        are made, so more passes for a condition are new streams that never repeat the earlier ones.
    """

    speeds: tuple[float, ...] = tuple(GEAR_SPEEDS.values())
    implements: tuple[str, ...] = IMPLEMENTS
    passes: int = 3
    duration: float = 120.0
    seed: int = 0
    first_index: int = 0

    def __post_init__(self) -> None:
        if not self.speeds or not self.implements:
            raise SimulatorConfigError("need at least one speed and one implement")
        for v in self.speeds:
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0.2 <= v <= 6.0):
                raise SimulatorConfigError(f"speed {v!r} m/s is outside the identification range 0.2..6 m/s")
        for i in self.implements:
            if i not in IMPLEMENTS:
                raise SimulatorConfigError(f"unknown implement {i!r}; expected one of {list(IMPLEMENTS)}")
        finite(self.passes, "passes", lo=1, integer=True, error=SimulatorConfigError)
        finite(self.duration, "duration", lo=5.0, hi=3600.0, unit="s", error=SimulatorConfigError)
        finite(self.seed, "seed", lo=0, integer=True, error=SimulatorConfigError)
        finite(self.first_index, "first_index", lo=0, integer=True, error=SimulatorConfigError)

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
                valve: ValveCurve | None = None, bridge: str = "hc11",
                module_driver: AgioDriverConfig | IsobusDriverConfig | None = None) -> list[tuple[str, PassLog]]:
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
    bridge
        ``hc11`` (default): the rate command sets the simulator's valve duty, as the HC11 board
        drives the valve open loop (all passes as one batch). ``agopengps``: every pass steers through an emulated
        AgOpenGPS steer module on the lockstep bench (:class:`~hil.bench.benches.agio.AgioLockstepBench`):
        the rate command goes to the host driver, which integrates it into the module's setpoint as
        the vehicle loop's driver does (bumpless engage, limits, lead), and the logged wheel angle is
        the module's PGN 253 angle, so the models include the module's own angle loop. ``isobus``: every
        pass steers through an emulated ISO 11783 steering controller on a python-can virtual bus
        (:class:`~hil.bench.benches.isobus.IsobusLockstepBench`): the host driver integrates the rate
        command into a curvature, commanded "intended to steer" after the handshake, and the logged wheel
        angle is that of the controller's estimated curvature, ``atan(wheelbase x curvature)``, as the
        vehicle loop reads it, so the models include the controller's filter, rate limit, valve loop and
        report period.
    module_driver
        The host driver's settings for ``bridge="agopengps"`` (an :class:`AgioDriverConfig`, default
        :data:`SYSID_MODULE_DRIVER`) or ``bridge="isobus"`` (an :class:`IsobusDriverConfig`, default the
        vehicle's, :func:`hil.vehicle.isobus.link.isobus_driver_config` of the tractor's wheelbase: its
        anti-windup bound lets a wheel that follows at full rate through); the rate commanded is
        ``min(steering.max_rate, module_driver.max_rate)``.
    """
    params = params or SimParams()
    driver = driver or DriverExcitation()
    if bridge not in BRIDGES:
        raise SimulatorConfigError(f"bridge must be one of {list(BRIDGES)}, got {bridge!r}")
    if bridge != "hc11" and valve is not None:
        raise SimulatorConfigError(f"a valve map applies to the direct valve drive; a steer module or a steering "
                                   f"controller closes its own angle loop (pass valve=None with bridge={bridge!r})")
    if module_driver is not None:
        wanted = {"agopengps": AgioDriverConfig, "isobus": IsobusDriverConfig}.get(bridge)
        if wanted is None or not isinstance(module_driver, wanted):
            raise SimulatorConfigError(f"module_driver applies only to bridge='agopengps' (an AgioDriverConfig) or "
                                       f"'isobus' (an IsobusDriverConfig), got a {type(module_driver).__name__} "
                                       f"with bridge={bridge!r}")
    jobs = [(c, i) for c in plan.conditions() for i in range(plan.first_index, plan.first_index + plan.passes)]
    conds = [c for c, _ in jobs]
    seeds = [pass_seed(plan.seed, c, i) for c, i in jobs]
    # the driver's own random draws come from a stream separate from the simulator's
    sim_seeds, drv_seeds = zip(*(s.spawn(2) for s in seeds))
    if bridge != "hc11":
        cfg = module_driver if module_driver is not None else (
            SYSID_MODULE_DRIVER if bridge == "agopengps" else isobus_driver_config(params.vehicle.wheelbase))
        logs, module_meta = [], []
        total = len(jobs) * plan.duration
        for n, (cond, sim_seed, drv_seed) in enumerate(zip(conds, sim_seeds, drv_seeds)):
            tick = None if progress is None else (
                lambda done, _all, n=n: progress(int(n * plan.duration + done), int(total)))
            channels, info = _run_bridge_pass(bridge, cond, plan.duration, sim_seed,
                                              np.random.default_rng(drv_seed), params, driver, cfg, tick)
            logs.append(channels)
            module_meta.append(info)
    else:
        sim = TractorSimulator(conds, plan.duration, list(sim_seeds), params)
        logs = _run_driver(sim, driver, [np.random.default_rng(s) for s in drv_seeds], progress, valve)
    out = []
    for n, ((cond, i), seed_seq, channels) in enumerate(zip(jobs, seeds, logs)):
        meta = _meta(cond, i, plan, params, driver)
        if valve is not None:
            meta["valve_map"] = valve.to_dict()
        if bridge != "hc11":
            meta.update(module_meta[n])
            meta["extra_channels"] = {**_EXTRA, **_ENGAGED}
        out.append((pass_name(cond, i), PassLog(times=channels[0], channels=channels[1], meta=meta)))
    return out


def _measured_gps(sim: TractorSimulator, now: float) -> tuple[np.ndarray, np.ndarray]:
    """The control point's measured cross-track [m] and heading [rad] from the newest epochs that
    arrived by ``now`` (0 where none did)."""
    rows = np.arange(sim.B)
    ip, ia = sim.latest_position(now), sim.latest_attitude(now)
    yaw = np.where(ia >= 0, sim.att["yaw"][rows, ia], 0.0)
    roll = np.where(ia >= 0, sim.att["roll"][rows, ia], 0.0)
    y_ant = np.where(ip >= 0, sim.pos["y"][rows, ip], 0.0)
    return control_point_from_antenna(y_ant, yaw, roll, sim.params.vehicle), yaw


_REC = ("t", "wheel_angle", "steer_rate_cmd", "truth_cross_track", "truth_heading_error", "truth_wheel_angle",
        "truth_speed")


def _run_driver(sim: TractorSimulator, drv: DriverExcitation, rngs: Sequence[np.random.Generator],
                progress: Callable[[int, int], None] | None, valve: ValveCurve | None = None):
    p = sim.params
    B = sim.B
    sub = int(round(1.0 / (p.sensor.rate * p.dt)))           # integration steps per report
    lag = int(round(p.sensor.latency / p.dt))                 # report latency in steps
    n_ticks = (sim.n_steps - lag) // sub
    cal = two_point_calibration(p.sensor, p.steering)
    max_rate = p.steering.max_rate if valve is None else valve.max_rate
    nominal = np.array([c.speed for c in sim.conditions])
    rule = SlewRule(drv, rngs, nominal, sim.duration, p.vehicle.wheelbase, max_rate)
    rec = {k: np.zeros((B, n_ticks)) for k in _REC}
    for j in range(n_ticks):
        while sim.k < j * sub:
            sim.step()
        counts = sim.wheel_angle_counts()                   # sampled now, arrives `lag` steps later
        for _ in range(lag):
            sim.step()
        now = sim.time
        delta_m = cal.to_angle(counts)
        y_m, yaw = _measured_gps(sim, now)
        rate_cmd = rule.rate(now, delta_m, y_m, yaw)
        if valve is None:
            sim.set_duty(nominal_duty(rate_cmd, p.steering))
        else:
            sim.set_duty(np.array([valve.command_for(float(r)) for r in rate_cmd]) / valve.full_scale)
        tr = sim.truth()
        for key, val in zip(_REC, (now, delta_m, rate_cmd, tr["cross_track"], tr["heading_error"],
                                   tr["wheel_angle"], tr["speed"])):
            rec[key][:, j] = val
        if progress is not None and j % 100 == 0:
            progress(sim.k, sim.n_steps)
    if progress is not None:
        progress(sim.n_steps, sim.n_steps)
    return [_channels(sim, b, rec) for b in range(B)]


def _can_follow(report: IsobusReport) -> bool:
    """The steering controller would follow "intended to steer" now: its handshake done (no reset pending),
    ready and not locked out."""
    m = report.message
    return m.reset is ResetStatus.NOT_REQUIRED and m.readiness is Readiness.READY and m.lockout is not Lockout.ACTIVE


def _run_bridge_pass(bridge: str, cond: Condition, duration: float, sim_seed: np.random.SeedSequence,
                     rng: np.random.Generator, params: SimParams, drv: DriverExcitation,
                     config: AgioDriverConfig | IsobusDriverConfig, progress: Callable[[float, float], None] | None):
    """One identification pass through an emulated steer module (``bridge="agopengps"``) or steering
    controller (``"isobus"``), in lockstep: the loop's timing (every cycle: read the device's reports, then
    command), the excitation rule of :class:`~hil.vehicle.excitation.SlewRule`.

    The driver engages when the device answers, the operator is not steering and (a steering controller) its
    handshake is done; it disengages when that stops, and engages again after the handshake is redone.
    Returns the pass's channels (as :func:`_channels`) and what its metadata adds about the device.
    """
    plant = SimulatedTractor(cond, duration + 1.0, sim_seed, params)
    sim, p = plant.sim, plant.params
    cal = two_point_calibration(p.sensor, p.steering)
    period = 1.0 / p.sensor.rate
    n_ticks = int(math.floor(duration * p.sensor.rate + 1e-9))
    max_rate = min(p.steering.max_rate, config.max_rate)
    rule = SlewRule(drv, [rng], np.array([cond.speed]), duration, p.vehicle.wheelbase, max_rate)
    rec = {k: np.zeros((1, n_ticks)) for k in _REC}
    engaged = np.zeros(n_ticks)
    engages = 0
    speed = [0.0]
    isobus = bridge == "isobus"
    if isobus:
        bench = IsobusLockstepBench(plant, cal, p.vehicle.wheelbase, speed=lambda: plant.truth()["speed"],
                                    driver_config=config, max_step=0.05)
    else:
        bench = AgioLockstepBench(plant, cal, p.steering, driver_config=config, max_step=0.05)
    with bench:
        bench.scheduler.independent = True
        driver = bench.driver
        if not isobus:
            driver.set_speed_source(lambda: speed[0])      # the measured ground speed goes into PGN 254
        for j in range(n_ticks):
            now = (j + 1) * period
            bench.clock.sleep_until(now)
            driver.poll()
            rep = driver.latest
            ready = (rep is not None and driver.is_alive() and not rep.manual_override
                     and (not isobus or _can_follow(rep)))
            ip = int(sim.latest_position(now)[0])
            speed[0] = float(sim.pos["speed"][0, ip]) if ip >= 0 else 0.0
            if driver.engaged and not ready:
                driver.disengage()
            elif not driver.engaged and ready:
                driver.engage()
                engages += 1
            if rep is None:
                delta = 0.0
            elif isobus:     # as the loop reads it: the estimated curvature's angle in 0.1 mrad counts
                delta = float(ISOBUS_CALIBRATION.to_angle(rep.adc_counts))
            else:
                delta = rep.angle
            rate = 0.0
            if driver.engaged:
                y_m, yaw = _measured_gps(sim, now)
                rate = float(rule.rate(now, np.array([delta]), y_m, yaw)[0])
                driver.send_rate(rate)
                engaged[j] = 1.0
            tr = plant.truth()
            for key, val in zip(_REC, (now, delta, rate, tr["cross_track"], tr["heading_error"],
                                       tr["wheel_angle"], tr["speed"])):
                rec[key][0, j] = val
            if progress is not None and j % 100 == 0:
                progress(now, duration)
        if driver.engaged:
            driver.disengage()
        stats, device = driver.stats(), bench.firmware.state
    times, chans = _channels(sim, 0, rec)
    chans["engaged"] = engaged
    gps_latency = {"cross_track": p.gps.position_latency, "speed": p.gps.position_latency,
                   "heading_error": p.gps.attitude_latency}
    if isobus:
        ctrl = bench.firmware.config
        info = {"bridge": "isobus",
                "isobus": {"driver": dict(config.__dict__),
                           "controller": {k: v for k, v in ctrl.__dict__.items() if isinstance(v, (int, float))}
                           | {"speed_window": list(ctrl.speed_window)},
                           "engages": engages, "engaged_fraction": float(engaged.mean()),
                           "setpoints_limited": stats.limited, "bad_frames": stats.bad_frames,
                           "intended_sent": stats.intended_sent, "controller_reports": device.reports,
                           "last_exit_code": device.exit_code},
                # the controller samples its angle when it reports (every report_period, on the loop's grid):
                # at the loop's polls the newest report is 0 or one loop period old
                "latency_s": {"wheel_angle": 0.5 * (ctrl.report_period - period), "steer_rate_cmd": 0.0,
                              **gps_latency},
                "source": "hil.bench.runs.sysid (simulated open-loop identification pass through an emulated "
                          "ISO 11783 steering controller)"}
    else:
        info = {"bridge": "agopengps",
                "agopengps": {"driver": dict(config.__dict__), "module_settings": dict(device.settings.__dict__),
                              "engages": engages, "engaged_fraction": float(engaged.mean()),
                              "setpoints_limited": stats.setpoints_limited, "bad_frames": stats.bad_frames,
                              "module_loops": device.loops},
                # the PGN 253 angle is the module's last 40 Hz loop before it answered the previous cycle's PGN 254
                "latency_s": {"wheel_angle": period + 0.5 * SteerModuleConfig().loop_period, "steer_rate_cmd": 0.0,
                              **gps_latency},
                "source": "hil.bench.runs.sysid (simulated open-loop identification pass through an emulated "
                          "AgOpenGPS steer module)"}
    return (times, chans), info


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
_ENGAGED = {"engaged": {"time": "t", "unit": "1", "doc": "the steer module was commanded with autosteer on"}}


def _meta(cond: Condition, index: int, plan: SysidPlan, params: SimParams, drv: DriverExcitation) -> dict:
    g = params.gps
    return {
        "implement": cond.implement, "nominal_speed": cond.speed, "gear": cond.gear,
        "condition": cond.name, "pass_index": index, "seed": plan.seed,
        "source": "hil.bench.runs.sysid (simulated open-loop identification pass)",
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
