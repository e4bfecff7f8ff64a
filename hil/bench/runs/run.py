"""A closed-loop pass on the bench: simulated tractor, emulated bridge and receivers, the vehicle loop.

:func:`simulated_run` assembles everything for one pass following an AB line or a field's route,
either in lockstep on a virtual clock (in-memory links, much faster than real
time) or in real time over pseudo-terminals, runs the loop and returns the run
log; :func:`summarize` gives the paper's Table 2 numbers for it.
"""

from __future__ import annotations

from contextlib import ExitStack
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from autosteer.checks import finite
from design.laws.controller import Controller
from gnss.frontend import FrontEndConfig, GnssFrontEnd
from gnss.track import PathTracker
from gnss.field import FieldGeometry
from identification.passlog import PassLog

from hil.bench.benches.agio import AgioLockstepBench, AgioUdpBench
from hil.bench.benches.bridge import LockstepBridge, PtyBridge
from hil.bench.benches.isobus import IsobusLockstepBench
from hil.devices.field_driver import FieldDriver, autosteer_on
from hil.bench.runs.field_route import RouteTruth, field_run
from hil.truth.conditions import condition_for
from hil.vehicle.bridge.driver import BridgeDriver
from hil.errors import SimulatorConfigError
from hil.devices.faults import FaultyLink, LinkFault
from hil.devices.firmware import config_for_tractor
from hil.links.memory import memory_link_pair
from hil.links.pty import PtyPair
from hil.vehicle.commissioning import Commissioning, MappedBridge
from hil.vehicle.agio.driver import ANGLE_CALIBRATION, module_loop_config
from hil.vehicle.isobus.driver import ANGLE_CALIBRATION as ISOBUS_CALIBRATION
from hil.vehicle.isobus.link import isobus_loop_config
from hil.vehicle.loop import LoopConfig, VehicleLoop
from hil.truth.params import SimParams
from hil.devices.plant import SimulatedTractor
from hil.devices.receivers import AttitudeReceiver, PositionReceiver
from hil.devices.wheel_calibration import two_point_calibration
from hil.devices.valve_faults import ValveFaults


#: Speeds a bench pass may run at, m/s: field work; below 0.5 m/s the loop does not engage.
SPEED_RANGE = (0.5, 6.0)
#: Steering bridges a bench pass may steer through.
BRIDGES = ("hc11", "agopengps", "isobus")
#: Largest start offset from the line, m, and heading error, rad, of a pass.
MAX_INITIAL_CROSS_TRACK = 5.0
MAX_INITIAL_HEADING = 0.5


