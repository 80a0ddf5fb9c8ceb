"""Lidar models: device presets, beam layouts, the sweep's own motion, and range noise.

Presets (datasheet numbers; the papers' sensors):
* ``rplidar_a1`` — Slamtec RPLIDAR A1 (Ueland 2017): 360°, ~1° steps as Ueland 2017 uses it, 0.15-12
m,
  5.5 Hz; accuracy 1 % of range up to 3 m, 2.5 % beyond (RPLIDAR A1 datasheet v2.x: "1 % of the
  range (≤ 3 m), 2 % (3-5 m), 2.5 % (5-25 m)") → σ = 0.01 r (we use the ≤ 3-5 m figure).
* ``hokuyo_utm30lx`` — Hokuyo UTM-30LX (Pham et al.): 270°, 0.25° (1081 beams), 0.1-30 m, 40 Hz,
  accuracy ±30 mm to 10 m and ±50 mm to 30 m (UTM-30LX specification) → σ ≈ 0.01 + 0.0013 r.
* ``hokuyo_utm30lx_sim60`` — the same with the 60 m range Pham et al. §V-B uses in Gazebo.
* ``vlp16`` — Velodyne VLP-16 (Roboat II): 16 rings at −15°…+15° every 2°, 0.2° azimuth at 10 Hz
  (1800 columns), 100 m, ±3 cm typical accuracy (VLP-16 datasheet) → σ = 0.03 m; min 0.5 m.

Each beam is cast from where the sensor was when that beam fired (``motion``): the sensor pose
is extrapolated backwards from the sweep's end with the vessel's current body velocities
(constant u, v, r over the sweep), as a spinning lidar on a moving boat really measures. Ranges
are reported raw, points in the sensor frame of their own firing time, with each point's time
offset, so SLAM can de-skew as LIO-SAM does.
"""

from dataclasses import dataclass, field

import numpy as np

from usvdrake.random_streams import generator
from usvdrake.worlds.raycast import ColumnLayout, Scene, cast


@dataclass(frozen=True)
class LidarPreset:
    name: str
    fov_deg: float  # [deg] horizontal field of view
    resolution_deg: float  # [deg] azimuth step
    range_min: float  # [m]
    range_max: float  # [m]
    rate_hz: float  # [Hz] revolutions per second
    noise_const: float  # [m] σ = noise_const + noise_prop · range
    noise_prop: float  # [-]
    elevations_deg: tuple[float, ...] = (0.0,)  # [deg] ring elevations (3D)
    clockwise: bool = False  # spin direction seen from above

    @property
    def columns(self) -> int:
        n = self.fov_deg / self.resolution_deg
        return int(round(n)) if self.fov_deg >= 360.0 else int(round(n)) + 1

    def layout(self) -> ColumnLayout:
        step = np.deg2rad(self.resolution_deg)
        if self.fov_deg >= 360.0:
            az0 = -np.pi
        else:
            az0 = -np.deg2rad(self.fov_deg) / 2
        if self.clockwise:
            return ColumnLayout(
                az0=-az0 if self.fov_deg < 360 else np.pi, daz=-step, count=self.columns
            )
        return ColumnLayout(az0=az0, daz=step, count=self.columns)


LIDAR_PRESETS: dict[str, LidarPreset] = {
    "rplidar_a1": LidarPreset("rplidar_a1", 360.0, 1.0, 0.15, 12.0, 5.5, 0.0, 0.01),
    "hokuyo_utm30lx": LidarPreset("hokuyo_utm30lx", 270.0, 0.25, 0.1, 30.0, 40.0, 0.01, 0.0013),
    "hokuyo_utm30lx_sim60": LidarPreset(
        "hokuyo_utm30lx_sim60", 270.0, 0.25, 0.1, 60.0, 40.0, 0.01, 0.0013
    ),
    "vlp16": LidarPreset(
        "vlp16",
        360.0,
        0.2,
        0.5,
        100.0,
        10.0,
        0.03,
        0.0,
        elevations_deg=tuple(np.arange(-15.0, 15.1, 2.0)),
        clockwise=True,
    ),
}


