"""NMEA 0183 byte streams cut into sentences (:class:`NmeaStream`, :func:`split_sentences`):
linear time, bounded memory, garbage and over-long lines dropped and counted. The sentences
themselves are decoded by :mod:`hardware_io.codecs.nmea`."""

from __future__ import annotations

import re

__all__ = ["MAX_SENTENCE_LEN", "NmeaStream", "split_sentences"]

#: The splitter drops sentences longer than this (``$`` to before the line end). NMEA 0183 allows
#: 82 characters including ``\r\n``; high-precision receivers exceed it a little.
MAX_SENTENCE_LEN = 120


_START = re.compile(rb"[$!]")
_END = re.compile(rb"[\r\n]")


def split_sentences(buffer: bytes, max_len: int = MAX_SENTENCE_LEN) -> tuple[list[bytes], bytes]:
    """Cuts complete sentences out of ``buffer``.

    Returns ``(sentences, rest)``: each sentence runs from ``$``/``!`` up to (excluding) the line
    end (``\\r\\n``, ``\\n`` or ``\\r``); ``rest`` is the unfinished tail to prepend to the next
    read. Bytes before a start character are garbage and dropped (resynchronisation); a sentence
    interrupted by a new start character is dropped (truncated); lines longer than ``max_len``
    are dropped, as is an unfinished tail already longer than that. Sentences are not checked
    here -- :func:`decode` verifies them. The result does not depend on how the stream was cut
    into reads.

    Linear time in ``len(buffer)``: each line end is searched for once, not once per start
    character, so a buffer of nothing but ``$`` costs no more than one of valid sentences.
    """
    out, rest, _, _ = _split(bytes(buffer), max_len)
    return out, rest


def _split(buffer: bytes, max_len: int) -> tuple[list[bytes], bytes, int, int]:
    """:func:`split_sentences` plus the number of bytes dropped (anything but line ends outside
    the returned sentences and the kept tail) and of over-long lines / tails dropped."""
    out: list[bytes] = []
    kept = overlong = 0
    pos = 0
    n_buf = len(buffer)
    e_cached: int | None = -1  # first line end after the last search; None: no line end left
    while True:
        m = _START.search(buffer, pos)
        if m is None:
            tail = b""
            break
        start = m.start()
        if e_cached is not None and e_cached <= start:
            em = _END.search(buffer, start + 1)
            e_cached = em.start() if em else None
        e = e_cached  # the first line end after start (each line end is found only once)
        nm = _START.search(buffer, start + 1, n_buf if e is None else e)
        if nm is not None:  # truncated: another sentence starts before this one ends
            pos = nm.start()
            continue
        if e is None:
            tail = buffer[start:]
            if len(tail) > max_len:
                tail = b""
                overlong += 1
            break
        if e - start <= max_len:
            out.append(buffer[start:e])
            kept += e - start
        else:
            overlong += 1
        pos = e + 1
    line_ends = buffer.count(b"\r") + buffer.count(b"\n")
    return out, tail, n_buf - kept - len(tail) - line_ends, overlong


class NmeaStream:
    """Incremental splitter: ``feed(chunk)`` returns the sentences completed by that chunk.

    Linear time, and at most ``max_len`` bytes kept between reads, whatever the input.
    Counters: ``dropped_bytes`` (garbage between sentences, truncated and over-long sentences;
    line ends are not counted) and ``overlong`` (lines longer than ``max_len`` dropped).
    """

    def __init__(self, max_len: int = MAX_SENTENCE_LEN) -> None:
        self.max_len = max_len
        self._rest = b""
        self.dropped_bytes = 0
        self.overlong = 0

    def feed(self, data: bytes) -> list[bytes]:
        sentences, self._rest, dropped, overlong = _split(self._rest + bytes(data), self.max_len)
        self.dropped_bytes += dropped
        self.overlong += overlong
        return sentences

    @property
    def pending(self) -> bytes:
        """The unfinished tail kept for the next read."""
        return self._rest

    def reset(self) -> None:
        self._rest = b""
