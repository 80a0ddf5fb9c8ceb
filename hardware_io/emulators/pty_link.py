"""Pseudo-terminal "wires" for device emulators and tests.

A :class:`PtyDevice` is the device end of a pseudo-terminal: the host opens :attr:`path` as if it
were a USB-serial adapter (``/dev/pts/N``) with :class:`hardware_io.transport.SerialTransport`,
and the emulator reads and writes the master end through :meth:`read` / :meth:`write`, which
never block. The slave end is put in raw mode so the line discipline passes bytes unchanged
(no echo, no CR/LF translation) exactly as a real UART does. Given a ``link`` path, :attr:`path`
is instead a symlink to the pseudo-terminal, as udev's ``/dev/serial/by-id`` names are: then
:meth:`PtyDevice.unplug` makes the device disappear (the host reads EIO, the name is gone) and
:meth:`PtyDevice.replug` brings it back under the same name, on a new pseudo-terminal.

:class:`WireFaults` models a bad cable on the emulator side: each byte crossing the wire in
either direction is replaced by a random byte with probability ``corruption``, and after
:meth:`WireFaults.cut` nothing crosses at all.
"""

from __future__ import annotations

import errno
import os
import time
import tty

import numpy as np

__all__ = ["PtyDevice", "WireFaults", "corrupt_bytes"]


def corrupt_bytes(data: bytes, probability: float, rng: np.random.Generator) -> bytes:
    """``data`` with each byte replaced, with ``probability``, by a uniformly random *different*
    byte (so every selected byte really changes)."""
    if probability <= 0.0 or not data:
        return data
    buf = np.frombuffer(data, np.uint8).copy()
    hit = rng.random(len(buf)) < probability
    if hit.any():
        buf[hit] ^= rng.integers(1, 256, int(hit.sum()), dtype=np.uint8)
    return buf.tobytes()


class WireFaults:
    """Corruption and cutting of the bytes on one serial wire (both directions).

    ``corruption``: probability that a byte is replaced (0.01 = 1 % of bytes). ``cut()``: from
    then on every byte is dropped; :attr:`cut_time` is the ``time.monotonic()`` of the cut.
    """

    def __init__(self, corruption: float = 0.0, seed: int = 0):
        if not 0.0 <= corruption < 1.0:
            raise ValueError(f"corruption must be in [0, 1), got {corruption}")
        self.corruption = corruption
        self.rng = np.random.default_rng(seed)
        self.cut_time: float | None = None
        self.bytes_corrupted = 0

    def cut(self) -> None:
        if self.cut_time is None:
            self.cut_time = time.monotonic()

    @property
    def is_cut(self) -> bool:
        return self.cut_time is not None

    def apply(self, data: bytes) -> bytes:
        if self.cut_time is not None:
            return b""
        out = corrupt_bytes(data, self.corruption, self.rng)
        if out is not data:
            self.bytes_corrupted += sum(a != b for a, b in zip(out, data, strict=True))
        return out


class PtyDevice:
    """The device end of a new pseudo-terminal; the host opens :attr:`path`.

    ``read()`` returns the bytes the host wrote (``b""`` if none), ``write(data)`` sends bytes
    to the host; both are non-blocking and pass through ``faults`` when given. Bytes written
    while no host has the port open, or while unplugged, are discarded like a UART's with
    nothing attached. ``close()`` releases both ends (the host then sees the device unplugged)
    and removes the link. With ``link``, :attr:`path` is that symlink and ``unplug()`` /
    ``replug()`` take the device away and bring it back (:attr:`plugged`; ``unplugs`` counts
    them); without it, :attr:`path` is the pseudo-terminal itself.
    """

    def __init__(self, faults: WireFaults | None = None, link: str | os.PathLike | None = None):
        self.faults = faults
        self.bytes_in = 0
        self.bytes_out = 0
        self.unplugs = 0
        self._link = None if link is None else os.fspath(link)
        self._master = self._slave = None
        self._open()
        self.path = self._link if self._link is not None else os.ttyname(self._slave)

    def _open(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        if self._link is not None:  # a new name in place of the old one, atomically
            tmp = f"{self._link}.new"
            os.symlink(os.ttyname(self._slave), tmp)
            os.replace(tmp, self._link)

    @property
    def plugged(self) -> bool:
        return self._master is not None

    def unplug(self) -> None:
        """The device goes away: both ends closed, the link removed."""
        if self.plugged:
            self.unplugs += 1
        self.close()

    def replug(self) -> None:
        """The device comes back on a new pseudo-terminal under the same :attr:`path` (only with
        a ``link``: a bare ``/dev/pts/N`` cannot be made again)."""
        if self._link is None:
            raise ValueError("replug needs a PtyDevice made with a link path")
        if not self.plugged:
            self._open()

    def read(self, max_bytes: int = 65536) -> bytes:
        if self._master is None:
            return b""
        try:
            data = os.read(self._master, max_bytes)
        except BlockingIOError:
            return b""
        except OSError as e:  # EIO: no host has the slave open
            if e.errno == errno.EIO:
                return b""
            raise
        self.bytes_in += len(data)
        return self.faults.apply(data) if self.faults is not None else data

    def write(self, data: bytes) -> int:
        """Queue ``data`` to the host; returns the number of bytes the kernel accepted (bytes
        that do not fit in the pty buffer are dropped, as a UART without flow control would)."""
        if self._master is None or not data:
            return 0
        if self.faults is not None:
            data = self.faults.apply(data)
            if not data:
                return 0
        try:
            n = os.write(self._master, data)
        except (BlockingIOError, OSError):
            return 0
        self.bytes_out += n
        return n

    def close(self) -> None:
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        if self._link is not None:
            try:
                os.unlink(self._link)
            except FileNotFoundError:
                pass

    def __enter__(self) -> PtyDevice:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
