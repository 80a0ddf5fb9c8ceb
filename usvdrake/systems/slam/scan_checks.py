"""What a 2D SLAM may take from a scan: insane input (a NaN or zero angle step, non-finite or
absurd ranges flagged valid) is refused or cleaned before any map or matcher sees it, so a
broken driver or a corrupted log cannot raise inside the SLAM or make it allocate gigabytes
(a ray of 1e300 m through an occupancy grid)."""

import dataclasses

import numpy as np

from usvdrake.sensors.messages import LaserScan

MAX_RANGE = 200.0  # [m] no 2D lidar a vessel carries reaches further (UTM-30LX: 60 m)
MAX_BEAMS = 100_000  # a revolution at 0.0036°: far beyond any real 2D lidar


def usable_scan(scan: LaserScan) -> LaserScan | None:
    """``scan`` if it is sane; a copy with its insane beams marked invalid if only some are;
    None if the scan as a whole cannot be used (non-finite or zero angle step or start, a
    non-finite time, no usable range limit, more beams than any lidar has)."""
    ranges = np.asarray(scan.ranges, float)
    valid = np.asarray(scan.valid, bool)
    if (
        not np.isfinite([scan.time, scan.angle_min, scan.angle_increment]).all()
        or scan.angle_increment == 0.0
        or not np.isfinite(scan.range_min)
        or not scan.range_max > 0.0
        or len(ranges) > MAX_BEAMS
        or len(valid) != len(ranges)
    ):
        return None
    range_max = min(float(scan.range_max), MAX_RANGE)  # NaN range_max fails the test above
    # only what no lidar measures: a noisy return a little past range_max is a real one
    sane = valid & np.isfinite(ranges) & (ranges > 0.0) & (ranges <= MAX_RANGE)
    if range_max == scan.range_max and np.array_equal(sane, valid):
        return scan  # the common case: nothing to clean, the very same message
    return dataclasses.replace(
        scan, range_max=range_max, ranges=np.where(sane, ranges, np.inf), valid=sane
    )
