"""`--bridge isobus...`: the specification, the bus it opens and the guidance system's node on it."""

from __future__ import annotations

import itertools

import can
import pytest

from hil.links.clock import VirtualClock
from hil.vehicle.errors import BridgeSpecError
from hil.vehicle.bridge_spec import BridgeSpec, parse_bridge
from hil.vehicle.drive import DriveConfig
from hil.vehicle.isobus.driver import IsobusDriverConfig
from hil.vehicle.isobus.errors import IsobusConfigError, IsobusLinkError
from hil.vehicle.isobus.link import GUIDANCE_ADDRESS, GUIDANCE_NAME, open_isobus_link
from hil.vehicle.isobus.network import PGN_ADDRESS_CLAIMED, CanId, Name
from hil.vehicle.isobus.protocol import PGN_COMMAND, CommandStatus, decode

_channels = itertools.count()


@pytest.mark.parametrize("text, spec", [
    ("isobus", BridgeSpec("isobus", "udp_multicast", device="239.74.163.2", port=43113)),
    ("isobus:socketcan:can0", BridgeSpec("isobus", "socketcan", device="can0")),
    ("isobus:virtual:bench-7", BridgeSpec("isobus", "virtual", device="bench-7")),
    ("isobus:udp_multicast:239.74.163.2", BridgeSpec("isobus", "udp_multicast", device="239.74.163.2", port=43113)),
    ("isobus:udp_multicast:239.1.2.3:45001", BridgeSpec("isobus", "udp_multicast", device="239.1.2.3", port=45001)),
])
def test_isobus_bridge_specifications(text, spec):
    assert parse_bridge(text) == spec


@pytest.mark.parametrize("text, match", [
    ("isobus:pcan:PCAN_USBBUS1", "must be one of socketcan, udp_multicast, virtual, got 'pcan'"),
    ("isobus:socketcan", "expected isobus:socketcan:CHANNEL, e.g. isobus:socketcan:can0"),
    ("isobus:socketcan:", "expected isobus:socketcan:CHANNEL"),
    ("isobus:socketcan:/dev/can0", "is not a network interface name"),
    ("isobus:udp_multicast:127.0.0.1", "'127.0.0.1' is not an IPv4 multicast group"),
    ("isobus:udp_multicast:ff15::1", "is not an IPv4 multicast group"),
    ("isobus:udp_multicast:239.1.2.3:70000", "the UDP port must be a port number"),
    ("isobus:udp_multicast:239.1.2.3:0", "the UDP port must be 1..65535"),
    ("isobus:", "must be one of"),
])
def test_bad_isobus_specifications_are_refused_with_the_form_expected(text, match):
    with pytest.raises(BridgeSpecError, match=match) as info:
        parse_bridge(text)
    assert repr(text) in str(info.value) and "\n" not in str(info.value)
    with pytest.raises(ValueError):
        DriveConfig(text, "/dev/null")


def test_drive_config_checks_the_wheelbase_of_an_isobus_bridge():
    with pytest.raises(IsobusConfigError, match="wheelbase must be a finite number > 0 m, got -1"):
        DriveConfig("isobus:socketcan:can0", "/dev/null", wheelbase=-1.0)
    DriveConfig("/dev/ttyS0", "/dev/null", wheelbase=-1.0)      # not used by an HC11 bridge


def test_the_link_puts_the_guidance_node_on_the_bus_and_claims_its_address():
    channel = f"isobus-link-{next(_channels)}"
    link = open_isobus_link(parse_bridge(f"isobus:virtual:{channel}"))
    listener = can.Bus(interface="virtual", channel=channel)
    try:
        clock = VirtualClock()
        driver = link.driver(clock, IsobusDriverConfig(wheelbase=2.7))
        claim = listener.recv(1.0)
        cid = CanId.decode(claim.arbitration_id)
        assert (cid.pgn, cid.source) == (PGN_ADDRESS_CLAIMED, GUIDANCE_ADDRESS)
        assert Name.from_bytes(bytes(claim.data)) == GUIDANCE_NAME
        with pytest.raises(IsobusConfigError, match="already has the guidance system's node"):
            link.driver(clock, IsobusDriverConfig(wheelbase=2.7))
        clock.sleep_until(0.25)              # the claim stands: the first "not intended" goes out
        driver.poll()
        command = listener.recv(1.0)
        assert CanId.decode(command.arbitration_id).pgn == PGN_COMMAND
        assert decode(PGN_COMMAND, bytes(command.data)).status is CommandStatus.NOT_INTENDED
    finally:
        listener.shutdown()
        link.close()


def test_an_interface_that_cannot_be_opened_is_one_line_naming_it():
    with pytest.raises(IsobusLinkError, match=r"isobus:socketcan:nocan7: cannot open the CAN bus .*ip link") as info:
        open_isobus_link(parse_bridge("isobus:socketcan:nocan7"))
    assert isinstance(info.value, OSError) and "\n" not in str(info.value)

