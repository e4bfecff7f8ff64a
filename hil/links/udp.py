"""A UDP socket as a byte link (``in_waiting`` / ``read`` / ``write`` / ``fileno``), for AgOpenGPS modules.

Each :meth:`UdpLink.write` sends one datagram to the peer; received datagrams are queued whole and
read as a byte stream (AgOpenGPS frames carry their own length, so the stream decoder finds them).
Datagrams from an address other than the peer are dropped and counted unless the link accepts any
sender (``accept_any=True``, the module's side when AgIO broadcasts). The socket is non-blocking;
nothing here sleeps.

Input is bounded whatever the peer sends: one call takes at most ``MAX_DATAGRAMS_PER_DRAIN``
datagrams from the socket (the kernel's buffer holds, and drops, the rest), and the queue of unread
bytes holds at most ``max_queued`` bytes; when a datagram would overflow it, the oldest queued
datagrams are dropped and counted (``datagrams_dropped``, ``bytes_dropped``). A flood costs data,
never an exception or an unbounded wait.

On the bench both ends are on loopback (127.0.0.1) with ports chosen by the system (port 0); on a
tractor the host binds port 9999 and sends to the module at 192.168.5.126:8888.
"""

from __future__ import annotations

import ipaddress
import socket
from collections import deque
from types import TracebackType

from autosteer.checks import finite
from hil.links.errors import LinkClosedError, LinkConfigError

__all__ = ["UdpLink", "udp_loopback_pair", "MAX_DATAGRAM", "MAX_DATAGRAMS_PER_DRAIN", "MAX_QUEUED"]

MAX_DATAGRAM = 2048
"""Largest datagram read, bytes (AgOpenGPS frames are at most 261 bytes)."""
MAX_QUEUED = 1 << 18
"""Default bound of the unread bytes a link holds, bytes (256 KiB: a second of AgOpenGPS traffic many
times over; more means the reader fell behind, and the oldest bytes are the ones to lose)."""
MAX_DATAGRAMS_PER_DRAIN = 256
"""Most datagrams taken from the socket in one call (a bounded cost per call under a flood)."""


def _address(name: str, value: object) -> tuple[str, int]:
    if (not isinstance(value, tuple) or len(value) != 2 or not isinstance(value[0], str)
            or isinstance(value[1], bool) or not isinstance(value[1], int) or not 0 <= value[1] <= 65535):
        raise LinkConfigError(f"{name} must be (IPv4 address, port 0..65535), got {value!r}")
    try:
        ipaddress.IPv4Address(value[0])
    except ValueError:
        raise LinkConfigError(f"{name}: {value[0]!r} is not an IPv4 address (e.g. 127.0.0.1 or 192.168.5.126)") from None
    return value[0], value[1]


