"""The python-can bus of an ``isobus`` bridge specification (:func:`hil.vehicle.bridge_spec.parse_bridge`), for
the vehicle's end (:mod:`hil.vehicle.isobus.link`) and the emulated controller's (``hil emulate``) alike."""

from __future__ import annotations

import can

from hil.vehicle.bridge_spec import BridgeSpec
from hil.vehicle.isobus.errors import IsobusConfigError, IsobusLinkError

__all__ = ["open_isobus_bus", "bus_text"]


def bus_text(spec: BridgeSpec) -> str:
    """The specification of ``spec``'s bus written out in full (``isobus:udp_multicast:239.74.163.2:43113``)."""
    port = f":{spec.port}" if spec.transport == "udp_multicast" else ""
    return f"isobus:{spec.transport}:{spec.device}{port}"


def open_isobus_bus(spec: BridgeSpec) -> can.BusABC:
    """Open the python-can bus of an ``isobus`` specification (the caller shuts it down).

    Raises
    ------
    IsobusConfigError
        ``spec`` is not an ``isobus`` bridge.
    IsobusLinkError
        The interface cannot be opened (a ``ConnectionError``, so an ``OSError``).
    """
    if spec.kind != "isobus":
        raise IsobusConfigError(f"not an ISOBUS bridge: {spec}; expected isobus:INTERFACE:CHANNEL")
    options = {"port": spec.port} if spec.transport == "udp_multicast" else {}
    try:
        return can.Bus(interface=spec.transport, channel=spec.device, **options)
    except (can.CanError, OSError, ImportError) as exc:
        raise IsobusLinkError(f"bridge {bus_text(spec)}: cannot open the CAN bus ({exc}); check the interface "
                              "exists and is up (ip link show), or name another") from exc