@dataclass
class LidarConfig:
    preset: str = "rplidar_a1"  # one of LIDAR_PRESETS
    rate_hz: float = 0.0  # [Hz] override the preset's rate (0: the preset's)
    range_max: float = 0.0  # [m] override the preset's maximum range (0: the preset's)
    mount: list[float] = field(
        default_factory=lambda: [0.0, 0.0, 0.5, 0.0]
    )  # [x y z m, yaw rad] in the body frame
    motion: bool = True  # cast each beam from where the sensor was when it fired
    noise: bool = True  # add range noise (σ from the preset)
    dropout: float = 0.0  # [-] probability that a beam returns nothing
    # Sun glare (Roboat II §VI-A: false returns on sunny days). On a fraction ``glare_fraction`` of
    # the sweeps, the beams pointing within ±``glare_width_deg``/2 of the sun's azimuth
    # ``glare_azimuth_deg`` (world frame, ENU, counter-clockwise from east) return, with
    # probability ``glare_beam_fraction`` each, a false range drawn uniformly between the
    # sensor's minimum range and ``glare_max_range``: the receiver saturates and fires on noise.
    glare_fraction: float = 0.0  # [-]
    glare_azimuth_deg: float = 200.0  # [deg] sun azimuth (SSW, a low afternoon sun)
    glare_width_deg: float = 12.0  # [deg]
    glare_beam_fraction: float = 0.3  # [-]
    glare_max_range: float = 30.0  # [m]


def sample_rate(cfg: "LidarConfig") -> float:
    """[Hz] how often a lidar of ``cfg`` delivers a sweep: its own ``rate_hz`` or the preset's."""
    return cfg.rate_hz or preset_by_name(cfg.preset).rate_hz


def preset_by_name(name: str) -> LidarPreset:
    if name not in LIDAR_PRESETS:
        raise KeyError(
            f"unknown lidar preset {name!r}; expected one of {', '.join(sorted(LIDAR_PRESETS))}"
        )
    return LIDAR_PRESETS[name]


