"""Byte transport for the link: pyserial by device path or URL, chunked non-blocking reads.

``open_serial("/dev/ttyACM0" | "loop://" | "socket://host:port" | "spy:///dev/ttyACM0")``.
Reads never use ``read_until`` (which reads byte by byte): :meth:`SerialTransport.read_chunk`
returns whatever is waiting, or waits at most ``timeout`` for the first byte.
"""

from __future__ import annotations

import dataclasses
import os
import select
import time
from typing import Protocol

import serial
from serial.tools import list_ports as _list_ports


class TransportError(IOError):
    """The port could not be opened, or failed while in use."""


class Transport(Protocol):
    """What the link needs from a byte pipe."""

    def read_chunk(self) -> bytes:
        """Bytes available now, else wait a short time (a few ms) for the first; b'' if none."""
        ...

    def write(self, data: bytes) -> None:
        """Send ``data``; raises TransportError on failure."""
        ...

    def reset_input(self) -> None:
        """Discard received but unread bytes."""
        ...

    def close(self) -> None:
        """Release the port (idempotent)."""
        ...


class SerialTransport:
    """A pyserial port opened exclusively where the platform supports it (POSIX flock).

    ``read_chunk`` is ``read(in_waiting or 1)`` with a fixed ``read_timeout``; ``write`` times
    out only when bytes are really stuck (see :meth:`write`).
    """

    def __init__(self, url: str, baud: int, read_timeout: float = 0.005,
                 write_timeout: float = 0.05):
        kwargs = dict(baudrate=baud or 115200, timeout=read_timeout, write_timeout=write_timeout)
        try:
            try:
                self._ser = serial.serial_for_url(url, exclusive=True, **kwargs)
            except (TypeError, ValueError) as exc:
                if "exclusive" not in str(exc):
                    raise
                self._ser = serial.serial_for_url(url, **kwargs)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise TransportError(f"cannot open {url!r}: {exc}") from None
        self.url = url
        self.write_timeout = write_timeout
        self._fd: int | None = None
        fileno = getattr(self._ser, "fileno", None)
        try:
            self._fd = fileno() if fileno is not None else None
        except (serial.SerialException, OSError, AttributeError, NotImplementedError):
            self._fd = None  # URL handlers (loop://, socket://) have no descriptor to write to
        if self._fd is not None:
            os.set_blocking(self._fd, False)  # pyserial opens it O_NONBLOCK already

    def read_chunk(self) -> bytes:
        try:
            return self._ser.read(self._ser.in_waiting or 1)
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"read from {self.url!r} failed: {exc}") from None

    def write(self, data: bytes) -> None:
        """Write ``data``; fails only if bytes cannot leave within ``write_timeout``.

        pyserial's ``write`` checks its deadline after every ``os.write``, also after one that
        wrote the whole frame: a thread that waited longer than the timeout for the GIL (the
        console process runs viser, the render thread and a loop) then gets "Write timeout"
        for a frame that went out, and the link is dropped (measured: the extensible console
        lost its link within seconds of GUI activity). Here the port's non-blocking descriptor
        is written directly and ``select`` waits only while bytes remain.
        """
        if self._fd is None:  # URL handlers without a file descriptor: pyserial's own write
            try:
                self._ser.write(data)
            except (serial.SerialException, serial.SerialTimeoutException, OSError) as exc:
                raise TransportError(f"write to {self.url!r} failed: {exc}") from None
            return
        rest = memoryview(bytes(data))
        deadline = time.monotonic() + self.write_timeout
        try:
            while rest:
                try:
                    n = os.write(self._fd, rest)
                except BlockingIOError:
                    n = 0
                rest = rest[n:]
                if not rest:
                    return
                remaining = deadline - time.monotonic()
                if remaining <= 0 or not select.select([], [self._fd], [], remaining)[1]:
                    raise TransportError(f"write to {self.url!r} failed: {len(rest)} bytes "
                                         f"stuck for {self.write_timeout * 1000:.0f} ms")
        except TransportError:
            raise
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"write to {self.url!r} failed: {exc}") from None


    def reset_input(self) -> None:
        try:
            self._ser.reset_input_buffer()
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"reset of {self.url!r} failed: {exc}") from None

    def close(self) -> None:
        try:
            self._ser.close()
        except (serial.SerialException, OSError):
            pass


def open_serial(url: str, baud: int) -> SerialTransport:
    """Open ``url`` (device path or pyserial URL); raises TransportError with the reason."""
    return SerialTransport(url, baud)


@dataclasses.dataclass(frozen=True)
class PortInfo:
    """A serial port the UI can offer."""

    device: str
    description: str


def list_ports() -> list[PortInfo]:
    """Serial ports present on this machine (the UI adds free text for pty paths and URLs)."""
    return [PortInfo(p.device, p.description or "") for p in sorted(_list_ports.comports())]
