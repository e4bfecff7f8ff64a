"""The vehicle's end of an ISO 11783 steering link: the CAN bus of a ``--bridge isobus...`` specification,
this guidance system's node on it, and the driver and loop settings the vehicle loop steers with.

:func:`open_isobus_link` opens the bus a parsed specification names
(:func:`hil.vehicle.bridge_spec.parse_bridge`, :func:`hil.vehicle.isobus.bus.open_isobus_bus`:
``isobus:socketcan:can0`` on a tractor, ``isobus:udp_multicast:GROUP[:PORT]`` against
``hil emulate --bridge isobus``, ``isobus:virtual:NAME`` in one process); :meth:`IsobusLink.driver`
puts the guidance system's node on it (NAME :data:`GUIDANCE_NAME`, preferred address
:data:`GUIDANCE_ADDRESS`, self-configurable) and returns the
:class:`~hil.vehicle.isobus.driver.IsobusDriver` the loop steers through. The loop reads the wheel angle
of the controller's estimated curvature, ``atan(wheelbase x curvature)``, through
:data:`~hil.vehicle.isobus.driver.ANGLE_CALIBRATION`, and takes its rate limit and steering-response
monitor from :func:`isobus_loop_config` (the steer-module rule with the controller's delay
:data:`~hil.vehicle.isobus.driver.ISOBUS_LAG`); the driver's anti-windup comes from the same delay
(:func:`isobus_driver_config`, whose defaults are the driver's own).
"""

from __future__ import annotations

import can

from hil.links.clock import Clock
from hil.vehicle.bridge_spec import BridgeSpec
from hil.vehicle.commissioning import Commissioning, loop_settings
from hil.vehicle.isobus.bus import open_isobus_bus
from hil.vehicle.isobus.driver import (
    ANGLE_NOISE,
    ISOBUS_LAG,
    ISOBUS_MAX_RATE,
    IsobusDriver,
    IsobusDriverConfig,
    windup_bound,
)
from hil.vehicle.isobus.errors import IsobusConfigError
from hil.vehicle.isobus.network import Name, Node
from hil.vehicle.loop import LoopConfig
from hil.vehicle.valve_map import ValveCurve

__all__ = ["GUIDANCE_NAME", "GUIDANCE_ADDRESS", "IsobusLink", "open_isobus_link", "isobus_loop_config",
           "isobus_driver_config", "controller_actuator", "controller_commissioning"]

GUIDANCE_NAME = Name(identity=0x7A5, manufacturer=0, function=0x83, vehicle_system=1, industry_group=2,
                     self_configurable=True)
"""NAME of the toolkit's guidance system (function 131; self-configurable, so it moves to a free address of
128-247 when a NAME of higher priority holds its own)."""
GUIDANCE_ADDRESS = 0x80
"""Preferred source address of the guidance system (the first of the self-configurable range)."""


class IsobusLink:
    """An open CAN bus for the guidance system (``close`` shuts it down, as a serial port's would).

    Parameters
    ----------
    bus : can.BusABC
        The bus (owned from now on).
    """

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.node: Node | None = None

    def driver(self, clock: Clock, config: IsobusDriverConfig, name: Name = GUIDANCE_NAME,
               address: int = GUIDANCE_ADDRESS) -> IsobusDriver:
        """The guidance system's node on the bus and the driver steering through it (the claim is sent now).

        Raises
        ------
        IsobusConfigError
            A second driver on the same link.
        IsobusLinkError
            The address claim cannot be sent.
        """
        if self.node is not None:
            raise IsobusConfigError("this ISOBUS link already has the guidance system's node; open another link")
        self.node = Node(self.bus, name, address, clock)
        return IsobusDriver(self.node, clock, config)

    def close(self) -> None:
        """Shut the bus down (python-can logs, never raises)."""
        self.bus.shutdown()


def open_isobus_link(spec: BridgeSpec) -> IsobusLink:
    """:func:`open_isobus_bus` as an :class:`IsobusLink`."""
    return IsobusLink(open_isobus_bus(spec))


def isobus_driver_config(wheelbase: float, lag: float = ISOBUS_LAG, max_rate: float = ISOBUS_MAX_RATE,
                         angle_noise: float = ANGLE_NOISE) -> IsobusDriverConfig:
    """The driver's settings for a steering controller whose measured angle trails the command by ``lag``, s.

    The setpoint is held within :func:`~hil.vehicle.isobus.driver.windup_bound` of the measured angle
    (anti-windup; with the defaults it is the driver's own default, 0.115 rad).

    Parameters
    ----------
    wheelbase
        m.
    lag, max_rate, angle_noise
        s, rad/s, rad.
    """
    return IsobusDriverConfig(wheelbase=wheelbase, max_rate=max_rate,
                              max_windup=windup_bound(lag, max_rate, angle_noise))


def controller_actuator(lag: float = ISOBUS_LAG) -> ValveCurve:
    """The steering controller as the loop's actuator: the wheel-angle rate the loop commands, up to
    :data:`~hil.vehicle.isobus.driver.ISOBUS_MAX_RATE` both ways, no dead band and linear (the controller
    closes its own loop on the curvature), the measured angle ``lag``, s, behind, with the reported angle's
    noise :data:`~hil.vehicle.isobus.driver.ANGLE_NOISE`."""
    return ValveCurve(full_scale=ISOBUS_MAX_RATE, deadband=0.0, flow_exponent=1.0, left_rate=ISOBUS_MAX_RATE,
                      right_rate=ISOBUS_MAX_RATE, lag=lag, angle_noise=ANGLE_NOISE)


def isobus_loop_config(base: LoopConfig | None = None, lag: float = ISOBUS_LAG) -> LoopConfig:
    """The loop's rate limit and steering-response monitor for a steering controller: the rule of a measured
    valve (:func:`hil.vehicle.commissioning.loop_settings`, as for a steer module) with
    :func:`controller_actuator` of delay ``lag``, s, as the actuator."""
    return loop_settings(controller_actuator(lag), base, linearity_error=0.0)


def controller_commissioning(tractor: str = "tractor") -> Commissioning:
    """The commissioning file of an ISO 11783 steering-ready tractor, for the field procedure.

    Its valve is commissioned by the tractor's maker and driven in a closed loop by the steering controller,
    so there is no valve test (``hil valve-test`` refuses the bridge). The file holds
    :func:`controller_actuator` instead of a measured valve: the excitation's full rate, and the loop's rate
    limit and steering-response monitor as :func:`isobus_loop_config` sets them, except that with no
    linearity measured the monitor keeps the larger margin of an unmeasured map.
    """
    return Commissioning(tractor=tractor, valve=controller_actuator(), linearity=None,
                         notes="ISO 11783 steering controller: no valve test (it closes its own loop); the "
                               "actuator is the controller as the loop sees it (hil.vehicle.isobus.link)")
