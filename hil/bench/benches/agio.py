"""Ready-made AgOpenGPS benches: emulated steer module + plant + host driver, in lockstep on an
in-memory link or in real time over a UDP loopback link (127.0.0.1).

They offer the host side what :class:`~hil.bench.benches.bridge.LockstepBridge` and
:class:`~hil.bench.benches.bridge.PtyBridge` offer (``clock``, ``driver``, ``firmware``, ``scheduler``
or ``runner``, ``host_link`` or ``port``), so :func:`hil.bench.runs.run.simulated_run` chooses a bridge
and runs the same loop. The module is loaded with the settings a technician would load on the
simulated tractor (:func:`module_settings`), over the wire (PGN 251 and 252) as AgIO does.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import TracebackType

from hil.devices.firmware import SteeringPlant
from hil.devices.steer_module import INNER_KP, SteerModule, SteerModuleConfig, module_settings
from hil.links.clock import RealClock, VirtualClock
from hil.links.link import ByteLink
from hil.links.memory import MemoryEndpoint, memory_link_pair
from hil.links.realtime import RealTimeRunner
from hil.links.scheduler import Device, LockstepScheduler
from hil.links.udp import UdpLink, udp_loopback_pair
from hil.truth.params import SteeringParams
from hil.vehicle.agio.driver import AgioDriver, AgioDriverConfig
from hil.vehicle.calibration import WheelAngleCalibration

__all__ = ["module_settings", "AgioLockstepBench", "AgioUdpBench", "INNER_KP"]

class _Common:
    driver: AgioDriver
    driver_config: AgioDriverConfig | None

    def driver_for(self, link: ByteLink) -> AgioDriver:
        """Another driver on ``link`` (a fault layer over the host's end), same clock and settings."""
        return AgioDriver(link, self.clock, self.driver_config)   # type: ignore[attr-defined]


class AgioLockstepBench(_Common):
    """Emulated module and plant on an in-memory link, in lockstep on a virtual clock.

    Parameters
    ----------
    plant : SteeringPlant
        Advanced by the scheduler.
    calibration, steering
        For the settings loaded into the module (:func:`module_settings`).
    module_config, driver_config : optional
        Of the module (its EEPROM at power-up) and the driver.
    extra_devices : sequence of Device, optional
        Further devices on the clock (receivers), stepped after the module.
    max_step : float, optional
        Longest plant integration step, s.
    """

    def __init__(self, plant: SteeringPlant, calibration: WheelAngleCalibration, steering: SteeringParams,
                 module_config: SteerModuleConfig | None = None, driver_config: AgioDriverConfig | None = None,
                 extra_devices: Sequence[Device] = (), max_step: float = 0.01) -> None:
        self.plant = plant
        self.clock = VirtualClock()
        self.host_link: MemoryEndpoint
        self.device_link: MemoryEndpoint
        self.host_link, self.device_link = memory_link_pair(self.clock, names=("agio", "steer module"))
        self.firmware = SteerModule(self.device_link, plant, module_config)
        self.scheduler = LockstepScheduler(self.clock, [self.firmware, *extra_devices], plant, max_step=max_step)
        self.driver_config = driver_config
        self.driver = AgioDriver(self.host_link, self.clock, driver_config)
        self.driver.configure(*module_settings(calibration, steering))

    def close(self) -> None:
        """Close the link."""
        self.host_link.close()

    def __enter__(self) -> AgioLockstepBench:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class AgioUdpBench(_Common):
    """Emulated module and plant behind a UDP loopback link (127.0.0.1), in real time.

    The module and the plant run in a :class:`RealTimeRunner` thread; the host side is a
    :class:`~hil.links.udp.UdpLink` (``port``). Use as a context manager.

    Parameters
    ----------
    plant, calibration, steering, module_config, driver_config, extra_devices
        As :class:`AgioLockstepBench`.
    poll : float, optional
        Longest sleep of the runner thread, s.
    """

    def __init__(self, plant: SteeringPlant, calibration: WheelAngleCalibration, steering: SteeringParams,
                 module_config: SteerModuleConfig | None = None, driver_config: AgioDriverConfig | None = None,
                 extra_devices: Sequence[Device] = (), poll: float = 0.001) -> None:
        self.plant = plant
        self.clock = RealClock()
        self.port: UdpLink
        self.module_link: UdpLink
        self.port, self.module_link = udp_loopback_pair()
        try:
            self.firmware = SteerModule(self.module_link, plant, module_config)
            self.runner = RealTimeRunner(self.clock, [self.firmware, *extra_devices], plant, poll=poll,
                                         wake_fds=[self.module_link.fileno()])
            self.driver_config = driver_config
            self.driver = AgioDriver(self.port, self.clock, driver_config)
            self.driver.configure(*module_settings(calibration, steering))
        except BaseException:
            self._close_links()
            raise

    def _close_links(self) -> None:
        self.port.close()
        self.module_link.close()

    def start(self) -> None:
        """Start the module's thread."""
        self.runner.start()

    def close(self) -> None:
        """Stop the thread (re-raising an error it died of) and close the sockets."""
        try:
            self.runner.stop()
        finally:
            self._close_links()

    def __enter__(self) -> AgioUdpBench:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
