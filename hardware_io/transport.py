"""Byte transports for the hardware bridge (I/O lives here; the codecs stay pure).

:class:`SerialTransport` wraps a :class:`serial.Serial` (pyserial) port for polling from a
periodic Drake event: :meth:`~SerialTransport.read` never blocks and returns whatever bytes are
available together with the host time at which they were read. After an unplug (EOF, EIO,
a broken pipe: any ``OSError`` or ``SerialException`` on read or write) the port is closed, one
warning line goes to stderr, and later reads and writes try to reopen it at most every
``reconnect_period`` seconds (reads returning ``b""``, writes dropped meanwhile); a reopening
that succeeds is announced by one more line. Both transports say how their link is with
:class:`LinkCounters`.
"""

from __future__ import annotations

import os
import socket
import sys
import time
from dataclasses import dataclass

import serial

__all__ = ["LinkCounters", "PortNotFoundError", "SerialTransport"]


@dataclass(frozen=True)
class LinkCounters:
    """How a transport's link to its device is: ``connected`` now, ``disconnects`` (times the
    device went away), ``reconnects`` (times it came back)."""

    connected: bool = True
    disconnects: int = 0
    reconnects: int = 0


class PortNotFoundError(OSError):
    """The serial port does not exist (device not plugged in, wrong path)."""

    def __init__(self, port: str):
        super().__init__(f"serial port {port} not found (device not plugged in or wrong path)")
        self.port = port


class SerialTransport:
    """Non-blocking serial port with automatic reconnection.

    ``read() -> (bytes, host_time)``: the available bytes (``b""`` if none or while
    disconnected) and ``time.monotonic()`` right after the read. ``write(data)`` writes all of
    ``data`` (dropped while disconnected, and what a full output buffer does not take).
    Counters: ``errors`` (I/O errors seen), ``disconnects`` (times the port was lost: each
    error closes it, so equal to ``errors``), ``reconnects`` (successful reopenings after an
    error); :attr:`link` has them as :class:`LinkCounters`. ``close()`` is final: the port is
    not reopened after it. A port that does not exist at construction raises
    :class:`PortNotFoundError`.
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
        self._closed = False
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

    @property
    def disconnects(self) -> int:
        return self.errors

    @property
    def link(self) -> LinkCounters:
        return LinkCounters(self.connected, self.disconnects, self.reconnects)

    def _fail(self, error: BaseException) -> None:
        self.errors += 1
        self._last_attempt = time.monotonic()
        if self._serial is not None:
            try:
                self._serial.close()
            except (OSError, serial.SerialException):
                pass
            self._serial = None
        reason = getattr(error, "strerror", None) or str(error) or type(error).__name__
        print(
            f"warning: serial port {self.port} lost ({reason}); "
            f"reopening it every {self.reconnect_period:g} s",
            file=sys.stderr,
            flush=True,
        )

    def _try_reconnect(self) -> bool:
        if self._closed:
            return False
        now = time.monotonic()
        if now - self._last_attempt < self.reconnect_period:
            return False
        self._last_attempt = now
        try:
            self._serial = self._open()
        except (OSError, serial.SerialException):
            return False
        self.reconnects += 1
        print(f"warning: serial port {self.port} back", file=sys.stderr, flush=True)
        return True

    def read(self) -> tuple[bytes, float]:
        if self._serial is None and not self._try_reconnect():
            return b"", time.monotonic()
        try:
            n = self._serial.in_waiting
            data = self._serial.read(n) if n else b""
        except (OSError, serial.SerialException) as e:
            self._fail(e)
            data = b""
        return bytes(data), time.monotonic()

    def write(self, data: bytes) -> None:
        if self._serial is None and not self._try_reconnect():
            return
        try:
            self._serial.write(data)
        except serial.SerialTimeoutException:
            pass  # a full output buffer (device not reading) is not a lost device
        except (OSError, serial.SerialException) as e:
            self._fail(e)

    def close(self) -> None:
        self._closed = True
        if self._serial is not None:
            try:
                self._serial.close()
            except (OSError, serial.SerialException):
                pass  # closing a port whose device has gone
            self._serial = None

    def __enter__(self) -> SerialTransport:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ------------------------------------------------------------------------------------------
# UDP

__all__ += ["UdpTransport"]


class UdpTransport:
    """Non-blocking UDP socket bound to ``(address, port)``, e.g. a Velodyne's data port 2368.

    ``read() -> (list[bytes], host_time)``: every datagram queued (at most ``max_datagrams``
    per call, the rest stay queued) and ``time.monotonic()`` right after the read; ``[]`` if
    none. The receive buffer is enlarged to :attr:`RCVBUF_BYTES` (the kernel caps it at
    ``net.core.rmem_max``) so that a VLP-16's ~754 packets/s (0.9 MB/s) survive a slow
    update. ``port=0`` binds an ephemeral port; :attr:`port` is the one bound. A bind
    failure (address in use, no such interface) raises ``OSError`` with one line naming the
    address and port. Counters: ``datagrams``, ``bytes_read``, ``errors`` (socket errors
    other than "nothing queued" on read; the socket stays open).
    """

    RCVBUF_BYTES = 4 * 1024 * 1024

    def __init__(self, address: str = "0.0.0.0", port: int = 2368, max_datagrams: int = 1000):
        if max_datagrams < 1:
            raise ValueError(f"max_datagrams must be positive, got {max_datagrams}")
        self.address, self.max_datagrams = address, int(max_datagrams)
        self.datagrams = 0
        self.bytes_read = 0
        self.errors = 0
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            try:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, self.RCVBUF_BYTES)
            except OSError:
                pass
            sock.bind((address, port))
        except (OSError, OverflowError) as e:
            sock.close()
            reason = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
            raise OSError(f"cannot bind UDP socket to {address}:{port}: {reason}") from None
        sock.setblocking(False)
        self._sock: socket.socket | None = sock
        self.port = sock.getsockname()[1]

    @property
    def connected(self) -> bool:
        return self._sock is not None

    @property
    def link(self) -> LinkCounters:
        """A bound socket has no link to lose: an unplugged sensor just stops sending, which
        the host watchdog sees as silence; so no disconnects or reconnects to count."""
        return LinkCounters(self.connected)

    def read(self) -> tuple[list[bytes], float]:
        out: list[bytes] = []
        sock = self._sock
        while sock is not None and len(out) < self.max_datagrams:
            try:
                data = sock.recv(65535)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self.errors += 1
                break
            out.append(data)
            self.bytes_read += len(data)
        self.datagrams += len(out)
        return out, time.monotonic()

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> UdpTransport:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
