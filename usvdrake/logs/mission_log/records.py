"""The records of an MCAP file read so that damage is skipped and counted, not raised.

An MCAP file is the magic, then records ``opcode (u8) length (u64 LE) content``, then (when
the writer was closed) a footer and the magic again. :func:`iter_records` walks the records
itself rather than with ``mcap``'s StreamReader, which raises at the first bad byte (and so
gives up on the rest of the file) or, for a record length past the end of the file, either
raises or stops quietly:

* a record whose content does not parse (a bit flip in a string length, a message too short
  for its header) is skipped when its framing still holds: the bytes after it begin a
  plausible record;
* a record whose framing does not hold (an unknown opcode, a length past the end of the file,
  content that does not parse followed by bytes that cannot begin a record) starts a damaged
  region: the reader scans forward for the next offset where a record parses *and* is
  followed by a plausible one, and goes on from there. Found: the region is one skipped record
  of that many bytes. Not found: the rest of the file could not be read, counted as one
  skipped record of that many bytes — a writer killed mid-record leaves exactly that at the
  end (one incomplete record); a corrupt length in the middle is found again after it;
* chunks (other writers' files; ours are unchunked) are opened when their compression is
  available and their declared size is sane, else skipped.

Every skip goes into a :class:`~usvdrake.logs.damage.ReadDamage` keyed by its byte offset.
A file that does not begin with the MCAP magic is refused (:class:`ConfigError`).
"""

import io
import mmap
import re
import struct
from collections.abc import Iterator
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Footer, Message, Schema
from mcap.stream_reader import breakup_chunk

from usvdrake.errors import ConfigError
from usvdrake.logs.damage import ReadDamage

MAGIC = b"\x89MCAP0\r\n"
_HEAD = struct.Struct("<BQ")
_OPCODES = frozenset(int(op) for op in Opcode)
_MESSAGE_HEAD = 22  # [bytes] channel id, sequence, log time, publish time
_PLAUSIBLE_LENGTH = 1 << 32  # a record of 4 GiB or more is a corrupt length, not a record
_MAX_CHUNK = 1 << 29  # [bytes] a chunk claiming to unpack to more is corrupt (writers: ~MB)
# where a record may begin: a known opcode, then a length < 4 GiB (its high 4 bytes zero);
# a lookahead, so that overlapping candidates are all found
_CANDIDATE = re.compile(rb"(?=[\x01-\x0f][\x00-\xff]{4}\x00\x00\x00\x00)")
# what the content of a record may raise when its bytes are corrupt
PARSE_ERRORS = (EndOfFile, McapError, struct.error, ValueError, KeyError, MemoryError)
_CORRUPT = object()  # a record skipped for its content, its framing intact


def _parse(op: int, content: bytes):
    """The record of ``op`` with ``content``; None for kinds the readers do not use."""
    stream = ReadDataStream(io.BytesIO(content))
    if op == Opcode.MESSAGE:
        if len(content) < _MESSAGE_HEAD:
            raise ValueError(f"message record of {len(content)} bytes")
        return Message.read(stream, len(content))
    if op == Opcode.CHANNEL:
        return Channel.read(stream)
    if op == Opcode.SCHEMA:
        return Schema.read(stream)
    if op == Opcode.FOOTER:
        return Footer.read(stream)
    if op == Opcode.CHUNK:
        return Chunk.read(stream)
    return None


def _plausible_head(buf, q: int, size: int) -> bool:
    """Whether a record may begin at ``q``: the end of the file, or a known opcode with a
    length below 4 GiB (it may run past the end: a file cut off there)."""
    if q == size:
        return True
    if q + _HEAD.size > size:
        return buf[q] in _OPCODES
    op, length = _HEAD.unpack_from(buf, q)
    return op in _OPCODES and length < _PLAUSIBLE_LENGTH


def _record_at(buf, q: int, size: int):
    """(end, record) of a whole record at ``q`` that parses and is followed by a plausible
    one, else None."""
    if q + _HEAD.size > size:
        return None
    op, length = _HEAD.unpack_from(buf, q)
    end = q + _HEAD.size + length
    if op not in _OPCODES or end > size or not _plausible_head(buf, end, size):
        return None
    try:
        return end, _parse(op, buf[q + _HEAD.size : end])
    except PARSE_ERRORS:
        return None


