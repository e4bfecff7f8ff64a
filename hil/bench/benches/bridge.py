"""Ready-made bridge benches: firmware + plant + driver on an in-memory link (lockstep) or a pty (real time).

Both give the host side the same two objects, a :class:`~hil.links.clock.Clock`
and a :class:`~hil.vehicle.bridge.driver.BridgeDriver`, so host code written as::

    bench.driver.engage()
    t = bench.clock.now()
    for k in range(n):
        t += 0.05
        bench.clock.sleep_until(t)
        reports = bench.driver.poll()
        bench.driver.send_rate(u)

runs unchanged in both. In lockstep, ``clock.sleep_until`` runs the plant and
every device up to ``t``; in real time, they run in a background thread.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import TracebackType

import serial

from hil.vehicle.bridge.config import DriverConfig, FirmwareConfig
from hil.vehicle.bridge.driver import BridgeDriver
from hil.devices.firmware import BridgeFirmware, SteeringPlant
from hil.links.clock import RealClock, VirtualClock
from hil.links.memory import MemoryEndpoint, memory_link_pair
from hil.links.pty import PtyPair
from hil.links.realtime import RealTimeRunner
from hil.links.scheduler import Device, LockstepScheduler

__all__ = ["LockstepBridge", "PtyBridge"]


class LockstepBridge:
    """Bridge firmware and plant on an in-memory link, in lockstep on a virtual clock.

    Parameters
    ----------
    plant : SteeringPlant
        Advanced by the scheduler (``plant.advance(dt)``, dt <= ``max_step``).
    firmware_config, driver_config : optional
        Defaults of :class:`FirmwareConfig` and :class:`DriverConfig`.
    extra_devices : sequence of Device, optional
        Further devices on the same clock (emulated receivers), stepped after the firmware.
    max_step : float, optional
        Longest plant integration step, s (default 0.01).
    start : float, optional
        Initial virtual time, s.

    Attributes
    ----------
    clock : VirtualClock
    scheduler : LockstepScheduler
    firmware : BridgeFirmware
    driver : BridgeDriver
    host_link, device_link : MemoryEndpoint
    """

    def __init__(self, plant: SteeringPlant, firmware_config: FirmwareConfig | None = None,
                 driver_config: DriverConfig | None = None, extra_devices: Sequence[Device] = (),
                 max_step: float = 0.01, start: float = 0.0) -> None:
        self.plant = plant
        self.clock = VirtualClock(start)
        self.host_link: MemoryEndpoint
        self.device_link: MemoryEndpoint
        self.host_link, self.device_link = memory_link_pair(self.clock, names=("host", "bridge"))
        self.firmware = BridgeFirmware(self.device_link, plant, firmware_config)
        self.scheduler = LockstepScheduler(self.clock, [self.firmware, *extra_devices], plant, max_step=max_step)
        self.driver = BridgeDriver(self.host_link, self.clock, driver_config)

    def close(self) -> None:
        """Close the link (nothing runs in the background)."""
        self.host_link.close()

    def __enter__(self) -> LockstepBridge:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class PtyBridge:
    """Bridge firmware and plant behind a pseudo-terminal, in real time.

    The host side is a pyserial ``Serial`` on the pty's slave device; the
    firmware and plant run in a :class:`RealTimeRunner` thread on the master side.
    Use as a context manager (starts the thread; stops it and closes everything on exit).

    Parameters
    ----------
    plant : SteeringPlant
        Advanced by the runner thread with the elapsed wall-clock time.
    firmware_config, driver_config : optional
        Defaults of :class:`FirmwareConfig` and :class:`DriverConfig`.
    extra_devices : sequence of Device, optional
        Further devices run by the same thread.
    poll : float, optional
        Longest sleep of the runner thread, s (default 0.001).

    Attributes
    ----------
    clock : RealClock
    pty : PtyPair
    port : serial.Serial
        Host end, opened at the firmware's baud rate (ignored by the pty).
    firmware : BridgeFirmware
    runner : RealTimeRunner
    driver : BridgeDriver
    """

    def __init__(self, plant: SteeringPlant, firmware_config: FirmwareConfig | None = None,
                 driver_config: DriverConfig | None = None, extra_devices: Sequence[Device] = (),
                 poll: float = 0.001) -> None:
        self.plant = plant
        self.clock = RealClock()
        self.pty = PtyPair()
        try:
            self.firmware = BridgeFirmware(self.pty.device_link(), plant, firmware_config)
            self.port: serial.Serial = self.pty.open_serial(baudrate=self.firmware.config.line.baud)
            self.runner = RealTimeRunner(self.clock, [self.firmware, *extra_devices], plant, poll=poll,
                                         wake_fds=[self.pty.device_link().fileno()])
            self.driver = BridgeDriver(self.port, self.clock, driver_config)
        except BaseException:
            self.pty.close()
            raise

    def start(self) -> None:
        """Start the firmware thread."""
        self.runner.start()

    def close(self) -> None:
        """Stop the thread (re-raising an error it died of) and close the pty."""
        try:
            self.runner.stop()
        finally:
            self.pty.close()

    def __enter__(self) -> PtyBridge:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

