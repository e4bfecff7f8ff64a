"""A ready-made ISO 11783 bench: the emulated steering controller on the simulated tractor's valve and the
host driver, two nodes of one python-can virtual bus, in lockstep on a virtual clock.

It offers the host side what :class:`~hil.bench.benches.bridge.LockstepBridge` offers (``clock``,
``driver``, ``firmware``, ``scheduler``), so :func:`hil.bench.runs.run.simulated_run` chooses the bridge
and runs the same loop. The controller (:class:`~hil.devices.isobus_controller.IsobusController`) turns
the commanded curvature into the valve's duty with its own angle loop; the host's node and driver are
those ``hil drive --bridge isobus...`` builds (:class:`hil.vehicle.isobus.link.IsobusLink`).
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Sequence
from types import TracebackType

import can

from hil.devices.firmware import SteeringPlant
from hil.devices.isobus_controller import IsobusController, IsobusControllerConfig
from hil.links.clock import VirtualClock
from hil.links.scheduler import Device, LockstepScheduler
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.isobus.driver import IsobusDriver, IsobusDriverConfig
from hil.vehicle.isobus.link import IsobusLink, isobus_driver_config

__all__ = ["IsobusLockstepBench"]

_benches = itertools.count()


class IsobusLockstepBench:
    """Emulated steering controller and plant on a python-can virtual bus, in lockstep on a virtual clock.

    Parameters
    ----------
    plant : SteeringPlant
        Advanced by the scheduler; the controller drives its valve.
    calibration : WheelAngleCalibration
        The controller's wheel-angle sensor (counts to rad).
    wheelbase : float
        The tractor's, m: the controller and the driver turn curvature into wheel angle with it.
    speed : callable, optional
        The tractor's ground speed, m/s (the controller's speed window); None: always inside it.
    controller_config, driver_config : optional
        Of the controller (default: ``calibration``, ``wheelbase`` and the defaults) and of the driver
        (default: the vehicle's, :func:`hil.vehicle.isobus.link.isobus_driver_config`).
    extra_devices : sequence of Device, optional
        Further devices on the clock (receivers), stepped after the controller.
    max_step : float, optional
        Longest plant integration step, s.

    Attributes
    ----------
    clock : VirtualClock
    scheduler : LockstepScheduler
    firmware : IsobusController
        The emulated controller (named as the other benches' firmware).
    driver : IsobusDriver
    link : IsobusLink
        The host's end of the bus.
    """

    def __init__(self, plant: SteeringPlant, calibration: WheelAngleCalibration, wheelbase: float,
                 speed: Callable[[], float] | None = None, controller_config: IsobusControllerConfig | None = None,
                 driver_config: IsobusDriverConfig | None = None, extra_devices: Sequence[Device] = (),
                 max_step: float = 0.01) -> None:
        self.plant = plant
        self.clock = VirtualClock()
        channel = f"isobus-bench-{os.getpid()}-{next(_benches)}"    # a bus of its own in this process
        self._device_bus = can.Bus(interface="virtual", channel=channel)
        self.link = IsobusLink(can.Bus(interface="virtual", channel=channel))
        try:
            config = controller_config or IsobusControllerConfig(calibration=calibration, wheelbase=wheelbase)
            self.firmware = IsobusController(self._device_bus, plant, config, speed=speed)
            self.scheduler = LockstepScheduler(self.clock, [self.firmware, *extra_devices], plant, max_step=max_step)
            self.driver: IsobusDriver = self.link.driver(self.clock, driver_config or isobus_driver_config(wheelbase))
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Shut both ends of the bus down."""
        self.link.close()
        self._device_bus.shutdown()

    def __enter__(self) -> IsobusLockstepBench:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