def _resync(buf, start: int, size: int) -> tuple[int, object] | None:
    """(offset, (end, record)) of the first offset from ``start`` where a record begins."""
    for m in _CANDIDATE.finditer(buf, start):
        found = _record_at(buf, m.start(), size)
        if found is not None:
            return m.start(), found
    return None


def _chunk_records(chunk: Chunk, path, where: int, damage: ReadDamage) -> list:
    """The records in a chunk, or [] (skipped and counted) if it cannot be opened."""
    if chunk.uncompressed_size > _MAX_CHUNK:
        damage.skip(path, where, "chunk with an impossible size")
        return []
    try:
        return breakup_chunk(chunk)
    except (*PARSE_ERRORS, RuntimeError, OSError) as e:  # lz4 / zstd errors are RuntimeErrors
        damage.skip(path, where, f"unreadable chunk ({type(e).__name__})")
        return []


def _open(path: Path) -> int:
    """The size of ``path``, an MCAP file or a piece of its magic (a writer killed at once);
    ConfigError if it is neither."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            magic = f.read(len(MAGIC))
    except OSError as e:
        raise ConfigError(path, "", "a readable MCAP mission log", e.strerror or str(e)) from None
    if not MAGIC.startswith(magic):
        raise ConfigError(path, "", "an MCAP mission log", "a file without the MCAP magic")
    return size


def iter_records(path: str | Path, damage: ReadDamage) -> Iterator[tuple[int, object]]:
    """(offset, record) of every readable Schema, Channel, Message and Footer of an MCAP file,
    in file order; the module says what is skipped and counted in ``damage``. Stops after the
    footer. The records of a chunk get its offset + 1 + their index (unique keys inside the
    chunk's bytes: they have no offset of their own in the file)."""
    path = Path(path)
    size = _open(path)
    if size < len(MAGIC):
        if size:
            damage.skip(path, 0, "incomplete magic (the file was cut off)", size)
        return
    if size == len(MAGIC):
        return
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
        size = len(buf)  # what is mapped (a file still being written may have grown)
        pos = len(MAGIC)
        while pos < size:
            step = _read_at(buf, pos, size, path, damage)
            if step is None:  # the framing does not hold: find where the records go on
                resync = _resync(buf, pos + 1, size)
                if resync is None:
                    damage.skip(path, pos, _tail_reason(buf, pos, size), size - pos)
                    return
                damage.skip(path, pos, "damaged region", resync[0] - pos)
                pos, step = resync
            end, record = step
            if isinstance(record, Chunk):
                for k, inner in enumerate(_chunk_records(record, path, pos, damage)):
                    yield pos + 1 + k, inner
            elif record is not None and record is not _CORRUPT:
                yield pos, record
            if isinstance(record, Footer):
                return
            pos = end


def _read_at(buf, pos: int, size: int, path, damage: ReadDamage):
    """(end, record) of the record at ``pos``: the record; None for a kind the readers do not
    use; :data:`_CORRUPT` (skipped and counted) when its content does not parse but the bytes
    after it begin a plausible record. None instead of the pair when the framing does not
    hold."""
    if pos + _HEAD.size > size:
        return None
    op, length = _HEAD.unpack_from(buf, pos)
    end = pos + _HEAD.size + length
    if op not in _OPCODES or end > size:
        return None
    try:
        return end, _parse(op, buf[pos + _HEAD.size : end])
    except PARSE_ERRORS:
        if not _plausible_head(buf, end, size):
            return None
        damage.skip(path, pos, f"corrupt {Opcode(op).name.lower()} record")
        return end, _CORRUPT


def _tail_reason(buf, pos: int, size: int) -> str:
    """Why the bytes from ``pos`` to the end could not be read."""
    if pos + _HEAD.size <= size:
        op, length = _HEAD.unpack_from(buf, pos)
        if op in _OPCODES and length < _PLAUSIBLE_LENGTH:
            return "incomplete last record (the file was cut off)"
    elif buf[pos] in _OPCODES:
        return "incomplete last record (the file was cut off)"
    return f"damaged rest of the file ({size - pos} bytes)"
