"""Velodyne VLP-16 (Puck) UDP data packets: pure codec, bytes <-> firings / points, no I/O.

Followed: Velodyne LiDAR, *VLP-16 User Manual* (63-9243), chapter 9 "Sensor Data": 9.1/9.2
(frame of reference, spherical -> Cartesian), 9.3 (data packet structure, Table 9-1 laser
elevations, Table 9-2 factory bytes), 9.4 (firing timing) and 9.5 (azimuth interpolation).

Data packet = the 1206-byte UDP payload (port 2368; the 1248 bytes quoted by the manual
include the 42-byte Ethernet/IP/UDP headers). Little-endian::

    12 × data block (100 bytes):
        flag        2 bytes  0xFF 0xEE
        azimuth     uint16   [0.01°], 0 .. 35999
        32 × (distance uint16 [2 mm], 0 = no return | reflectivity uint8)
    timestamp       uint32   [µs] past the hour (0 .. 3 599 999 999), first firing of block 0
    return mode     uint8    0x37 strongest, 0x38 last, 0x39 dual
    product id      uint8    0x22 VLP-16 / Puck LITE (same elevations)

Each block holds two firing sequences of the 16 lasers (channels 0-15 and 16-31); laser id i
has the elevation ``ELEVATIONS_DEG[i]`` = -15, 1, -13, 3, ... 15° (the interleaved firing
order). Only the first firing's azimuth is transmitted; the second firing's azimuth is
interpolated halfway to the next block's azimuth (the last block reuses the previous gap), as
in the manual's 9.5 at firing (not per-laser) resolution. In dual-return mode blocks 2k
(last return) and 2k+1 (strongest, or second strongest) are the same two firings and carry the
same azimuth.

Timing (9.4): lasers fire every 2.304 µs, a firing sequence lasts 55.296 µs, a block 110.592 µs
(a block pair in dual mode).

**There is no checksum or CRC in a VLP-16 data packet** (UDP's own checksum is the only
integrity check, handled -- or not -- by the network stack). :func:`decode_packet` can only
reject what is structurally impossible: a wrong datagram size, a block flag other than
0xFFEE, an azimuth ≥ 36000, a timestamp ≥ one hour, unknown factory bytes, or dual-mode block
pairs with different azimuths. A corrupted distance or reflectivity is undetectable; decoded
points are nevertheless always bounded (distance ≤ 65535 × 2 mm = 131.07 m).

Frames: the manual's sensor frame has Y forward, X right, Z up, azimuth α clockwise from Y
seen from above: X = R cos ω sin α, Y = R cos ω cos α, Z = R sin ω. Points here are in the
project's sensor frame (x forward, y left, z up; as ROS's velodyne_pointcloud)::

    x = R cos ω cos α,   y = -R cos ω sin α,   z = R sin ω     (x = Y, y = -X)

so the project's azimuth (counter-clockwise from x) is -α. The per-laser vertical offsets of
Table 9-1 (a few mm) are not applied, like the simulated ``Lidar3D``.

Every decoding error is a :class:`VelodyneError` (a ``ValueError``); nothing else is raised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from usvdrake.sensors.messages import PointCloud

__all__ = [
    "BLOCK_FLAG",
    "DISTANCE_UNIT_M",
    "ELEVATIONS_DEG",
    "LASER_RING",
    "PACKET_SIZE",
    "PRODUCT_VLP16",
    "RETURN_DUAL",
    "RETURN_LAST",
    "RETURN_STRONGEST",
    "Firing",
    "PacketPoints",
    "SweepAssembler",
    "VelodyneError",
    "Vlp16Packet",
    "decode_firings",
    "decode_packet",
    "encode_firings",
    "encode_packet",
    "packet_points",
]

PACKET_SIZE = 1206
BLOCKS = 12
CHANNELS = 32
LASERS = 16
BLOCK_FLAG = b"\xff\xee"
DISTANCE_UNIT_M = 0.002
MAX_DISTANCE_M = 0xFFFF * DISTANCE_UNIT_M  # 131.07 m
AZIMUTH_UNITS = 36000  # 0.01° per unit
US_PER_HOUR = 3_600_000_000
RETURN_STRONGEST = 0x37
RETURN_LAST = 0x38
RETURN_DUAL = 0x39
RETURN_MODES = (RETURN_STRONGEST, RETURN_LAST, RETURN_DUAL)
PRODUCT_VLP16 = 0x22
FIRING_US = 2.304  # between two lasers of a firing sequence
SEQUENCE_US = 55.296  # one firing sequence of 16 lasers (incl. recharge)
BLOCK_US = 2 * SEQUENCE_US

#: elevation [deg] of laser id 0..15 (Table 9-1: the order they are fired and stored)
ELEVATIONS_DEG = np.array([-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15], float)
#: ring (0 = lowest, 15 = highest; the index into the sorted elevations) of laser id 0..15
LASER_RING = np.argsort(np.argsort(ELEVATIONS_DEG))
RING_ELEVATIONS_DEG = np.sort(ELEVATIONS_DEG)

_BLOCK_DTYPE = np.dtype(
    [
        ("flag", "u1", (2,)),
        ("azimuth", "<u2"),
        ("ch", [("d", "<u2"), ("r", "u1")], (CHANNELS,)),
    ]
)
_PACKET_DTYPE = np.dtype(
    [
        ("blocks", _BLOCK_DTYPE, (BLOCKS,)),
        ("timestamp", "<u4"),
        ("return_mode", "u1"),
        ("product_id", "u1"),
    ]
)
assert _PACKET_DTYPE.itemsize == PACKET_SIZE


class VelodyneError(ValueError):
    """A datagram that is not a VLP-16 data packet, or a packet/firing that cannot be encoded."""


@dataclass(eq=False, frozen=True)
class Vlp16Packet:
    """One data packet, field by field as on the wire (raw units)."""

    azimuth_cdeg: np.ndarray  #: (12,) block azimuths [0.01°], Velodyne α
    distance: np.ndarray  #: (12, 32) [2 mm units], 0 = no return; channel = firing*16 + laser
    reflectivity: np.ndarray  #: (12, 32) uint8
    timestamp_us: int  #: [µs] past the hour
    return_mode: int = RETURN_STRONGEST
    product_id: int = PRODUCT_VLP16

    def __eq__(self, other) -> bool:
        if not isinstance(other, Vlp16Packet):
            return NotImplemented
        return (
            np.array_equal(self.azimuth_cdeg, other.azimuth_cdeg)
            and np.array_equal(self.distance, other.distance)
            and np.array_equal(self.reflectivity, other.reflectivity)
            and (self.timestamp_us, self.return_mode, self.product_id)
            == (other.timestamp_us, other.return_mode, other.product_id)
        )

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class Firing:
    """One firing sequence of the 16 lasers (indexed by laser id, not ring)."""

    azimuth_deg: float  #: Velodyne α [deg], clockwise from Y (forward), [0, 360)
    distances_m: tuple[float, ...]  #: 16 [m], 0.0 = no return
    reflectivities: tuple[int, ...] = (0,) * LASERS  #: 16 uint8
    time_offset_us: float = 0.0  #: first laser of this firing, from the packet timestamp
    return_index: int = 0  #: dual mode: 0 last return (even block), 1 strongest (odd block)


@dataclass(eq=False)
class PacketPoints:
    """The returns (distance > 0) of one packet in the project's sensor frame."""

    xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  #: [m]
    ring: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    laser_id: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    azimuth_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: Velodyne α
    distance_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reflectivity: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    time_offset_us: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: per laser
    return_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int))


