"""A lockstep vehicle loop whose inputs an attacker can edit: the bridge's byte stream and the GNSS solution.

The bench's parts as :func:`hil.bench.runs.run.simulated_run` assembles them in lockstep (virtual clock,
in-memory links, the emulated HC11 board or AgOpenGPS steer module, the emulated receivers), with two
layers in front of the loop:

- :class:`InjectingLink` on the host's end of the bridge link adds bytes after what the device sent
  (well-formed reports of impossible angles, floods of garbage) or swallows the device's bytes (silence);
- :class:`EditedFrontEnd` hands the loop an edited :class:`~gnss.frontend.NavSolution` (non-finite
  values, a jump, a fix that stops arriving).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from design.laws.controller import Controller
from gnss.frontend import FrontEndConfig, GnssFrontEnd, NavSolution
from gnss.field import FieldGeometry
from hil.bench.benches.agio import AgioLockstepBench
from hil.bench.benches.bridge import LockstepBridge
from hil.devices.firmware import config_for_tractor
from hil.devices.plant import SimulatedTractor
from hil.devices.receivers import AttitudeReceiver, PositionReceiver
from hil.devices.wheel_calibration import two_point_calibration
from hil.links.memory import memory_link_pair
from hil.truth.conditions import condition_for
from hil.vehicle.agio import protocol as agio_protocol
from hil.vehicle.agio.driver import ANGLE_CALIBRATION, module_loop_config
from hil.vehicle.bridge import protocol as hc11_protocol
from hil.vehicle.bridge.driver import BridgeDriver
from hil.vehicle.loop import LoopConfig, VehicleLoop

#: What an injector returns for a cycle: bytes to add after the device's, and whether to swallow the device's.
Injection = tuple[bytes, bool]


class InjectingLink:
    """The host's end of a bridge link with an attacker in the middle (called once per clock time)."""

    def __init__(self, inner, clock, inject: Callable[[float], Injection]) -> None:
        self.inner, self.clock, self.inject = inner, clock, inject
        self._extra = bytearray()
        self._asked = math.nan
        self.injected = 0

    def _fill(self) -> None:
        now = self.clock.now()
        if now != self._asked:
            self._asked = now
            data, silence = self.inject(now)
            if silence:
                self.inner.read(self.inner.in_waiting)
            self._extra += data
            self.injected += len(data)

    @property
    def in_waiting(self) -> int:
        self._fill()
        return self.inner.in_waiting + len(self._extra)

    def read(self, size: int = 1) -> bytes:
        self._fill()
        data = self.inner.read(min(size, self.inner.in_waiting))
        rest = size - len(data)
        if rest > 0 and self._extra:
            data += bytes(self._extra[:rest])
            del self._extra[:rest]
        return data

    def write(self, data: bytes) -> int:
        return self.inner.write(data)


class EditedFrontEnd:
    """A GNSS front-end whose published solution passes through ``edit(t, nav)`` first."""

    def __init__(self, inner: GnssFrontEnd, edit: Callable[[float, NavSolution], NavSolution]) -> None:
        self.inner, self.edit = inner, edit

    def step(self, t: float | None = None) -> NavSolution:
        nav = self.inner.step(t)
        return self.edit(nav.t, nav)

    def solution(self, t: float) -> NavSolution:
        return self.inner.solution(t)


def hc11_report(counts: int, seq: int = 0) -> bytes:
    """A well-formed HC11 wheel-angle report frame (engaged flag set) with ``counts``."""
    msg = hc11_protocol.WheelAngleReport(adc_counts=counts, flags=hc11_protocol.StatusFlags.ENGAGED, command_seq=0,
                                         duty=0.0, bad_frames=0, dropped_frames=0, bridge_time_ms=0)
    return hc11_protocol.encode_frame(msg, seq & 0xFF)


def agio_report(angle: float) -> bytes:
    """A well-formed PGN 253 with the steer switch on and ``angle`` (rad)."""
    msg = agio_protocol.FromAutosteer(steer_angle=angle, heading=None, roll=None,
                                      switches=agio_protocol.Switches.NONE, pwm_display=0)
    return agio_protocol.encode_frame(msg)


def garbage(rng: np.random.Generator, n: int) -> bytes:
    """``n`` random bytes below 0x80: never a sync byte of either protocol (0xA5, 0x80), so never a frame."""
    return rng.integers(0, 0x80, n, dtype=np.uint8).tobytes()


@dataclass
class HostileRun:
    """A finished run: its log, its loop (config, events) and the injector's link."""

    log: object
    loop: VehicleLoop
    link: InjectingLink
    driver: object


def nothing(now: float) -> Injection:
    return b"", False


def same(t: float, nav: NavSolution) -> NavSolution:
    return nav


def hostile_run(bridge: str, controller: Controller, duration: float = 6.0, seed: int = 0,
                inject: Callable[[float], Injection] = nothing,
                edit: Callable[[float, NavSolution], NavSolution] = same,
                loop_config: LoopConfig | None = None) -> HostileRun:
    """Run the loop in lockstep on the simulated tractor (no implement, 1.79 m/s, 0.3 m off the line).

    ``controller`` is reset by the loop; build it once per test module (its construction costs more
    than a short run)."""
    cond = condition_for("none", 1.79)
    plant = SimulatedTractor(cond, duration + 1.0, seed, None, initial={"Y": 0.3, "PSI": 0.0})
    p = plant.params
    config = loop_config or LoopConfig(wheel_stop=p.steering.max_wheel_angle)
    cal = two_point_calibration(p.sensor, p.steering)
    geo = FieldGeometry()
    vp = p.vehicle
    fe_config = FrontEndConfig(origin=geo.origin, lever_arm=(vp.antenna_ahead_of_cg, vp.antenna_left_of_cg,
                                                             vp.antenna_height))
    agio = bridge == "agopengps"
    bench = (AgioLockstepBench(plant, cal, p.steering, max_step=0.05) if agio
             else LockstepBridge(plant, config_for_tractor(p.steering), max_step=0.05))
    with bench:
        bench.scheduler.independent = True
        sources = []
        for cls, name in ((PositionReceiver, "position"), (AttitudeReceiver, "attitude")):
            host, dev = memory_link_pair(bench.clock, names=("host", name))
            bench.scheduler.add(cls(plant, dev, geo))
            sources.append(host)
        clock = bench.clock
        link = InjectingLink(bench.host_link, clock, inject)
        driver = bench.driver_for(link) if agio else BridgeDriver(link, clock, bench.driver.config)
        frontend = GnssFrontEnd(fe_config, sources=sources, clock=clock.now)
        if agio:
            driver.set_speed_source(lambda: frontend.solution(clock.now()).speed)
            cal = ANGLE_CALIBRATION
            config = module_loop_config(config)
        loop = VehicleLoop(clock, driver, EditedFrontEnd(frontend, edit), geo.ab_line(), controller,
                           cal, config, truth=plant.truth)
        loop.run(duration, start=clock.now())
        log = loop.run_log({"implement": "none", "nominal_speed": 1.79, "bridge": bridge,
                            "bridge_stats": {k: v for k, v in driver.stats().__dict__.items() if k != "ping_rtts"}})
    return HostileRun(log, loop, link, driver)


def edited(nav: NavSolution, **changes: float) -> NavSolution:
    """``nav`` with some fields replaced."""
    return dataclasses.replace(nav, **changes)
