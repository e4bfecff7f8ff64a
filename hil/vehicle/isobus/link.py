"""The vehicle's end of an ISO 11783 steering link: the CAN bus of a ``--bridge isobus...`` specification,
this guidance system's node on it, and the driver and loop settings the vehicle loop steers with.

:func:`open_isobus_link` opens the bus a parsed specification names
(:func:`hil.vehicle.agio.spec.parse_bridge`, :func:`hil.vehicle.isobus.bus.open_isobus_bus`:
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
from hil.vehicle.agio.driver import module_loop_config
from hil.vehicle.agio.spec import BridgeSpec
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

__all__ = ["GUIDANCE_NAME", "GUIDANCE_ADDRESS", "IsobusLink",
           "open_isobus_link", "isobus_loop_config", "isobus_driver_config"]

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


def isobus_loop_config(base: LoopConfig | None = None, lag: float = ISOBUS_LAG) -> LoopConfig:
    """The loop's rate limit and steering-response monitor for a steering controller: the steer-module rule
    (:func:`hil.vehicle.agio.driver.module_loop_config`, full rate
    :data:`~hil.vehicle.isobus.driver.ISOBUS_MAX_RATE` both ways) with delay ``lag``, s, and the reported
    angle's noise :data:`~hil.vehicle.isobus.driver.ANGLE_NOISE`."""
    return module_loop_config(base, max_rate=ISOBUS_MAX_RATE, lag=lag, angle_noise=ANGLE_NOISE)