# ------------------------------------------------------------------------------------------
# Raw packets


def decode_packet(datagram: bytes) -> Vlp16Packet:
    """One UDP payload -> :class:`Vlp16Packet`; :class:`VelodyneError` if impossible."""
    if not isinstance(datagram, bytes | bytearray | memoryview):
        raise VelodyneError(f"not a byte string: {type(datagram).__name__}")
    if len(datagram) != PACKET_SIZE:
        raise VelodyneError(f"datagram of {len(datagram)} bytes, expected {PACKET_SIZE}")
    rec = np.frombuffer(bytes(datagram), _PACKET_DTYPE)[0]
    blocks = rec["blocks"]
    bad = np.nonzero((blocks["flag"][:, 0] != 0xFF) | (blocks["flag"][:, 1] != 0xEE))[0]
    if bad.size:
        raise VelodyneError(f"block {int(bad[0])}: flag is not 0xFFEE")
    az = blocks["azimuth"].astype(np.int64)
    if (az >= AZIMUTH_UNITS).any():
        raise VelodyneError(f"azimuth {int(az.max())} ≥ 36000 (0.01°)")
    ts, mode, product = int(rec["timestamp"]), int(rec["return_mode"]), int(rec["product_id"])
    if ts >= US_PER_HOUR:
        raise VelodyneError(f"timestamp {ts} µs is not within an hour")
    if mode not in RETURN_MODES:
        raise VelodyneError(f"unknown return mode 0x{mode:02X}")
    if product != PRODUCT_VLP16:
        raise VelodyneError(f"product id 0x{product:02X} is not a VLP-16 (0x22)")
    if mode == RETURN_DUAL and (az[0::2] != az[1::2]).any():
        raise VelodyneError("dual return mode: block pair with different azimuths")
    return Vlp16Packet(
        azimuth_cdeg=az,
        distance=blocks["ch"]["d"].astype(np.int64),
        reflectivity=blocks["ch"]["r"].astype(np.int64),
        timestamp_us=ts,
        return_mode=mode,
        product_id=product,
    )