def body_motion(q: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Poses (x, y) and headings at times dt [s] (negative: the past) relative to state q =
    [x y ψ u v r], with constant body velocities (exact arc integration)."""
    x, y, psi, u, v, r = q
    rd = r * dt
    small = np.abs(r) < 1e-9
    rs = r if not small else 1.0
    a = np.where(small, dt, np.sin(rd) / rs)
    b = np.where(small, 0.5 * r * dt**2, (1.0 - np.cos(rd)) / rs)
    bx, by = a * u - b * v, b * u + a * v  # displacement in the body frame at dt = 0
    c, s = np.cos(psi), np.sin(psi)
    return np.column_stack([x + c * bx - s * by, y + s * bx + c * by]), psi + rd


@dataclass
class Sweep:
    ranges: np.ndarray  # (rings, columns) [m], inf = no return
    column_time: np.ndarray  # (columns,) [s] firing time relative to the sweep's start
    sweep_time: float  # [s]


class LidarModel:
    """One lidar on one vessel in one world: casts sweeps and adds noise."""

    def __init__(self, preset: LidarPreset, cfg: LidarConfig, scene: Scene, seed: int, stream: int):
        self.preset, self.cfg, self.scene, self.seed, self.stream = preset, cfg, scene, seed, stream
        self.layout = preset.layout()
        self.tan_e = np.tan(np.deg2rad(np.asarray(preset.elevations_deg)))
        self.rate = cfg.rate_hz or preset.rate_hz
        self.range_max = cfg.range_max or preset.range_max
        self.sweep_time = 1.0 / preset.rate_hz  # one revolution at the device's spin rate
        self.column_time = (
            np.arange(self.layout.count)
            / (preset.fov_deg / preset.resolution_deg)
            * self.sweep_time
        )

    def sensor_poses(self, q: np.ndarray, dt: np.ndarray):
        """Sensor positions (n × 2), heights and headings at times dt relative to state q."""
        mx, my, mz, myaw = self.cfg.mount
        pos, psi = body_motion(np.asarray(q, float), dt)
        c, s = np.cos(psi), np.sin(psi)
        return pos + np.column_stack([c * mx - s * my, s * mx + c * my]), mz, psi + myaw

    def sweep(self, q: np.ndarray, k: int, movers: Scene | None = None) -> Sweep:
        """The k-th sweep, ending now at state q. ``movers``: solids that move (other vessels),
        cast as well and the nearer return kept; they hold still during the sweep."""
        if self.cfg.motion:
            dt = self.column_time - self.sweep_time
            pos, z, heading = self.sensor_poses(q, dt)
            ref = len(dt) // 2
            ranges = self._cast_all(
                movers,
                pos[ref],
                z,
                float(heading[ref]),
                column_origin_xy=pos,
                column_heading=heading,
            )
        else:
            pos, z, heading = self.sensor_poses(q, np.zeros(1))
            ranges = self._cast_all(movers, pos[0], z, float(heading[0]))
        if self.cfg.noise or self.cfg.dropout > 0:
            rng = generator(self.seed, self.stream, k)
            if self.cfg.noise:
                sigma = self.preset.noise_const + self.preset.noise_prop * np.where(
                    np.isfinite(ranges), ranges, 0.0
                )
                ranges = ranges + sigma * rng.standard_normal(ranges.shape)
                ranges = np.where(ranges > self.preset.range_min, ranges, np.inf)
            if self.cfg.dropout > 0:
                ranges = np.where(rng.random(ranges.shape) < self.cfg.dropout, np.inf, ranges)
        if self.cfg.glare_fraction > 0:
            ranges = self.glare(ranges, np.broadcast_to(heading, (self.layout.count,)), k)
        return Sweep(ranges, self.column_time, self.sweep_time)

    def glare(self, ranges: np.ndarray, heading: np.ndarray, k: int) -> np.ndarray:
        """Sweep k's ranges with sun-glare false returns (see ``LidarConfig.glare_*``);
        ``heading`` [rad]: the sensor's yaw when each column fired. Seeded by (seed, stream, k)
        on its own generator, so glare does not change the range noise."""
        cfg = self.cfg
        rng = generator(self.seed, self.stream + 1000, k)
        if rng.random() >= cfg.glare_fraction:
            return ranges
        world_az = heading + self.layout.azimuths
        off = np.angle(np.exp(1j * (world_az - np.deg2rad(cfg.glare_azimuth_deg))))
        cols = np.abs(off) <= 0.5 * np.deg2rad(cfg.glare_width_deg)
        hit = (rng.random(ranges.shape) < cfg.glare_beam_fraction) & cols[None, :]
        false = rng.uniform(self.preset.range_min, cfg.glare_max_range, ranges.shape)
        return np.where(hit, false, ranges)

    def _cast_all(self, movers: Scene | None, origin_xy, z, heading, **motion) -> np.ndarray:
        """Noise-free ranges against the world's scene and, if given, the moving solids."""
        args = (self.layout, self.tan_e, origin_xy, z, heading, self.range_max)
        ranges = cast(self.scene, *args, self.preset.range_min, **motion)
        if movers is not None and len(movers):
            ranges = np.minimum(ranges, cast(movers, *args, self.preset.range_min, **motion))
        return ranges


def sensor_to_world(points: np.ndarray, mount, pose) -> np.ndarray:
    """Lidar points (n × 2 or n × 3, sensor frame) in the world frame for a vessel at ``pose``
    = [x y ψ] with the lidar at ``mount`` = [x y z yaw] on the body [m, rad]; z gets the mount
    height (a 2D scan lies in the sensor's plane)."""
    pts = np.asarray(points, float)
    x, y, psi = (float(v) for v in pose[:3])
    mx, my, mz, myaw = mount
    c, s = np.cos(psi), np.sin(psi)
    ox, oy = x + c * mx - s * my, y + s * mx + c * my
    ca, sa = np.cos(psi + myaw), np.sin(psi + myaw)
    z = mz + (pts[:, 2] if pts.shape[1] > 2 else np.zeros(len(pts)))
    return np.column_stack(
        [ox + ca * pts[:, 0] - sa * pts[:, 1], oy + sa * pts[:, 0] + ca * pts[:, 1], z]
    )
