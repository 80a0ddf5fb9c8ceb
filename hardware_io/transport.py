"""Byte transports for the hardware bridge (I/O lives here; the codecs stay pure).

:class:`SerialTransport` wraps a :class:`serial.Serial` (pyserial) port for polling from a
periodic Drake event: :meth:`~SerialTransport.read` never blocks and returns whatever bytes are
available together with the host time at which they were read. After an unplug (an ``OSError``
or ``SerialException`` on read or write) the port is closed and later reads try to reopen it at
most every ``reconnect_period`` seconds, returning ``b""`` meanwhile.
"""

from __future__ import annotations

import os
import time

import serial

__all__ = ["PortNotFoundError", "SerialTransport"]


class PortNotFoundError(OSError):
    """The serial port does not exist (device not plugged in, wrong path)."""

    def __init__(self, port: str):
        super().__init__(f"serial port {port} not found (is the GPS plugged in?)")
        self.port = port


class SerialTransport:
    """Non-blocking serial port with automatic reconnection.

    ``read() -> (bytes, host_time)``: the available bytes (``b""`` if none or while
    disconnected) and ``time.monotonic()`` right after the read. ``write(data)`` writes all of
    ``data`` (dropped while disconnected). Counters: ``errors`` (I/O errors seen),
    ``reconnects`` (successful reopenings after an error). A port that does not exist at
    construction raises :class:`PortNotFoundError`.
    """

    def __init__(
        self,
        port: str,
        baudrate: int = 9600,
        timeout: float = 0,
        reconnect_period: float = 1.0,
    ):
        self.port, self.baudrate, self.timeout = port, baudrate, timeout
        self.reconnect_period = reconnect_period
        self.errors = 0
        self.reconnects = 0
        self._last_attempt = -float("inf")
        if not os.path.exists(port):
            raise PortNotFoundError(port)
        try:
            self._serial: serial.Serial | None = self._open()
        except (OSError, serial.SerialException) as e:
            if not os.path.exists(port):
                raise PortNotFoundError(port) from None
            raise OSError(f"serial port {port} cannot be opened: {e}") from None

    def _open(self) -> serial.Serial:
        return serial.Serial(
            self.port, self.baudrate, timeout=self.timeout, write_timeout=self.timeout
        )

    @property
    def connected(self) -> bool:
        return self._serial is not None

    def _fail(self) -> None:
        self.errors += 1
        self._last_attempt = time.monotonic()
        if self._serial is not None:
            try:
                self._serial.close()
            except (OSError, serial.SerialException):
                pass
            self._serial = None

    def _try_reconnect(self) -> bool:
        now = time.monotonic()
        if now - self._last_attempt < self.reconnect_period:
            return False
        self._last_attempt = now
        try:
            self._serial = self._open()
        except (OSError, serial.SerialException):
            return False
        self.reconnects += 1
        return True

    def read(self) -> tuple[bytes, float]:
        if self._serial is None and not self._try_reconnect():
            return b"", time.monotonic()
        try:
            n = self._serial.in_waiting
            data = self._serial.read(n) if n else b""
        except (OSError, serial.SerialException):
            self._fail()
            data = b""
        return bytes(data), time.monotonic()

    def write(self, data: bytes) -> None:
        if self._serial is None and not self._try_reconnect():
            return
        try:
            self._serial.write(data)
        except (OSError, serial.SerialException):
            self._fail()

    def close(self) -> None:
        if self._serial is not None:
            self._serial.close()
            self._serial = None

    def __enter__(self) -> SerialTransport:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