class UdpLink:
    """One UDP endpoint talking to one peer.

    Parameters
    ----------
    local : (str, int)
        Address and port to bind (port 0: chosen by the system, see :attr:`local_address`).
    peer : (str, int) or None
        Where :meth:`write` sends; None until :meth:`connect_to` (or learnt from the first
        datagram when ``accept_any``).
    accept_any : bool, optional
        Accept datagrams from any sender (default False: only from ``peer``).
    broadcast : bool, optional
        Allow sending to a broadcast address (AgIO's 192.168.5.255).
    max_queued : int, optional
        Most unread bytes held, bytes (default :data:`MAX_QUEUED`); older datagrams are dropped for newer.

    Raises
    ------
    LinkConfigError
        A malformed address.
    OSError
        The socket cannot be bound (port in use, address not on this machine).
    """

    def __init__(self, local: tuple[str, int], peer: tuple[str, int] | None = None, accept_any: bool = False,
                 broadcast: bool = False, max_queued: int = MAX_QUEUED) -> None:
        local = _address("local", local)
        finite(max_queued, "max_queued", lo=MAX_DATAGRAM, integer=True, unit="bytes", error=LinkConfigError,
               fix="at least one datagram")
        self.max_queued = max_queued
        self.peer = None if peer is None else _address("peer", peer)
        self.accept_any = bool(accept_any)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            if broadcast:
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
            self._sock.bind(local)
            self._sock.setblocking(False)
        except BaseException:
            self._sock.close()
            raise
        self._rx: deque[bytes] = deque()
        self._queued = 0
        self._closed = False
        self.datagrams_sent = 0
        self.datagrams_received = 0
        self.foreign_datagrams = 0
        self.datagrams_dropped = 0
        self.bytes_dropped = 0

    @property
    def local_address(self) -> tuple[str, int]:
        """The bound address and port."""
        host, port = self._sock.getsockname()[:2]
        return host, port

    def connect_to(self, peer: tuple[str, int]) -> None:
        """Set the peer that :meth:`write` sends to (and that datagrams must come from)."""
        self.peer = _address("peer", peer)

    def fileno(self) -> int:
        """The socket's descriptor (for ``select``)."""
        return self._sock.fileno()

    def _check_open(self) -> None:
        if self._closed:
            raise LinkClosedError("this UDP link is closed")

    def _drain(self) -> None:
        rx = self._rx
        for _ in range(MAX_DATAGRAMS_PER_DRAIN):   # bounded: the kernel's buffer holds (and drops) the rest
            try:
                data, sender = self._sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except ConnectionRefusedError:   # an ICMP "port unreachable" from an earlier send
                continue
            if self.peer is None and self.accept_any:
                self.peer = (sender[0], sender[1])
            if not self.accept_any and (self.peer is None or sender[:2] != self.peer):
                self.foreign_datagrams += 1
                continue
            while rx and self._queued + len(data) > self.max_queued:   # the reader fell behind: lose the oldest
                old = rx.popleft()
                self._queued -= len(old)
                self.datagrams_dropped += 1
                self.bytes_dropped += len(old)
            rx.append(data)
            self._queued += len(data)
            self.datagrams_received += 1

    @property
    def in_waiting(self) -> int:
        """Bytes received and not yet read."""
        self._check_open()
        self._drain()
        return self._queued

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` received bytes (datagrams concatenated); never waits."""
        self._check_open()
        if isinstance(size, bool) or not isinstance(size, int) or size < 0:
            raise LinkConfigError(f"read size must be a non-negative int, got {size!r}")
        self._drain()
        out = bytearray()
        while self._rx and len(out) < size:
            chunk = self._rx.popleft()
            take = size - len(out)
            if len(chunk) > take:
                self._rx.appendleft(chunk[take:])
                chunk = chunk[:take]
            out += chunk
        self._queued -= len(out)
        return bytes(out)

    def write(self, data: bytes) -> int:
        """Send ``data`` as one datagram to the peer; returns ``len(data)``.

        Raises
        ------
        LinkClosedError
            The link is closed.
        LinkConfigError
            No peer is known yet.
        OSError
            The network refused the datagram.
        """
        self._check_open()
        if self.peer is None:
            raise LinkConfigError("this UDP link has no peer to send to yet (give peer= or connect_to())")
        data = bytes(data)
        self._sock.sendto(data, self.peer)
        self.datagrams_sent += 1
        return len(data)

    def close(self) -> None:
        """Close the socket (idempotent)."""
        if not self._closed:
            self._closed = True
            self._sock.close()

    def __enter__(self) -> UdpLink:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def udp_loopback_pair() -> tuple[UdpLink, UdpLink]:
    """Two UDP links on 127.0.0.1, each the other's peer, on ports chosen by the system.

    Returns
    -------
    (UdpLink, UdpLink)
        The host's end and the module's end.
    """
    host = UdpLink(("127.0.0.1", 0))
    try:
        module = UdpLink(("127.0.0.1", 0), peer=host.local_address)
    except BaseException:
        host.close()
        raise
    host.connect_to(module.local_address)
    return host, module
