"""Byte transport for the link: pyserial by device path or URL, chunked non-blocking reads.

``open_serial("/dev/ttyACM0" | "loop://" | "socket://host:port" | "spy:///dev/ttyACM0")``.
Reads never use ``read_until`` (which reads byte by byte): :meth:`SerialTransport.read_chunk`
returns whatever is waiting, or waits at most ``timeout`` for the first byte.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import serial
from serial.tools import list_ports as _list_ports


class TransportError(IOError):
    """The port could not be opened, or failed while in use."""


class Transport(Protocol):
    """What the link needs from a byte pipe."""

    def read_chunk(self, timeout: float = 0.0) -> bytes:
        """Bytes available now (waiting up to ``timeout`` s for the first one); b'' if none."""
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
    """A pyserial port opened exclusively where the platform supports it (POSIX flock)."""

    def __init__(self, url: str, baud: int, write_timeout: float = 0.05):
        kwargs = dict(baudrate=baud or 115200, timeout=0, write_timeout=write_timeout)
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

    def read_chunk(self, timeout: float = 0.0) -> bytes:
        try:
            n = self._ser.in_waiting
            if n:
                return self._ser.read(n)
            if timeout <= 0:
                return b""
            self._ser.timeout = timeout
            try:
                first = self._ser.read(1)
            finally:
                self._ser.timeout = 0
            if not first:
                return b""
            n = self._ser.in_waiting
            return first + (self._ser.read(n) if n else b"")
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"read from {self.url!r} failed: {exc}") from None

    def write(self, data: bytes) -> None:
        try:
            self._ser.write(data)
        except (serial.SerialException, serial.SerialTimeoutException, OSError) as exc:
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
