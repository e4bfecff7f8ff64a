"""ISO 11783-5 address claim and guidance traffic on python-can buses (virtual in lockstep, UDP multicast
in real time).

Identifier layout (J1939-21 / ISO 11783-3): priority bits 26-28, data page 24, PF 16-23, PS (the
destination of a PDU1 group) 8-15, source 0-7; Address Claimed is PGN 60928 at priority 6 to 255.
"""

from __future__ import annotations

import itertools

import can
import pytest

from hil.links.clock import RealClock, VirtualClock
from hil.vehicle.isobus.errors import AddressClaimError, FieldError, IsobusConfigError, IsobusLinkError
from hil.vehicle.isobus.network import CLAIM_WAIT, CanId, Name, Node, open_bus
from hil.vehicle.isobus.protocol import CommandStatus, GuidanceSystemCommand

_channels = itertools.count()


@pytest.fixture
def buses():
    channel = f"isobus-test-{next(_channels)}"
    opened: list[can.BusABC] = []

    def bus() -> can.BusABC:
        opened.append(can.Bus(interface="virtual", channel=channel))
        return opened[-1]

    yield bus
    for b in opened:
        b.shutdown()


def frames(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (m := bus.recv(0.0)) is not None:
        out.append(m)
    return out


LOW, HIGH = Name(identity=5, manufacturer=69, function=0x83), Name(identity=6, manufacturer=69, function=0x83)


def test_identifiers_golden():
    assert CanId(3, 0xAD00, source=0x80, destination=0x1C).encode() == 0x0CAD1C80
    assert CanId(6, 0xEE00, source=0x80).encode() == 0x18EEFF80
    assert CanId.decode(0x0CAC801C) == CanId(3, 0xAC00, 0x1C, 0x80)
    assert CanId.decode(0x18FEF100) == CanId(6, 0xFEF1, 0x00, 0xFF)       # PDU2: PS is part of the PGN


def test_name_bits_and_order():
    name = Name(identity=0x1FFFFF, manufacturer=0x7FF, industry_group=2, self_configurable=True)
    assert name.value == (1 << 63) | (2 << 60) | (0x7FF << 21) | 0x1FFFFF
    assert Name.from_bytes(name.to_bytes()) == name and name.to_bytes()[0] == 0xFF
    assert LOW.value < HIGH.value
    with pytest.raises(IsobusConfigError, match=r"identity must be an int in \[0, 2097151\]"):
        Name(identity=1 << 21)


def test_no_guidance_before_the_claim_has_stood_for_250_ms(buses):
    clock = VirtualClock()
    node, listener = Node(buses(), LOW, 0x80, clock), buses()
    command = GuidanceSystemCommand(0.0, CommandStatus.NOT_INTENDED)
    with pytest.raises(AddressClaimError, match="not claimed; call claim"):
        node.send(command)
    node.claim()
    claim = frames(listener)
    assert [(m.arbitration_id, bytes(m.data)) for m in claim] == [(0x18EEFF80, LOW.to_bytes())]
    clock.advance_to(CLAIM_WAIT - 1e-6)
    with pytest.raises(AddressClaimError, match="usable 0.25 s later"):
        node.send(command)
    clock.advance_to(CLAIM_WAIT)
    node.send(command, destination=0x1C)
    [m] = frames(listener)
    assert m.arbitration_id == 0x0CAD1C80 and bytes(m.data) == bytes.fromhex("807dfcffffffffff")


def test_a_conflict_the_lower_name_keeps_the_address_the_higher_claims_another(buses):
    clock = VirtualClock()
    lost = []
    low, high = Node(buses(), LOW, 0x2A, clock), Node(buses(), HIGH, 0x2A, clock, on_lost=lambda: lost.append(1))
    listener = buses()
    low.claim()
    high.claim()
    high.poll()          # sees LOW's claim for 0x2A: loses, claims 128 (self-configurable)
    low.poll()           # sees HIGH's claim for 0x2A: wins, claims again
    clock.advance_to(CLAIM_WAIT)
    high.poll()
    assert (low.address, high.address, lost) == (0x2A, 128, [1])
    assert low.claimed and high.claimed and low.conflicts == 1 and high.conflicts == 1
    sources = [CanId.decode(m.arbitration_id).source for m in frames(listener)]
    assert sources == [0x2A, 0x2A, 128, 0x2A]   # low, high, high's new claim, low's repeated claim


def test_a_node_that_cannot_configure_itself_goes_silent_with_cannot_claim(buses):
    clock = VirtualClock()
    # The self-configurable bit is the NAME's most significant: a fixed NAME outranks every
    # self-configurable one, so both nodes here are fixed.
    low_fixed = Name(identity=5, manufacturer=69, self_configurable=False)
    fixed = Name(identity=6, manufacturer=69, self_configurable=False)
    low, high, listener = Node(buses(), low_fixed, 0x2A, clock), Node(buses(), fixed, 0x2A, clock), buses()
    low.claim()
    high.claim()
    high.poll()
    frames(listener)
    clock.advance_to(1.0)
    assert high.silent and not high.claimed and high.address is None
    with pytest.raises(AddressClaimError, match="lost and no address is free"):
        high.send(GuidanceSystemCommand(0.0, CommandStatus.NOT_INTENDED))
    low.request_claims()           # a request is answered with Cannot Claim Address from 254
    high.poll()
    low.poll()
    answers = [(CanId.decode(m.arbitration_id).source, Name.from_bytes(bytes(m.data))) for m in frames(listener)
               if CanId.decode(m.arbitration_id).pgn == 0xEE00]
    assert answers == [(0xFE, fixed), (0x2A, low_fixed)]


def test_guidance_to_another_address_is_ignored_and_malformed_data_is_a_refusal(buses):
    clock = VirtualClock()
    node, raw = Node(buses(), LOW, 0x1C, clock), buses()
    raw.send(can.Message(arbitration_id=CanId(3, 0xAD00, 0x80, 0x33).encode(), data=bytes(8), is_extended_id=True))
    raw.send(can.Message(arbitration_id=CanId(3, 0xAD00, 0x80, 0x1C).encode(),
                         data=bytes.fromhex("807df9ffffffffff"), is_extended_id=True))
    raw.send(can.Message(arbitration_id=CanId(3, 0xAD00, 0x80, 0xFF).encode(),
                         data=bytes.fromhex("587dfdffffffffff"), is_extended_id=True))
    got = node.poll()
    assert [r.source for r in got] == [0x80, 0x80]
    assert isinstance(got[0].message, FieldError) and node.refused == 1
    assert got[1].message == GuidanceSystemCommand(0.01, CommandStatus.INTENDED)


@pytest.mark.parametrize("spec, error, match", [
    ("socketcan:can0", IsobusConfigError, "expected isobus:INTERFACE:CHANNEL"),
    ("isobus:pcan:PCAN_USBBUS1", IsobusConfigError, "interface must be socketcan, virtual or udp_multicast"),
    ("isobus:socketcan:nosuchcan9", IsobusLinkError, "cannot open socketcan"),
])
def test_bus_specifications(spec, error, match):
    with pytest.raises(error, match=match):
        open_bus(spec)


def test_a_virtual_bus_by_specification():
    a, b = open_bus("isobus:virtual:spec-test"), open_bus("isobus:virtual:spec-test")
    try:
        a.send(can.Message(arbitration_id=0x18EEFF80, data=LOW.to_bytes(), is_extended_id=True))
        assert bytes(b.recv(0.0).data) == LOW.to_bytes()
    finally:
        a.shutdown()
        b.shutdown()


@pytest.mark.realtime
def test_claim_and_a_command_over_udp_multicast_in_real_time():
    a, b = open_bus("isobus:udp_multicast:239.74.163.2"), open_bus("isobus:udp_multicast:239.74.163.2")
    try:
        clock = RealClock()
        guidance, controller = Node(a, LOW, 0x80, clock), Node(b, HIGH, 0x1C, clock)
        guidance.claim()
        controller.claim()
        clock.sleep_until(CLAIM_WAIT + 0.05)
        guidance.poll()
        controller.poll()
        guidance.send(GuidanceSystemCommand(-0.01, CommandStatus.INTENDED), destination=0x1C)
        got = []
        deadline = clock.now() + 2.0            # slack for a stalled host
        while not got and clock.now() < deadline:
            got = controller.poll()
            clock.sleep_until(clock.now() + 0.005)
        assert [(r.source, r.message) for r in got] == [(0x80, GuidanceSystemCommand(-0.01, CommandStatus.INTENDED))]
        assert guidance.conflicts == 0 and controller.conflicts == 0   # its own looped-back claim is no conflict
    finally:
        a.shutdown()
        b.shutdown()