@dataclass(frozen=True)
class RunSpec:
    """One closed-loop pass.

    Attributes
    ----------
    implement, speed
        Condition (implement name, nominal speed in m/s).
    duration
        Length of the pass, s.
    seed
        Seed of the simulated tractor and its sensors.
    realtime
        Real time over pseudo-terminals instead of lockstep on in-memory links.
    initial_cross_track, initial_heading
        Where the tractor starts relative to the line (m, rad).
    override, stuck_valve
        Plant fault intervals ``(start, end)`` in s: the driver turns the wheel; the valve sticks.
    gps_outage, rtk_float
        Receiver fault intervals: no GPS output at all; position reported as RTK float.
    link_faults
        Faults on the bridge link, host side (see :mod:`hil.devices.faults`).
    bridge
        ``hc11`` (the emulated HC11 board), ``agopengps`` (an emulated AgOpenGPS steer module:
        in-memory link in lockstep, UDP on 127.0.0.1 in real time; :mod:`hil.bench.benches.agio`) or
        ``isobus`` (an emulated ISO 11783 steering controller on a python-can virtual bus, in lockstep
        only; :mod:`hil.bench.benches.isobus`).
    geometry
        Where the simulator's frame lies on the Earth.
    field, field_passes
        A named field or a field file (:func:`gnss.field_io.load_field`) instead of the AB line,
        and how many of its passes to drive (default all): the loop follows the route of the
        passes and the headland turns between them (:mod:`hil.bench.runs.field_route`); the initial
        offsets are then from the route at ``start_station`` m.
    field_driver
        On a field, a driver takes the wheel when the autosteer has let go and hands it back on
        the line (:mod:`hil.devices.field_driver`); without one a disengaged tractor keeps its wheel.
    """

    implement: str = "none"
    speed: float = 1.79
    duration: float = 60.0
    seed: int = 0
    realtime: bool = False
    initial_cross_track: float = 0.3
    initial_heading: float = 0.0
    override: tuple[tuple[float, float], ...] = ()
    stuck_valve: tuple[tuple[float, float], ...] = ()
    gps_outage: tuple[tuple[float, float], ...] = ()
    rtk_float: tuple[tuple[float, float], ...] = ()
    link_faults: tuple[LinkFault, ...] = ()
    bridge: str = "hc11"
    geometry: FieldGeometry = field(default_factory=FieldGeometry)
    field: str | None = None
    field_passes: int | None = None
    start_station: float = 0.0
    field_driver: bool = True

    def __post_init__(self) -> None:
        finite(self.duration, "duration", lo=1, hi=3600, unit="s", error=SimulatorConfigError)
        finite(self.seed, "seed", lo=0, integer=True, error=SimulatorConfigError)
        for name, bound, unit in (("initial_cross_track", MAX_INITIAL_CROSS_TRACK, "m"),
                                  ("initial_heading", MAX_INITIAL_HEADING, "rad")):
            finite(getattr(self, name), name, lo=-bound, hi=bound, unit=unit, error=SimulatorConfigError,
                   fix="a pass starts near its line")
        finite(self.speed, "speed", lo=SPEED_RANGE[0], hi=SPEED_RANGE[1], unit="m/s", error=SimulatorConfigError,
               fix="field work; the paper's gears are 1.00-2.91 m/s")
        if self.bridge not in BRIDGES:
            raise SimulatorConfigError(f"bridge must be 'isobus', 'hc11' or 'agopengps', got {self.bridge!r}")
        if self.bridge == "isobus" and (self.realtime or self.link_faults):
            raise SimulatorConfigError("the isobus bench runs in lockstep on a virtual CAN bus, without byte-link "
                                       "faults: drop realtime and the link faults (hil emulate --bridge isobus "
                                       "runs it in real time)")
        condition_for(self.implement, self.speed)   # validates implement
        if self.field is not None and (not isinstance(self.field, str) or not self.field):
            raise SimulatorConfigError(f"field must be a field name or file, got {self.field!r}")
        if self.field is None and (self.field_passes is not None or self.start_station != 0.0):
            raise SimulatorConfigError("field_passes and start_station need a field")
        if not isinstance(self.field_driver, bool):
            raise SimulatorConfigError(f"field_driver must be True or False, got {self.field_driver!r}")
        finite(self.start_station, "start_station", noun="a finite station in m", error=SimulatorConfigError)


