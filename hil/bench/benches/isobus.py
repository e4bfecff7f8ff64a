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
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import TracebackType

import can
import numpy as np

from hil.devices.firmware import SteeringPlant
from hil.devices.isobus_controller import IsobusController, IsobusControllerConfig
from hil.links.clock import VirtualClock
from hil.links.scheduler import Device, LockstepScheduler
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.isobus.driver import IsobusDriver, IsobusDriverConfig
from hil.vehicle.isobus.link import IsobusLink, isobus_driver_config

__all__ = ["IsobusLockstepBench", "ControllerDelays", "controller_delays"]

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


@dataclass(frozen=True)
class ControllerDelays:
    """How far each stage of the steering controller trails the driver's wheel-angle setpoint, s.

    Parameters
    ----------
    setpoint : float
        The controller's own setpoint (after its curvature filter and rate limit).
    wheel : float
        The true wheel angle.
    measured : float
        The wheel angle of the reported curvature, as the loop reads it at 20 Hz.
    """

    setpoint: float
    wheel: float
    measured: float


def _lag(a: np.ndarray, b: np.ndarray, dt: float, max_lag: int = 30) -> float:
    """The shift of ``b`` behind ``a`` that correlates best, s (whole samples refined by a parabola)."""
    a, b = a - a.mean(), b - b.mean()
    corr = np.array([np.dot(a[:len(a) - k], b[k:]) / (np.linalg.norm(a[:len(a) - k]) * np.linalg.norm(b[k:]))
                     for k in range(max_lag + 1)])
    k = int(np.argmax(corr))
    if 0 < k < max_lag:
        c0, c1, c2 = corr[k - 1:k + 2]
        return float(k + 0.5 * (c0 - c2) / (c0 - 2.0 * c1 + c2)) * dt
    return float(k * dt)


def controller_delays(seconds: float = 60.0, seed: int = 0, **controller: float) -> ControllerDelays:
    """Measure the steering controller's delays on the lockstep bench (the simulated tractor, no implement,
    1.79 m/s): the driver steers a random wheel-angle rate (up to 0.35 rad/s, pulled back to straight ahead)
    at 20 Hz, as the loop does, and each stage is compared with the setpoint it integrates.

    Parameters
    ----------
    seconds
        Length of the measurement, s.
    seed
        Of the rate signal and the simulator.
    controller
        Settings of the controller (:class:`IsobusControllerConfig`) other than its calibration and
        wheelbase, the tractor's (default: its defaults).
    """
    from hil.devices.plant import SimulatedTractor
    from hil.devices.wheel_calibration import two_point_calibration
    from hil.truth.conditions import condition_for
    plant = SimulatedTractor(condition_for("none", 1.79), seconds + 5.0, seed)
    p = plant.params
    cal = two_point_calibration(p.sensor, p.steering)
    rng = np.random.default_rng(seed)
    dt, rows = 0.05, []
    config = IsobusControllerConfig(calibration=cal, wheelbase=p.vehicle.wheelbase, **controller)
    with IsobusLockstepBench(plant, cal, p.vehicle.wheelbase, controller_config=config, max_step=0.01) as bench:
        t, driver = 0.0, bench.driver
        for _ in range(20):                           # the claim and the handshake
            t += dt
            bench.clock.sleep_until(t)
            driver.poll()
        driver.engage()
        rate = 0.0
        for _ in range(round(seconds / dt)):
            t += dt
            bench.clock.sleep_until(t)
            driver.poll()
            rate = min(0.35, max(-0.35, 0.9 * rate + rng.normal(0.0, 0.06) - 0.5 * driver.setpoint))
            driver.send_rate(rate)
            rows.append((driver.setpoint, math.atan(config.wheelbase * bench.firmware.state.setpoint),
                         float(plant.truth()["wheel_angle"]), driver.latest.angle))
    s, c, w, m = np.array(rows).T
    return ControllerDelays(setpoint=_lag(s, c, dt), wheel=_lag(s, w, dt), measured=_lag(s, m, dt))
