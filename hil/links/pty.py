"""Pseudo-terminal pairs: a real serial device node for host code, a raw fd for the emulator.

The host side is the slave device (``/dev/pts/N``), opened with pyserial exactly
like a USB-serial adapter, so the host driver runs its real-port code path. The
emulated device holds the master side as a raw non-blocking file descriptor
(:class:`FdLink`). A pseudo-terminal passes bytes as fast as they come and
ignores the baud rate: line timing is the emulated device's job.
"""

from __future__ import annotations

import errno
import fcntl
import os
import select
import struct
import termios
import tty
from types import TracebackType

import serial

from hil.links.errors import LinkClosedError, LinkConfigError

__all__ = ["FdLink", "PtyPair"]


class FdLink:
    """A raw, non-blocking file descriptor with the :class:`~hil.links.link.ByteLink` interface.

    Parameters
    ----------
    fd : int
        Open file descriptor (a pty master or slave).
    name : str, optional
        Used in error messages.
    write_timeout : float, optional
        Longest wait for the kernel buffer to accept a write, s (default 1).
    """

    def __init__(self, fd: int, name: str = "fd", write_timeout: float = 1.0) -> None:
        self._fd = fd
        self.name = name
        self.write_timeout = write_timeout
        os.set_blocking(fd, False)

    def fileno(self) -> int:
        """The file descriptor (for ``select``)."""
        if self._fd < 0:
            raise LinkClosedError(f"{self.name}: link is closed")
        return self._fd

    @property
    def in_waiting(self) -> int:
        """Bytes readable now (``FIONREAD``)."""
        buf = fcntl.ioctl(self.fileno(), termios.FIONREAD, b"\0\0\0\0")
        return struct.unpack("i", buf)[0]

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes without waiting (b"" when none).

        Raises
        ------
        LinkClosedError
            The other side of the pseudo-terminal is gone (EIO) or this link is closed.
        """
        if size <= 0:
            return b""
        try:
            return os.read(self.fileno(), size)
        except BlockingIOError:
            return b""
        except OSError as err:
            if err.errno == errno.EIO:
                raise LinkClosedError(f"{self.name}: the other end of the pseudo-terminal is closed") from err
            raise

    def write(self, data: bytes) -> int:
        """Write all of ``data``, waiting (bounded by ``write_timeout``) while the kernel buffer is full.

        Raises
        ------
        TimeoutError
            The buffer stayed full for ``write_timeout`` seconds.
        """
        view = memoryview(bytes(data))
        done = 0
        # Each pass writes >= 1 byte or waits up to write_timeout once; bounded by len(data)+1 passes.
        for _ in range(len(view) + 1):
            if done >= len(view):
                break
            try:
                done += os.write(self.fileno(), view[done:])
            except BlockingIOError:
                _, writable, _ = select.select([], [self._fd], [], self.write_timeout)
                if not writable:
                    raise TimeoutError(f"{self.name}: could not write for {self.write_timeout} s "
                                       "(nobody reads the other side?)") from None
        return done

    def close(self) -> None:
        """Close the descriptor (idempotent)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


class PtyPair:
    """A pseudo-terminal pair in raw mode.

    Use as a context manager; :meth:`close` closes every side it opened.

    Attributes
    ----------
    slave_name : str
        Device path of the host side, e.g. ``/dev/pts/3``.
    """

    def __init__(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no CR/LF translation, no signals: 8-bit clean
        self._master = master
        self._slave = slave  # kept open so that the master never sees EIO before the host opens
        self.slave_name = os.ttyname(slave)
        self._device: FdLink | None = None
        self._serials: list[serial.Serial] = []

    def device_link(self) -> FdLink:
        """The emulated device's end (the pty master), created once."""
        if self._device is None:
            self._device = FdLink(self._master, name=f"pty master of {self.slave_name}")
        return self._device

    def open_serial(self, baudrate: int = 9600, **options: object) -> serial.Serial:
        """Open the host's end with pyserial, as a real port would be (non-blocking reads).

        Parameters
        ----------
        baudrate : int, optional
            Set on the port like on a real one; a pseudo-terminal ignores it.
        **options
            Further ``serial.Serial`` keyword arguments (``timeout`` defaults to 0).
        """
        if "port" in options:
            raise LinkConfigError("open_serial() opens this pair's own slave; do not pass port=")
        options.setdefault("timeout", 0)
        port = serial.Serial(self.slave_name, baudrate=baudrate, **options)  # type: ignore[arg-type]
        self._serials.append(port)
        return port

    def hang_up_host_side(self) -> None:
        """Close every holder of the host's end (this pair's pyserial ports and its kept slave fd),
        as when a host program exits or a USB adapter is unplugged; the device side then reads EOF."""
        for port in self._serials:
            port.close()
        self._serials.clear()
        if self._slave >= 0:
            os.close(self._slave)
            self._slave = -1

    def close(self) -> None:
        """Close the pyserial ports, the slave and the master (idempotent)."""
        self.hang_up_host_side()
        if self._device is not None:
            self._device.close()
        elif self._master >= 0:
            os.close(self._master)
        self._master = -1

    def __enter__(self) -> PtyPair:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
