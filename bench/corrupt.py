"""A log corrupter: damaged copies of a log file's bytes, for the robustness benchmark
(``bench/robustness.py``) and ``tests/test_log_corruption.py``.

:func:`corrupt_variants` gives ``(kind, damaged bytes)`` pairs, deterministic for a seed, the
kinds interleaved so that any prefix of the list mixes them: random bit flips (1 to 100),
truncations at random offsets (inside the magic too), zeroed blocks, record lengths set to
3 GiB, 2^63 or off by a few bytes (MCAP files: real record headers, found by walking the
records; other files: 8 bytes of 0xFF written at a random offset), swapped and repeated blocks,
garbage behind the real magic and with none, a foreign file, one byte, the magic alone and an
empty file. Only the standard library: the benchmark imports it beside its own code.
"""

import random
import struct

MCAP_MAGIC = b"\x89MCAP0\r\n"
_HEAD = struct.Struct("<BQ")


def mcap_record_offsets(data: bytes) -> list[int]:
    """Offsets of the record headers of an MCAP file's bytes (walked from the magic; [] for
    another file), up to the first that does not fit."""
    if not data.startswith(MCAP_MAGIC):
        return []
    offsets, pos = [], len(MCAP_MAGIC)
    while pos + _HEAD.size <= len(data):
        _, length = _HEAD.unpack_from(data, pos)
        if pos + _HEAD.size + length > len(data):
            break
        offsets.append(pos)
        pos += _HEAD.size + length
    return offsets


def flip_bits(data: bytes, n: int, rng: random.Random) -> bytes:
    """``data`` with ``n`` random bits flipped (past the first 8 bytes: the magic is kept, so
    the reader gets past its first check)."""
    out = bytearray(data)
    lo = min(8, len(out) - 1)
    for _ in range(n):
        i = rng.randrange(lo, len(out))
        out[i] ^= 1 << rng.randrange(8)
    return bytes(out)


def zero_block(data: bytes, size: int, rng: random.Random) -> bytes:
    """``data`` with ``size`` bytes zeroed from a random offset past the magic."""
    out = bytearray(data)
    start = rng.randrange(min(8, len(out) - 1), len(out))
    out[start : start + size] = bytes(len(out[start : start + size]))
    return bytes(out)


def bad_length(data: bytes, length: int | None, rng: random.Random) -> bytes:
    """A record length replaced: a random MCAP record's by ``length`` (None: its own ± 1 to 7
    bytes); in another file, 8 bytes of 0xFF at a random offset."""
    out = bytearray(data)
    offsets = mcap_record_offsets(data)
    if not offsets:
        i = rng.randrange(min(8, len(out) - 1), len(out))
        out[i : i + 8] = b"\xff" * len(out[i : i + 8])
        return bytes(out)
    pos = rng.choice(offsets[len(offsets) // 4 :])  # past the schemas and channels, mostly
    old = _HEAD.unpack_from(out, pos)[1]
    new = max(old + rng.choice([-7, -3, -1, 1, 2, 5]), 0) if length is None else length
    struct.pack_into("<Q", out, pos + 1, new)
    return bytes(out)


def swap_blocks(data: bytes, size: int, rng: random.Random) -> bytes:
    """Two random blocks of ``size`` bytes past the magic swapped."""
    if len(data) < 8 + 2 * size:
        return data[::-1]
    a, b = sorted(rng.sample(range(8, len(data) - size), 2))
    b = max(b, a + size)
    if b + size > len(data):
        return data[:8] + data[8:][::-1]
    return (
        data[:a] + data[b : b + size] + data[a + size : b] + data[a : a + size] + data[b + size :]
    )


def repeat_block(data: bytes, size: int, rng: random.Random) -> bytes:
    """A random block of ``size`` bytes written twice in a row (a writer that repeated a
    buffer)."""
    a = rng.randrange(min(8, len(data)), max(len(data) - size, 9))
    return data[: a + size] + data[a : a + size] + data[a + size :]


def corrupt_variants(data: bytes, seed: int = 0) -> list[tuple[str, bytes]]:
    """Damaged copies of a log file's ``data``: 48 ``(kind, bytes)`` pairs, the kinds
    interleaved (module doc), the same for the same ``data`` and ``seed``."""
    if len(data) < 16:
        raise ValueError(f"corrupt_variants: {len(data)} bytes is too little to damage")
    rng = random.Random(seed)
    n = len(data)
    garbage = random.Random(seed + 1).randbytes(min(n, 1 << 16))
    rounds = []
    for k in range(4):
        rounds.append(
            [
                (f"bitflip_{(1, 3, 10, 100)[k]}", flip_bits(data, (1, 3, 10, 100)[k], rng)),
                ("truncate", data[: rng.randrange(9, n)]),
                (
                    f"zero_block_{(16, 512, 4096, 64)[k]}",
                    zero_block(data, (16, 512, 4096, 64)[k], rng),
                ),
                (
                    ("length_3GiB", "length_2^63", "length_off_by_a_few", "length_zero")[k],
                    bad_length(data, (3 << 30, 1 << 63, None, 0)[k], rng),
                ),
                (f"bitflip_{(2, 5, 30, 1)[k]}", flip_bits(data, (2, 5, 30, 1)[k], rng)),
                ("truncate", data[: rng.randrange(n // 2, n)]),
                (("swap_blocks", "repeat_block", "swap_blocks", "repeat_block")[k], None),
            ]
        )
        kind = rounds[-1][-1][0]
        size = (64, 300, 4096, 17)[k]
        block = (
            swap_blocks(data, size, rng) if kind == "swap_blocks" else repeat_block(data, size, rng)
        )
        rounds[-1][-1] = (f"{kind}_{size}", block)
    specials = [
        ("empty", b""),
        ("garbage", garbage),
        ("garbage_after_magic", data[:8] + garbage[: n - 8]),
        ("truncate_in_magic", data[: rng.randrange(1, 8)]),
        ("truncate_after_magic", data[:8]),
        ("foreign_text", b"<html><body>not a log</body></html>\n" * 20),
        ("one_byte", data[:1]),
        ("nul_bytes", bytes(min(n, 4096))),
        ("bitflips_everywhere", flip_bits(data, max(n // 100, 1), rng)),
        ("appended_garbage", data + garbage[:4096]),
        ("truncate_and_garbage", data[: n // 2] + garbage[:1024]),
        ("duplicated_file", data + data),
    ]
    variants = []
    for k, r in enumerate(rounds):  # three of the special cases after each round
        variants += r + specials[3 * k : 3 * k + 3]
    variants += [
        ("bitflip_7", flip_bits(data, 7, rng)),
        ("truncate", data[: rng.randrange(9, n)]),
        ("bitflip_50", flip_bits(data, 50, rng)),
        ("zero_block_1024", zero_block(data, 1024, rng)),
        ("length_3GiB", bad_length(data, 3 << 30, rng)),
        ("length_off_by_a_few", bad_length(data, None, rng)),
        ("bitflip_3", flip_bits(data, 3, rng)),
        ("truncate", data[: rng.randrange(9, n)]),
    ]
    return variants
