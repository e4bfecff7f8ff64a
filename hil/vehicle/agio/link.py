"""Opening the link to an AgOpenGPS steer module from a parsed bridge specification
(:func:`hil.vehicle.bridge_spec.parse_bridge`)."""

from __future__ import annotations

import ipaddress
from collections.abc import Callable

from hil.links.link import ByteLink
from hil.links.udp import UdpLink
from hil.vehicle.agio.errors import AgioConfigError
from hil.vehicle.bridge_spec import BridgeSpec

__all__ = ["open_agio_link"]


def open_agio_link(spec: BridgeSpec, open_port: Callable[..., ByteLink], baud: int) -> ByteLink:
    """Open the link to an AgOpenGPS module.

    Parameters
    ----------
    spec
        A parsed ``agopengps:...`` specification.
    open_port
        Opens a serial port (``serial.Serial``'s signature), for the serial transport.
    baud
        Serial line rate, bit/s (a USB CDC port ignores it).

    Raises
    ------
    AgioConfigError
        ``spec`` is not an AgOpenGPS bridge.
    OSError
        The socket cannot be bound or the port opened.
    """
    if spec.kind != "agopengps":
        raise AgioConfigError(f"not an AgOpenGPS bridge: {spec}")
    if spec.transport == "serial":
        return open_port(spec.device, baudrate=baud, timeout=0)
    broadcast = ipaddress.IPv4Address(spec.host) == ipaddress.IPv4Address("255.255.255.255") \
        or spec.host.endswith(".255")
    return UdpLink(("0.0.0.0", spec.local_port), peer=(spec.host, spec.port), accept_any=broadcast,
                   broadcast=broadcast)