def simulated_run(spec: RunSpec, controller: Controller, params: SimParams | None = None,
                  loop_config: LoopConfig | None = None,
                  progress: Callable[[float, float], None] | None = None,
                  commissioning: Commissioning | None = None, map_valve: bool = True,
                  epochs: bool = False, receiver_latency: float = 0.0) -> PassLog:
    """Run one closed-loop pass on the simulated tractor and return its run log.

    With ``commissioning`` (a tractor's commissioning file), the loop's rate limit and
    steering-response monitor come from the measured valve (:func:`hil.vehicle.commissioning.loop_settings`)
    and, unless ``map_valve`` is false, its rate commands go through the valve's inverse map
    (:class:`hil.vehicle.commissioning.MappedBridge`). With ``epochs`` the log's GPS channels are the
    receivers' epochs with their valid times (:meth:`hil.vehicle.loop.VehicleLoop.run_log`; an AB line only);
    ``receiver_latency`` is the receivers' minimum output latency declared to the front-end, s (what
    ``hil drive --receiver-latency`` declares on a tractor; 0: none).
    """
    cond = condition_for(spec.implement, spec.speed)
    if epochs and spec.field is not None:
        raise SimulatorConfigError("epochs: the receivers' epochs are recorded against the AB line, not a field")
    fld = None if spec.field is None else field_run(spec.field, params or SimParams(), spec.speed, spec.field_passes)
    initial = ({"Y": spec.initial_cross_track, "PSI": spec.initial_heading} if fld is None else
               fld.start_state(spec.start_station, spec.initial_cross_track, spec.initial_heading))
    plant = SimulatedTractor(cond, spec.duration + 1.0, spec.seed, params, initial=initial)
    valve = ValveFaults(plant, override=spec.override, stuck_valve=spec.stuck_valve)   # what the bridge drives
    driver_layer = None
    if fld is not None and spec.field_driver:   # a driver takes the wheel when the autosteer lets go
        valve = driver_layer = FieldDriver(valve, plant, fld.path, spec.start_station)
    p = plant.params
    if loop_config is None:   # the steering monitor knows this tractor's wheel stop
        loop_config = LoopConfig(wheel_stop=p.steering.max_wheel_angle)
    cal = two_point_calibration(p.sensor, p.steering)
    geo = spec.geometry
    vp = p.vehicle
    fe_config = FrontEndConfig(origin=geo.origin, lever_arm=(vp.antenna_ahead_of_cg, vp.antenna_left_of_cg,
                                                             vp.antenna_height), receiver_latency=receiver_latency)
    agio, isobus = spec.bridge == "agopengps", spec.bridge == "isobus"
    with ExitStack() as stack:
        if spec.realtime:
            pos_pty, att_pty = stack.enter_context(PtyPair()), stack.enter_context(PtyPair())
            receivers = [PositionReceiver(plant, pos_pty.device_link(), geo),
                         AttitudeReceiver(plant, att_pty.device_link(), geo)]
            bench = stack.enter_context(AgioUdpBench(valve, cal, p.steering, extra_devices=receivers) if agio
                                        else PtyBridge(valve, config_for_tractor(p.steering), extra_devices=receivers))
            sources = [pos_pty.open_serial(baudrate=38400, timeout=0),
                       att_pty.open_serial(baudrate=38400, timeout=0)]
            for s in sources:
                stack.callback(s.close)
        else:
            # The simulator integrates on its own dt grid whatever the advance; the scheduler need not
            # stop between device wake-ups for it (at most every loop period).
            bench = stack.enter_context(
                IsobusLockstepBench(valve, cal, vp.wheelbase, speed=lambda: plant.truth()["speed"], max_step=0.05)
                if isobus else AgioLockstepBench(valve, cal, p.steering, max_step=0.05) if agio
                else LockstepBridge(valve, config_for_tractor(p.steering), max_step=0.05))
            # the firmware and the receivers share only the plant; each has its own link to the host
            bench.scheduler.independent = True
            receivers, sources = [], []
            for cls, name in ((PositionReceiver, "position"), (AttitudeReceiver, "attitude")):
                host, dev = memory_link_pair(bench.clock, names=("host", name))
                rx = cls(plant, dev, geo)
                bench.scheduler.add(rx)
                receivers.append(rx)
                sources.append(host)
        for rx in receivers:
            rx.suppressed.extend(spec.gps_outage)
        receivers[0].downgraded.extend(spec.rtk_float)
        clock = bench.clock
        driver = bench.driver
        if driver_layer is not None:
            firmware = bench.firmware
            driver_layer.autosteer_engaged = lambda: autosteer_on(firmware.state)
        faulty = None
        if spec.link_faults:
            host = bench.port if spec.realtime else bench.host_link
            rng = np.random.default_rng(np.random.SeedSequence(spec.seed, spawn_key=(99,)))
            faulty = FaultyLink(host, clock, spec.link_faults, rng)
            driver = bench.driver_for(faulty) if agio else BridgeDriver(faulty, clock, bench.driver.config)
        frontend = GnssFrontEnd(fe_config, sources=sources, clock=clock.now)
        if agio:   # the module needs the ground speed (PGN 254); its angle comes in 0.01 degree
            driver.set_speed_source(lambda: frontend.solution(clock.now()).speed)
            cal = ANGLE_CALIBRATION
            if commissioning is None:
                loop_config = module_loop_config(loop_config)
        if isobus:   # the controller closes its own angle loop; the loop reads its estimated curvature's angle
            cal = ISOBUS_CALIBRATION
            if commissioning is None:
                loop_config = isobus_loop_config(loop_config)
        if commissioning is not None:
            loop_config = commissioning.loop_config(loop_config)
            if map_valve and spec.bridge == "hc11":   # a module or a steering controller closes its own angle loop
                driver = MappedBridge(driver, commissioning.valve)
        if fld is None:
            loop = VehicleLoop(clock, driver, frontend, geo.ab_line(), controller, cal, loop_config,
                               truth=plant.truth, epochs=epochs)
        else:   # the vehicle's own tracker on the route in ENU; the bench's on the simulator's frame
            tracker = PathTracker(geo.place(fld.path), station=spec.start_station, cycle=1.0 / loop_config.rate)
            loop = VehicleLoop(clock, driver, frontend, tracker, controller, cal, loop_config,
                               truth=RouteTruth(plant, fld.route, spec.start_station), parts=fld.route.parts)
        loop.run(spec.duration, start=clock.now(), progress=progress)
        stats = driver.stats()
        frontend_stats = _refused(frontend)
        firmware = bench.firmware.state
    meta = {"implement": cond.implement, "nominal_speed": cond.speed, "gear": cond.gear, "seed": spec.seed,
            "source": "hil.bench.runs.run (closed loop on the simulated tractor)",
            "mode": ("realtime-udp" if agio else "realtime-pty") if spec.realtime else "lockstep",
            "bridge": spec.bridge,
            "initial": {"cross_track": spec.initial_cross_track, "heading": spec.initial_heading},
            "faults": {"override": list(spec.override), "stuck_valve": list(spec.stuck_valve),
                       "gps_outage": list(spec.gps_outage), "rtk_float": list(spec.rtk_float),
                       "link": [asdict(f) for f in spec.link_faults],
                       "link_fault_counts": faulty.counts if faulty else {}},
            "firmware": {k: v for k, v in asdict(firmware).items() if isinstance(v, (int, float, bool))},
            "bridge_stats": {k: v for k, v in stats.__dict__.items() if k != "ping_rtts"},
            "receivers_sent": {"position": receivers[0].sent, "attitude": receivers[1].sent},
            "receivers_corrupted": {"position": receivers[0].corrupted, "attitude": receivers[1].corrupted},
            "gnss_refused": frontend_stats,
            "simulator": p.to_dict()}
    if fld is not None:
        meta["field"] = {**fld.describe(), "source": spec.field, "start_station_m": spec.start_station,
                         "driver_takeovers": None if driver_layer is None else driver_layer.takeovers}
    return loop.run_log(meta)


def _refused(frontend: GnssFrontEnd) -> dict:
    """Messages the front-end's readers decoded and refused (by reason), summed over the sources."""
    refused: dict[str, int] = {}
    decoded = garbage = 0
    for reader in frontend.readers:
        st = reader.stats
        decoded += sum(st.messages.values())
        garbage += st.garbage_bytes
        for k, v in st.errors.items():
            refused[k] = refused.get(k, 0) + v
    return {"decoded": decoded, "refused": refused, "garbage_bytes": garbage}