def _int_array(name: str, v, shape: tuple[int, ...], hi: int) -> np.ndarray:
    a = np.asarray(v)
    if a.shape != shape or not (np.issubdtype(a.dtype, np.integer) or a.dtype == bool):
        raise VelodyneError(f"{name}: expected integers of shape {shape}, got {a.shape}")
    if a.size and (a.min() < 0 or a.max() > hi):
        raise VelodyneError(f"{name}: values outside [0, {hi}]")
    return a


def encode_packet(packet: Vlp16Packet) -> bytes:
    """:class:`Vlp16Packet` -> the 1206-byte UDP payload."""
    az = _int_array("azimuth_cdeg", packet.azimuth_cdeg, (BLOCKS,), AZIMUTH_UNITS - 1)
    d = _int_array("distance", packet.distance, (BLOCKS, CHANNELS), 0xFFFF)
    r = _int_array("reflectivity", packet.reflectivity, (BLOCKS, CHANNELS), 0xFF)
    ts = int(packet.timestamp_us)
    if ts != packet.timestamp_us or not 0 <= ts < US_PER_HOUR:
        raise VelodyneError(f"timestamp {packet.timestamp_us!r} µs is not within an hour")
    if packet.return_mode not in RETURN_MODES:
        raise VelodyneError(f"unknown return mode {packet.return_mode!r}")
    if packet.product_id != PRODUCT_VLP16:
        raise VelodyneError(f"product id {packet.product_id!r} is not a VLP-16")
    if packet.return_mode == RETURN_DUAL and (az[0::2] != az[1::2]).any():
        raise VelodyneError("dual return mode: block pair with different azimuths")
    rec = np.zeros((), _PACKET_DTYPE)
    rec["blocks"]["flag"] = (0xFF, 0xEE)
    rec["blocks"]["azimuth"] = az
    rec["blocks"]["ch"]["d"] = d
    rec["blocks"]["ch"]["r"] = r
    rec["timestamp"] = ts
    rec["return_mode"] = packet.return_mode
    rec["product_id"] = packet.product_id
    return rec.tobytes()


# ------------------------------------------------------------------------------------------
# Firings and points


def _firing_azimuths_cdeg(packet: Vlp16Packet) -> np.ndarray:
    """(12, 2) azimuth [0.01°, float, in [0, 36000)] of both firings of every block."""
    dual = packet.return_mode == RETURN_DUAL
    az = np.asarray(packet.azimuth_cdeg, np.float64)  # whole hundredths: exact in float
    distinct = az[0::2] if dual else az  # one azimuth per pair of firings
    gap = np.empty_like(distinct)
    np.mod(distinct[1:] - distinct[:-1], AZIMUTH_UNITS, out=gap[:-1])
    gap[-1] = gap[-2]  # the last block: the previous gap
    second = np.mod(distinct + 0.5 * gap, AZIMUTH_UNITS)
    out = np.empty((az.size, 2))
    out[:, 0] = az
    out[:, 1] = np.repeat(second, 2) if dual else second
    return out


def _block_times_us(packet: Vlp16Packet) -> np.ndarray:
    seq = np.arange(BLOCKS) // 2 if packet.return_mode == RETURN_DUAL else np.arange(BLOCKS)
    return seq * BLOCK_US


