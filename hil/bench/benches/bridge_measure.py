"""Measurements of the bridge path: lockstep speed, and real-time latencies over a pseudo-terminal.

Library functions behind a benchmark or a CLI command; each returns a frozen
dataclass of plain numbers (seconds, ratios) and takes the plant to drive, so
the truth simulator or a test double can be used.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import asdict, dataclass

from autosteer.checks import finite, positive

from hil.bench.benches.bridge import LockstepBridge, PtyBridge
from hil.vehicle.bridge.config import DriverConfig, FirmwareConfig
from hil.vehicle.bridge.errors import ConfigError
from hil.devices.firmware import SteeringPlant
from hil.links.clock import Clock

__all__ = ["LockstepSpeed", "PtyLatency", "measure_lockstep_speed", "measure_pty_latency"]


def _percentile(values: list[float], q: float) -> float:
    if not values:
        return math.nan
    s = sorted(values)
    return s[min(len(s) - 1, max(0, math.ceil(q / 100 * len(s)) - 1))]


class _ValveClock:
    """Wraps a plant; stamps every valve command with the bench clock (runs in the device thread)."""

    def __init__(self, plant: SteeringPlant) -> None:
        self.plant = plant
        self.clock: Clock | None = None
        self.valve_times: list[tuple[float, float]] = []

    def set_valve_duty(self, duty: float) -> None:
        self.plant.set_valve_duty(duty)
        if self.clock is not None:
            self.valve_times.append((self.clock.now(), duty))

    def wheel_angle_counts(self) -> int:
        return self.plant.wheel_angle_counts()

    def manual_override(self) -> bool:
        return self.plant.manual_override()

    def advance(self, dt: float) -> None:
        self.plant.advance(dt)


@dataclass(frozen=True)
class LockstepSpeed:
    """Result of :func:`measure_lockstep_speed`.

    Parameters
    ----------
    virtual_s, wall_s : float
        Simulated and elapsed wall-clock time, s.
    speedup : float
        ``virtual_s / wall_s``.
    cycles, reports : int
        Host cycles run, reports received.
    device_steps, plant_steps : int
        Scheduler work.
    """

    virtual_s: float
    wall_s: float
    speedup: float
    cycles: int
    reports: int
    device_steps: int
    plant_steps: int

    def as_dict(self) -> dict[str, float]:
        """Plain dict (for JSON)."""
        return asdict(self)


def measure_lockstep_speed(plant: SteeringPlant, duration: float = 60.0, period: float = 0.05,
                           firmware_config: FirmwareConfig | None = None) -> LockstepSpeed:
    """Run a host that polls and commands every ``period`` s for ``duration`` s of virtual time.

    Every byte is encoded, line-timed and decoded, as in a HIL run.

    Parameters
    ----------
    plant : SteeringPlant
        Driven by the emulated bridge; advanced by the scheduler.
    duration, period : float
        Virtual time to run and host cycle period, s.
    firmware_config : FirmwareConfig, optional
        Bridge settings (default 9600 baud, 20 Hz, 250 ms watchdog).
    """
    positive(duration, "duration", unit="s", error=ConfigError)
    positive(period, "period", unit="s", error=ConfigError)
    bench = LockstepBridge(plant, firmware_config)
    drv, clock = bench.driver, bench.clock
    n = int(round(duration / period))
    reports = 0
    drv.engage()
    wall0 = time.perf_counter()
    for k in range(1, n + 1):
        clock.sleep_until(k * period)
        reports += len(drv.poll())
        drv.send_rate(0.1 if (k // 20) % 2 else -0.1)
    wall = time.perf_counter() - wall0
    return LockstepSpeed(virtual_s=n * period, wall_s=wall, speedup=n * period / wall, cycles=n, reports=reports,
                         device_steps=bench.scheduler.device_steps, plant_steps=bench.scheduler.plant_steps)


@dataclass(frozen=True)
class PtyLatency:
    """Result of :func:`measure_pty_latency` (all times in s).

    Parameters
    ----------
    ping_rtt_min, ping_rtt_median, ping_rtt_p99, ping_rtt_max : float
        Ping-pong round trips through pyserial, the pty and the emulated firmware
        (the 9600-baud wire time of ping + pong is 18.75 ms).
    command_to_valve_median, command_to_valve_max : float
        From ``send_rate`` returning to the plant's ``set_valve_duty`` (wire time 9.375 ms).
    wire_command : float
        Modelled line time of one command frame.
    runner_late_max : float
        Largest lateness of a firmware step behind its requested time.
    samples : int
        Pings and commands measured (each).
    """

    ping_rtt_min: float
    ping_rtt_median: float
    ping_rtt_p99: float
    ping_rtt_max: float
    command_to_valve_median: float
    command_to_valve_max: float
    wire_command: float
    runner_late_max: float
    samples: int

    def as_dict(self) -> dict[str, float]:
        """Plain dict (for JSON)."""
        return asdict(self)


def measure_pty_latency(plant: SteeringPlant, samples: int = 50, timeout: float = 0.2,
                        firmware_config: FirmwareConfig | None = None,
                        driver_config: DriverConfig | None = None) -> PtyLatency:
    """Measure ping round trips and command-to-valve latency over a pseudo-terminal in real time.

    Takes about ``samples * 0.08`` s of wall-clock time.
    """
    finite(samples, "samples", lo=1, integer=True, error=ConfigError)
    positive(timeout, "timeout", unit="s", error=ConfigError)
    probe = _ValveClock(plant)
    with PtyBridge(probe, firmware_config, driver_config) as bench:
        probe.clock = bench.clock
        drv, clock = bench.driver, bench.clock
        clock.sleep_until(clock.now() + 0.06)
        rtts = [drv.ping(timeout) for _ in range(samples)]
        drv.engage()
        clock.sleep_until(clock.now() + 0.02)
        latencies = []
        for k in range(samples):
            before = len(probe.valve_times)
            t_send = clock.now()
            drv.send_rate(0.1 if k % 2 else -0.1)  # a new value every time: the valve is always told
            clock.sleep_until(t_send + 0.04)
            drv.poll()
            later = probe.valve_times[before:]
            if later:
                latencies.append(later[0][0] - t_send)
        drv.disengage()
        wire = 9 * bench.firmware.config.line.byte_time
        late = bench.runner.late_max
    if not latencies:
        latencies = [math.nan]
    return PtyLatency(ping_rtt_min=min(rtts), ping_rtt_median=statistics.median(rtts),
                      ping_rtt_p99=_percentile(rtts, 99), ping_rtt_max=max(rtts),
                      command_to_valve_median=statistics.median(latencies),
                      command_to_valve_max=max(latencies), wire_command=wire, runner_late_max=late,
                      samples=samples)
