"""Bridge specifications of ``--bridge`` (``hil drive``, ``hil valve-test``, ``hil emulate``, ...): which
steering bridge, over which link. Shared by the three bridges; each opens its own link from the parsed
specification.

::

    hc11:PORT                          the HC11 board on a serial port (a bare PORT means the same)
    agopengps:serial:PORT              an AgOpenGPS steer module on a USB serial port
    agopengps:udp:HOST:PORT[:LOCAL]    an AgOpenGPS steer module over UDP: it listens on HOST:PORT
                                       (192.168.5.126:8888), the host binds LOCAL (default 9999)
    isobus:socketcan:IFACE             an ISO 11783 steering-ready tractor on a SocketCAN interface (can0)
    isobus:udp_multicast:GROUP[:PORT]  the same over python-can's UDP multicast bus (between processes on
                                       one host: ``hil emulate --bridge isobus``; default port 43113)
    isobus:virtual:NAME                python-can's in-process virtual bus (tests)
    isobus                             ``isobus:udp_multicast:239.74.163.2:43113``, the emulated tractor's
                                       default bus
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

from hil.vehicle.errors import BridgeSpecError

__all__ = ["BridgeSpec", "parse_bridge", "AGIO_LOCAL_PORT", "AGIO_MODULE_PORT", "ISOBUS_GROUP",
           "ISOBUS_PORT", "ISOBUS_INTERFACES"]

AGIO_LOCAL_PORT = 9999
"""Port AgIO (and the host) binds; the modules reply to it."""
AGIO_MODULE_PORT = 8888
"""Port the steer module listens on."""
ISOBUS_GROUP = "239.74.163.2"
"""IPv4 multicast group of the default ISOBUS bus (python-can's ``UdpMulticastBus.DEFAULT_GROUP_IPv4``)."""
ISOBUS_PORT = 43113
"""UDP port of python-can's multicast bus (its default)."""
ISOBUS_INTERFACES = ("socketcan", "udp_multicast", "virtual")
"""python-can interfaces an ``isobus:`` bridge may name."""


@dataclass(frozen=True)
class BridgeSpec:
    """A parsed ``--bridge`` value.

    Parameters
    ----------
    kind : str
        ``hc11``, ``agopengps`` or ``isobus``.
    transport : str
        ``serial`` or ``udp``; for ``isobus`` the python-can interface (:data:`ISOBUS_INTERFACES`).
    device : str
        Serial device (serial transport); for ``isobus`` the python-can channel (``can0``, the multicast
        group, the virtual bus's name).
    host, port, local_port
        The module's IPv4 address and port, and the port the host binds (udp transport); for
        ``isobus:udp_multicast`` the UDP port is ``port``.
    """

    kind: str
    transport: str
    device: str = ""
    host: str = ""
    port: int = 0
    local_port: int = AGIO_LOCAL_PORT


def _port(text: str, what: str, spec: str) -> int:
    if not text.isdigit() or not 0 <= int(text) <= 65535:
        raise BridgeSpecError(f"bridge {spec!r}: {what} must be a port number 0..65535, got {text!r}")
    return int(text)


def _isobus(text: str, rest: str) -> BridgeSpec:
    """``isobus[:INTERFACE:CHANNEL]`` (``rest`` is what follows ``isobus:``)."""
    if text == "isobus":
        return BridgeSpec("isobus", "udp_multicast", device=ISOBUS_GROUP, port=ISOBUS_PORT)
    interface, sep, channel = rest.partition(":")
    if interface not in ISOBUS_INTERFACES:
        raise BridgeSpecError(f"bridge {text!r}: the CAN interface must be one of {', '.join(ISOBUS_INTERFACES)}, "
                              f"got {interface!r}; e.g. isobus:socketcan:can0")
    if not sep or not channel:
        raise BridgeSpecError(f"bridge {text!r}: expected isobus:{interface}:CHANNEL, e.g. "
                              + {"socketcan": "isobus:socketcan:can0", "virtual": "isobus:virtual:bench",
                                 "udp_multicast": f"isobus:udp_multicast:{ISOBUS_GROUP}"}[interface])
    if interface == "socketcan":
        if len(channel) > 15 or not all(c.isalnum() or c in "_-." for c in channel):
            raise BridgeSpecError(f"bridge {text!r}: {channel!r} is not a network interface name (up to 15 "
                                  "letters, digits, '_', '-', '.'), e.g. can0")
        return BridgeSpec("isobus", "socketcan", device=channel)
    if interface == "virtual":
        return BridgeSpec("isobus", "virtual", device=channel)
    group, _, port = channel.partition(":")
    try:
        multicast = ipaddress.IPv4Address(group).is_multicast
    except ValueError:
        multicast = False
    if not multicast:
        raise BridgeSpecError(f"bridge {text!r}: {group!r} is not an IPv4 multicast group (224.0.0.0/4); expected "
                              f"isobus:udp_multicast:GROUP[:PORT], e.g. isobus:udp_multicast:{ISOBUS_GROUP}")
    number = _port(port, "the UDP port", text) if port else ISOBUS_PORT
    if number == 0:
        raise BridgeSpecError(f"bridge {text!r}: the UDP port must be 1..65535 (every node of the bus uses the same "
                              "one), got 0")
    return BridgeSpec("isobus", "udp_multicast", device=group, port=number)


def parse_bridge(text: str) -> BridgeSpec:
    """Parse ``hc11:PORT``, ``agopengps:serial:PORT``, ``agopengps:udp:HOST:PORT[:LOCAL]``,
    ``isobus[:INTERFACE:CHANNEL]`` or a bare PORT.

    Raises
    ------
    BridgeSpecError
        An unknown kind, transport or CAN interface, a malformed address or port, an empty device.
    """
    if not isinstance(text, str) or not text:
        raise BridgeSpecError("the bridge must be named: hc11:PORT, agopengps:serial:PORT, agopengps:udp:HOST:PORT "
                              "or isobus:INTERFACE:CHANNEL")
    kind, sep, rest = text.partition(":")
    if kind == "isobus":
        return _isobus(text, rest)
    if kind == "hc11":
        if not rest:
            raise BridgeSpecError(f"bridge {text!r}: hc11:PORT needs a serial device, e.g. hc11:/dev/ttyS0")
        return BridgeSpec("hc11", "serial", device=rest)
    if kind != "agopengps":
        if kind.startswith("/") or not sep:      # a bare device path: the HC11 board, as before
            return BridgeSpec("hc11", "serial", device=text)
        raise BridgeSpecError(f"unknown bridge {kind!r} in {text!r}; expected hc11:PORT, agopengps:serial:PORT, "
                              "agopengps:udp:HOST:PORT or isobus:INTERFACE:CHANNEL")
    transport, _, where = rest.partition(":")
    if transport == "serial":
        if not where:
            raise BridgeSpecError(f"bridge {text!r}: agopengps:serial:PORT needs a device, e.g. /dev/ttyACM0")
        return BridgeSpec("agopengps", "serial", device=where)
    if transport != "udp":
        raise BridgeSpecError(f"bridge {text!r}: the transport must be serial or udp, got {transport!r}")
    parts = where.split(":")
    if len(parts) not in (2, 3):
        raise BridgeSpecError(f"bridge {text!r}: expected agopengps:udp:HOST:PORT[:LOCALPORT], "
                              f"e.g. agopengps:udp:192.168.5.126:8888")
    try:
        ipaddress.IPv4Address(parts[0])
    except ValueError:
        raise BridgeSpecError(f"bridge {text!r}: {parts[0]!r} is not an IPv4 address (the module is "
                              "usually 192.168.5.126)") from None
    local = _port(parts[2], "the local port", text) if len(parts) == 3 else AGIO_LOCAL_PORT
    return BridgeSpec("agopengps", "udp", host=parts[0], port=_port(parts[1], "the module's port", text),
                      local_port=local)