# per return mode, the blocks a sweep uses and their firings' times in the packet [µs] (nb, 2)
_ALL_BLOCKS = np.arange(BLOCKS)
_DUAL_BLOCKS = _ALL_BLOCKS[0::2]
_FIRING_US = (_ALL_BLOCKS * BLOCK_US)[:, None] + np.array([0.0, SEQUENCE_US])
_DUAL_FIRING_US = ((_ALL_BLOCKS // 2) * BLOCK_US)[_DUAL_BLOCKS, None] + np.array([0.0, SEQUENCE_US])


def decode_firings(packet: Vlp16Packet | bytes) -> list[Firing]:
    """The 24 firings of a packet, block by block (first firing, then second); in dual mode
    the firings of blocks 2k and 2k+1 coincide in time (``return_index`` 0 and 1)."""
    if not isinstance(packet, Vlp16Packet):
        packet = decode_packet(packet)
    az = _firing_azimuths_cdeg(packet) / 100.0
    tb = _block_times_us(packet)
    dual = packet.return_mode == RETURN_DUAL
    out = []
    for b in range(BLOCKS):
        for f in range(2):
            ch = slice(f * LASERS, (f + 1) * LASERS)
            out.append(
                Firing(
                    azimuth_deg=float(az[b, f]),
                    distances_m=tuple(float(v) * DISTANCE_UNIT_M for v in packet.distance[b, ch]),
                    reflectivities=tuple(int(v) for v in packet.reflectivity[b, ch]),
                    time_offset_us=float(tb[b] + f * SEQUENCE_US),
                    return_index=(b % 2) if dual else 0,
                )
            )
    return out


def _quantise_distance(d) -> int:
    try:
        v = float(d)
    except (TypeError, ValueError) as e:
        raise VelodyneError(f"distance {d!r} is not a number") from e
    if not math.isfinite(v) or v < 0:
        raise VelodyneError(f"distance {d!r} is not a finite non-negative number")
    k = round(v / DISTANCE_UNIT_M)
    if k > 0xFFFF:
        raise VelodyneError(f"distance {v} m exceeds {MAX_DISTANCE_M} m")
    return k


def encode_firings(
    firings,
    timestamp_us: int,
    return_mode: int = RETURN_STRONGEST,
    product_id: int = PRODUCT_VLP16,
) -> bytes:
    """24 single-return firings (in firing order) -> one packet. Distances are rounded to the
    2 mm grid and azimuths to 0.01°; only the azimuth of each block's first firing (the even
    ones) is transmitted -- the odd firings' ``azimuth_deg`` is ignored (the decoder
    interpolates it). ``time_offset_us`` and ``return_index`` are implied by the position.
    Dual-return packets are built with :func:`encode_packet`."""
    firings = list(firings)
    if len(firings) != 2 * BLOCKS:
        raise VelodyneError(f"{len(firings)} firings, a packet holds {2 * BLOCKS}")
    if return_mode == RETURN_DUAL:
        raise VelodyneError("encode_firings is for single-return packets")
    az = np.zeros(BLOCKS, np.int64)
    dist = np.zeros((BLOCKS, CHANNELS), np.int64)
    refl = np.zeros((BLOCKS, CHANNELS), np.int64)
    for i, fr in enumerate(firings):
        b, f = divmod(i, 2)
        if len(fr.distances_m) != LASERS or len(fr.reflectivities) != LASERS:
            raise VelodyneError(f"firing {i}: needs {LASERS} distances and reflectivities")
        if f == 0:
            a = float(fr.azimuth_deg)
            if not math.isfinite(a):
                raise VelodyneError(f"firing {i}: azimuth {fr.azimuth_deg!r}")
            az[b] = round(a * 100.0) % AZIMUTH_UNITS
        dist[b, f * LASERS : (f + 1) * LASERS] = [_quantise_distance(d) for d in fr.distances_m]
        refl[b, f * LASERS : (f + 1) * LASERS] = [int(r) for r in fr.reflectivities]
    return encode_packet(Vlp16Packet(az, dist, refl, timestamp_us, return_mode, product_id))


def spherical_to_xyz(distance_m, elevation_rad, azimuth_deg) -> np.ndarray:
    """(n, 3) points in the project's sensor frame from Velodyne (R, ω, α)."""
    a = np.deg2rad(np.asarray(azimuth_deg, float))
    r = np.asarray(distance_m, float)
    e = np.asarray(elevation_rad, float)
    rc = r * np.cos(e)
    return np.column_stack([rc * np.cos(a), -rc * np.sin(a), r * np.sin(e)])


def packet_points(packet: Vlp16Packet | bytes) -> PacketPoints:
    """Every return (distance > 0) of a packet as points in the project's sensor frame."""
    if not isinstance(packet, Vlp16Packet):
        packet = decode_packet(packet)
    az = np.repeat(_firing_azimuths_cdeg(packet), LASERS, axis=1) / 100.0  # (12, 32)
    laser = np.tile(np.arange(LASERS), (BLOCKS, 2))
    t = (
        _block_times_us(packet)[:, None]
        + np.repeat([0.0, SEQUENCE_US], LASERS)[None, :]
        + laser * FIRING_US
    )
    ret = np.zeros((BLOCKS, CHANNELS), int)
    if packet.return_mode == RETURN_DUAL:
        ret[1::2] = 1
    d = np.asarray(packet.distance)
    m = d > 0
    dist = d[m] * DISTANCE_UNIT_M
    lid = laser[m]
    return PacketPoints(
        xyz=spherical_to_xyz(dist, np.deg2rad(ELEVATIONS_DEG[lid]), az[m]),
        ring=LASER_RING[lid],
        laser_id=lid,
        azimuth_deg=az[m],
        distance_m=dist,
        reflectivity=np.asarray(packet.reflectivity)[m],
        time_offset_us=t[m],
        return_index=ret[m],
    )


# ------------------------------------------------------------------------------------------
# Sweep assembly


class SweepAssembler:
    """Packets -> full 360° sweeps as ``PointCloud`` (16 rings × ``360/resolution_deg``
    columns).

    A sweep ends where the Velodyne azimuth α wraps past ``cut_azimuth_deg`` (default 0°:
    straight ahead, the sensor's own 359.99° -> 0° wrap; 180° gives the simulated
    ``Lidar3D`` layout, column 0 pointing backwards). The first, partial sweep is dropped
    (``partial_sweeps``). Column k covers α = cut + k·resolution (nearest), i.e. the project
    azimuth ``azimuths[k] = -(cut + k·resolution)`` wrapped to (-π, π] -- decreasing, as the
    sensor spins clockwise. Where two returns land in one cell the nearer one is kept; in dual
    mode only the last return (even blocks) is used.

    ``points`` are the measured points (exact firing azimuth, not the column's), one per filled
    cell; ``time`` is the last firing's time [s] past the hour of the first packet (timestamps
    are unwrapped across hour rollovers); ``point_time`` is from the sweep's first firing.

    Bounded memory whatever the azimuths: a sweep still open after ``max_sweep_packets``
    packets (default 1000, ~3x the most a revolution takes: 302 packets in dual-return mode at
    the slowest 300 rpm) has no wrap -- a stalled motor, a constant or garbage azimuth -- and is
    dropped (``overlong_sweeps``, its packets in ``dropped_packets``); the next sweep starts
    afresh (its first part counts as partial, like the one after start-up).
    """

    def __init__(
        self,
        resolution_deg: float = 0.2,
        cut_azimuth_deg: float = 0.0,
        max_sweep_packets: int = 1000,
    ):
        if max_sweep_packets < 1:
            raise ValueError("max_sweep_packets must be positive")
        self.max_sweep_packets = int(max_sweep_packets)
        self.overlong_sweeps = 0
        self.dropped_packets = 0
        self._sweep_packets = 0  # packets contributing to the sweep in progress
        n = 360.0 / resolution_deg
        if resolution_deg <= 0 or abs(n - round(n)) > 1e-9:
            raise ValueError("resolution_deg must divide 360")
        self.columns = int(round(n))
        self.resolution_deg = float(resolution_deg)
        self.cut_azimuth_deg = float(cut_azimuth_deg) % 360.0
        az = -np.deg2rad(self.cut_azimuth_deg + self.resolution_deg * np.arange(self.columns))
        self.azimuths = np.pi - np.mod(np.pi - az, 2 * np.pi)  # (-π, π]
        self.elevations = np.deg2rad(RING_ELEVATIONS_DEG)
        self.sweeps = 0
        self.partial_sweeps = 0
        self.packets = 0
        self._hours = 0
        self._last_ts: int | None = None
        self._prev_rel: float | None = None
        self._complete = False  # the current sweep started at a wrap
        self._parts: list[tuple[np.ndarray, ...]] = []

    def feed(self, packet: Vlp16Packet | bytes) -> list[PointCloud]:
        """Add one packet (decoded or a raw datagram); returns the sweeps it completed."""
        if not isinstance(packet, Vlp16Packet):
            packet = decode_packet(packet)
        self.packets += 1
        if self._sweep_packets >= self.max_sweep_packets:  # no wrap for far too long
            self.overlong_sweeps += 1
            self.dropped_packets += self._sweep_packets
            self._parts, self._sweep_packets = [], 0
            self._complete = False
        ts = packet.timestamp_us
        if self._last_ts is not None and ts < self._last_ts - US_PER_HOUR // 2:
            self._hours += 1  # top of the hour
        self._last_ts = ts
        base_us = self._hours * float(US_PER_HOUR) + ts

        dual = packet.return_mode == RETURN_DUAL
        use = _DUAL_BLOCKS if dual else _ALL_BLOCKS
        fa = _firing_azimuths_cdeg(packet)[use] / 100.0  # (nb, 2)
        ft = base_us + (_DUAL_FIRING_US if dual else _FIRING_US)
        rel = np.mod(fa - self.cut_azimuth_deg, 360.0).ravel()  # firing order
        # the firings where the azimuth wrapped past the cut (found at once, not per firing)
        before = np.empty_like(rel)
        before[1:] = rel[:-1]
        before[0] = -np.inf if self._prev_rel is None else self._prev_rel
        wraps = (rel < before - 1.0).nonzero()[0]
        self._prev_rel = float(rel[-1])
        out: list[PointCloud] = []
        start = 0
        for i in wraps:
            self._add(packet, use, fa, ft, start, int(i))
            start = int(i)
            cloud = self._finish()
            if cloud is not None:
                out.append(cloud)
            self._complete = True
        self._add(packet, use, fa, ft, start, len(rel))
        return out

    def _add(self, packet, use, fa, ft, lo: int, hi: int) -> None:
        if hi <= lo:
            return
        self._sweep_packets += 1
        # kept as they came: the points are made in _finish, so a sweep that is dropped
        # (a stalled azimuth never wraps) costs no more than this
        self._parts.append((packet.distance, use, fa, ft, lo, hi))

    @staticmethod
    def _points(distance, use, fa, ft, lo: int, hi: int):
        """(ranges [m], laser ids, azimuths [deg], times [µs], firing times [µs]) of firings
        lo..hi of one packet's blocks ``use``."""
        idx = np.arange(lo, hi)
        blk, f = use[idx // 2], idx % 2
        d = np.asarray(distance)[blk[:, None], f[:, None] * LASERS + np.arange(LASERS)]
        t = ft.ravel()[idx][:, None] + np.arange(LASERS) * FIRING_US
        a = np.broadcast_to(fa.ravel()[idx][:, None], d.shape)
        m = d > 0
        lid = np.broadcast_to(np.arange(LASERS), d.shape)[m]
        return d[m] * DISTANCE_UNIT_M, lid, a[m], t[m], ft.ravel()[idx]

    def flush(self) -> PointCloud | None:
        """The sweep in progress (complete or not) as a cloud, and start afresh."""
        cloud = self._finish(force=True)
        self._prev_rel = None
        self._complete = False
        return cloud

    def _finish(self, force: bool = False) -> PointCloud | None:
        parts, self._parts = self._parts, []
        self._sweep_packets = 0
        if not parts:
            return None
        if not (self._complete or force):
            self.partial_sweeps += 1
            return None
        points = [self._points(*part) for part in parts]
        r, lid, a, t, ftimes = (np.concatenate(p) for p in zip(*points, strict=True))
        t0, t1 = float(ftimes.min()), float(ftimes.max() + (LASERS - 1) * FIRING_US)
        ring = LASER_RING[lid]
        col = np.rint(np.mod(a - self.cut_azimuth_deg, 360.0) / self.resolution_deg).astype(int)
        col %= self.columns
        cell = ring * self.columns + col
        order = np.lexsort((r, cell))
        keep = order[np.r_[True, cell[order][1:] != cell[order][:-1]]] if r.size else order
        image = np.full((LASERS, self.columns), np.inf)
        image[ring[keep], col[keep]] = r[keep]
        self.sweeps += 1
        return PointCloud(
            time=t1 / 1e6,
            elevations=self.elevations.copy(),
            azimuths=self.azimuths.copy(),
            range_image=image,
            points=spherical_to_xyz(r[keep], np.deg2rad(ELEVATIONS_DEG[lid[keep]]), a[keep]),
            ring=ring[keep],
            column=col[keep],
            point_time=(t[keep] - t0) / 1e6,
            sweep_time=(t1 - t0) / 1e6,
            motion_applied=False,
        )
