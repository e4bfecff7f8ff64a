"""ISO 11783-5 network management on python-can: the NAME, address claim, and one node's traffic.

A :class:`Node` is one control function on a CAN bus (a ``can.BusABC``: python-can's virtual bus
in lockstep tests, its UDP multicast bus between processes, SocketCAN on a tractor). It claims
its address before it sends anything, answers requests for the address claim, resolves a
conflict by NAME (the numerically lower NAME wins), and sends and receives the guidance
parameter groups of :mod:`hil.vehicle.isobus.protocol`. Time comes from a
:class:`~hil.links.clock.Clock`; nothing here sleeps or starts a thread, so the same node runs on
the virtual clock and in real time (whoever owns the loop calls :meth:`Node.poll`).

Address claim (ISO 11783-5, as SAE J1939-81): the node sends Address Claimed (PGN 60928 to the
global address 255, priority 6, data = its 64-bit NAME, little-endian) and may send other
messages once no contending claim has arrived for 250 ms. A claim for the same address from
another NAME: if ours is lower, the node sends its claim again and keeps the address; if higher,
it loses the address and, when its NAME is self-configurable, claims the next free address of
its range, else sends Cannot Claim Address (source 254) and stays silent. A Request (PGN 59904)
for PGN 60928 sent to the global address or to ours is answered with the claim.

python-can and not can-j1939: can-j1939 runs its own threads and wall-clock timers, so its claim
cannot be stepped on the virtual clock of the lockstep bench, and the node would be two state
machines (its and ours) for the one guidance interface that needs it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import can

from hil.links.clock import Clock
from hil.vehicle.isobus.errors import (
    AddressClaimError,
    FrameError,
    IsobusConfigError,
    IsobusLinkError,
)
from hil.vehicle.isobus.protocol import CLASSES, PRIORITY, Message, decode, encode

__all__ = [
    "PGN_ADDRESS_CLAIMED", "PGN_REQUEST", "GLOBAL", "NULL_ADDRESS", "CLAIM_WAIT", "Name", "CanId", "Received",
    "Node", "open_bus",
]

PGN_ADDRESS_CLAIMED = 0xEE00
"""Address Claimed / Cannot Claim Address, PGN 60928."""
PGN_REQUEST = 0xEA00
"""Request, PGN 59904 (3 data bytes: the requested PGN, little-endian)."""
GLOBAL = 0xFF
"""The global destination address."""
NULL_ADDRESS = 0xFE
"""Source address of Cannot Claim Address."""
CLAIM_WAIT = 0.25
"""Time after an address claim before other messages may be sent, s."""
MAX_FRAMES_PER_POLL = 256
"""Frames one :meth:`Node.poll` reads at most (a flooded bus cannot hold the loop)."""


@dataclass(frozen=True)
class Name:
    """The 64-bit ISO 11783-5 NAME of a control function; a lower value wins an address conflict.

    Parameters
    ----------
    identity : int
        Identity number, 21 bits (unique per manufacturer).
    manufacturer : int
        Manufacturer code, 11 bits.
    ecu_instance, function_instance : int
        3 and 5 bits.
    function : int
        Function, 8 bits.
    vehicle_system, vehicle_system_instance : int
        7 and 4 bits.
    industry_group : int
        3 bits (2 = agricultural and forestry).
    self_configurable : bool
        Whether the node may claim another address when it loses its own.
    """

    identity: int
    manufacturer: int = 0
    ecu_instance: int = 0
    function_instance: int = 0
    function: int = 0
    vehicle_system: int = 0
    vehicle_system_instance: int = 0
    industry_group: int = 2
    self_configurable: bool = True

    _BITS = (("identity", 0, 21), ("manufacturer", 21, 11), ("ecu_instance", 32, 3), ("function_instance", 35, 5),
             ("function", 40, 8), ("vehicle_system", 49, 7), ("vehicle_system_instance", 56, 4),
             ("industry_group", 60, 3))

    def __post_init__(self) -> None:
        for field, _, width in self._BITS:
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < (1 << width):
                raise IsobusConfigError(f"Name.{field} must be an int in [0, {(1 << width) - 1}], got {value!r}")
        if not isinstance(self.self_configurable, bool):
            raise IsobusConfigError(f"Name.self_configurable must be a bool, got {self.self_configurable!r}")

    @property
    def value(self) -> int:
        """The NAME as a 64-bit integer (bit 47 reserved, 0)."""
        out = int(self.self_configurable) << 63
        for field, shift, _ in self._BITS:
            out |= getattr(self, field) << shift
        return out

    def to_bytes(self) -> bytes:
        """The 8 data bytes of an address claim (little-endian)."""
        return self.value.to_bytes(8, "little")

    @classmethod
    def from_bytes(cls, data: bytes) -> Name:
        """The NAME of an address claim's data bytes.

        Raises
        ------
        FrameError
            Not 8 bytes.
        """
        if len(data) != 8:
            raise FrameError(f"an address claim carries an 8-byte NAME, got {len(data)} bytes")
        v = int.from_bytes(bytes(data), "little")
        values = {field: (v >> shift) & ((1 << width) - 1) for field, shift, width in cls._BITS}
        return cls(self_configurable=bool(v >> 63), **values)


@dataclass(frozen=True)
class CanId:
    """A 29-bit ISO 11783 / J1939 identifier, split.

    Parameters
    ----------
    priority : int
        0 (highest) to 7.
    pgn : int
        Parameter group number (for PDU1 groups, PF < 240, without the destination).
    source : int
        Source address.
    destination : int
        Destination address (PDU1), or 255 for PDU2 groups.
    """

    priority: int
    pgn: int
    source: int
    destination: int = GLOBAL

    def encode(self) -> int:
        """The 29-bit arbitration id."""
        pf = (self.pgn >> 8) & 0xFF
        ps = self.destination if pf < 240 else self.pgn & 0xFF
        return (self.priority << 26) | ((self.pgn & 0x30000) | (pf << 8) | ps) << 8 | self.source

    @classmethod
    def decode(cls, arbitration_id: int) -> CanId:
        """Split a 29-bit arbitration id."""
        pf, ps = (arbitration_id >> 16) & 0xFF, (arbitration_id >> 8) & 0xFF
        page = (arbitration_id >> 8) & 0x30000
        if pf < 240:
            return cls((arbitration_id >> 26) & 7, page | pf << 8, arbitration_id & 0xFF, ps)
        return cls((arbitration_id >> 26) & 7, page | pf << 8 | ps, arbitration_id & 0xFF, GLOBAL)


@dataclass(frozen=True)
class Received:
    """A guidance message (or its refusal) received by a node.

    Parameters
    ----------
    time : float
        Node clock time of the poll that read it, s.
    source : int
        Sender's address.
    pgn : int
        Parameter group number.
    message : Message or FrameError
        The decoded message, or why it was refused.
    """

    time: float
    source: int
    pgn: int
    message: Message | FrameError


class Node:
    """One ISO 11783 control function on a CAN bus.

    Parameters
    ----------
    bus : can.BusABC
        The bus (owned by the caller, who shuts it down).
    name : Name
        This node's NAME.
    address : int
        Preferred source address (0-253).
    clock : Clock
        Time source.
    address_range : tuple of int, optional
        Addresses a self-configurable node tries after losing its own, in order (default
        128-247, the self-configurable range of J1939).
    on_lost : callable, optional
        Called with no argument when the node loses its address (the driver disengages).
    """

    def __init__(self, bus: can.BusABC, name: Name, address: int, clock: Clock,
                 address_range: tuple[int, int] = (128, 247), on_lost: Callable[[], None] | None = None) -> None:
        if isinstance(address, bool) or not isinstance(address, int) or not 0 <= address <= 253:
            raise IsobusConfigError(f"node address must be an int in [0, 253], got {address!r}")
        lo, hi = address_range
        if not 0 <= lo <= hi <= 253:
            raise IsobusConfigError(f"address_range must satisfy 0 <= low <= high <= 253, got {address_range!r}")
        self.bus = bus
        self.name = name
        self.clock = clock
        self.address: int | None = address
        self._range = (lo, hi)
        self.on_lost = on_lost
        """Called with no argument when the node loses its address (settable)."""
        self._claimed_at = math.inf     # time of our last claim; the address is usable CLAIM_WAIT later
        self._silent = False            # lost and cannot claim: sends nothing but Cannot Claim Address
        self._tried: set[int] = set()
        self.conflicts = 0
        """Address claims for our address received from another NAME."""
        self.refused = 0
        """Guidance frames refused (malformed) since the start."""

    # -- state --------------------------------------------------------------------------
    @property
    def claimed(self) -> bool:
        """Whether the node holds its address and may send guidance messages now."""
        return (not self._silent and self.address is not None
                and self.clock.now() >= self._claimed_at + CLAIM_WAIT)

    @property
    def claiming(self) -> bool:
        """Whether a claim has been sent for the current address (it may still be in its 250 ms)."""
        return not self._silent and self.address is not None and self._claimed_at < math.inf

    @property
    def silent(self) -> bool:
        """Whether the node lost its address and found no other (it sends no guidance)."""
        return self._silent

    # -- sending ------------------------------------------------------------------------
    def _send(self, can_id: CanId, data: bytes) -> None:
        try:
            self.bus.send(can.Message(arbitration_id=can_id.encode(), data=data, is_extended_id=True))
        except can.CanError as exc:
            raise IsobusLinkError(f"CAN bus {self.bus.channel_info!r}: sending PGN 0x{can_id.pgn:04X} failed "
                                  f"({exc}); check the interface is up") from exc

    def claim(self) -> None:
        """Send the address claim for the current address (call once at start; a node that lost its
        address and found no other sends Cannot Claim Address from 254 instead)."""
        if self._silent or self.address is None:
            self._send(CanId(6, PGN_ADDRESS_CLAIMED, NULL_ADDRESS), self.name.to_bytes())
            return
        self._tried.add(self.address)
        self._send(CanId(6, PGN_ADDRESS_CLAIMED, self.address), self.name.to_bytes())
        self._claimed_at = self.clock.now()

    def request_claims(self) -> None:
        """Ask every node for its address claim (Request for PGN 60928 to the global address)."""
        source = self.address if self.address is not None and not self._silent else NULL_ADDRESS
        self._send(CanId(6, PGN_REQUEST, source), PGN_ADDRESS_CLAIMED.to_bytes(3, "little"))

    def send(self, message: Message, destination: int = GLOBAL) -> None:
        """Send a guidance message (priority 3) to ``destination``.

        Raises
        ------
        AddressClaimError
            The address is not (yet, or no longer) claimed.
        EncodeError
            The message cannot be encoded.
        """
        if not self.claimed:
            state = "lost and no address is free" if self._silent else (
                f"claimed at {self._claimed_at:.3f} s, usable {CLAIM_WAIT} s later" if self._claimed_at < math.inf
                else "not claimed; call claim() first")
            raise AddressClaimError(f"node {self.name.value:#018x} cannot send at {self.clock.now():.3f} s: "
                                    f"address {state}")
        pgn, data = encode(message)
        self._send(CanId(PRIORITY, pgn, self.address, destination), data)  # type: ignore[arg-type]

    # -- receiving ----------------------------------------------------------------------
    def poll(self) -> list[Received]:
        """Read what is waiting (at most :data:`MAX_FRAMES_PER_POLL` frames): handle network
        management, return the guidance messages addressed to this node or to all."""
        out: list[Received] = []
        now = self.clock.now()
        for _ in range(MAX_FRAMES_PER_POLL):
            try:
                frame = self.bus.recv(0.0)
            except can.CanError as exc:
                raise IsobusLinkError(f"CAN bus {self.bus.channel_info!r}: receiving failed ({exc}); check the "
                                      "interface is up") from exc
            if frame is None:
                break
            if not frame.is_extended_id or frame.is_remote_frame or frame.is_error_frame:
                continue
            cid = CanId.decode(frame.arbitration_id)
            data = bytes(frame.data)
            if cid.pgn == PGN_ADDRESS_CLAIMED:
                self._on_claim(cid.source, data)
            elif cid.pgn == PGN_REQUEST:
                if data[:3] == PGN_ADDRESS_CLAIMED.to_bytes(3, "little") and cid.destination in (GLOBAL, self.address):
                    self.claim()            # silent: Cannot Claim Address from 254
            elif cid.pgn in CLASSES and cid.source != self.address and cid.destination in (GLOBAL, self.address):
                try:
                    message: Message | FrameError = decode(cid.pgn, data)
                except FrameError as exc:
                    message = exc
                    self.refused += 1
                out.append(Received(now, cid.source, cid.pgn, message))
        return out

    def _on_claim(self, source: int, data: bytes) -> None:
        if source != self.address or self._silent:
            return
        try:
            other = Name.from_bytes(data)
        except FrameError:
            return
        if other.value == self.name.value:
            return                                          # our own claim looped back (UDP multicast)
        self.conflicts += 1
        if self.name.value < other.value:
            self.claim()                                    # we win: say so again
            return
        self._lose()

    def _lose(self) -> None:
        self.address = None
        self._claimed_at = math.inf
        if self.on_lost is not None:
            self.on_lost()
        if self.name.self_configurable:
            lo, hi = self._range
            free = [a for a in range(lo, hi + 1) if a not in self._tried]
            if free:
                self.address = free[0]
                self.claim()
                return
        self._silent = True
        self._send(CanId(6, PGN_ADDRESS_CLAIMED, NULL_ADDRESS), self.name.to_bytes())


def open_bus(spec: str) -> can.BusABC:
    """A python-can bus from a specification ``isobus:INTERFACE:CHANNEL``.

    ``isobus:socketcan:can0`` (a real adapter or ``vcan``), ``isobus:virtual:NAME`` (in-process,
    lockstep tests), ``isobus:udp_multicast:239.74.163.2`` (between processes on one host).

    Raises
    ------
    IsobusConfigError
        A malformed specification or an interface not in that list.
    IsobusLinkError
        The interface cannot be opened.
    """
    parts = spec.split(":", 2)
    if len(parts) != 3 or parts[0] != "isobus" or not parts[2]:
        raise IsobusConfigError(f"bus specification {spec!r}: expected isobus:INTERFACE:CHANNEL, e.g. "
                                "isobus:socketcan:can0")
    _, interface, channel = parts
    if interface not in ("socketcan", "virtual", "udp_multicast"):
        raise IsobusConfigError(f"bus specification {spec!r}: interface must be socketcan, virtual or "
                                f"udp_multicast, got {interface!r}")
    try:
        return can.Bus(interface=interface, channel=channel)
    except (can.CanError, OSError, ImportError) as exc:
        raise IsobusLinkError(f"bus specification {spec!r}: cannot open {interface} channel {channel!r} ({exc}); "
                              "check the interface exists and is up (ip link)") from exc
