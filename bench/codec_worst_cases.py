"""Benchmark: the byte-stream codecs on the worst cases of the robustness issue, at full size.

* ``nmea``: 160 kB of ``$`` in one ``NmeaStream.feed`` (was quadratic: 84 s);
* ``vlp16``: 20 000 VLP-16 packets at one azimuth (a stalled or broken encoder: no sweep ever
  wraps), then ``flush`` (was +250 MB, 1.4 GB at flush);
* ``rplidar``: 2 000 000 scan nodes without a start flag into the revolution assembler (was
  +290 MB); the nodes are built before the clock starts (the parser that makes them is a
  separate stage, fed bytes at the sensor's 8 000 nodes/s).

Each case runs once for its time (wall ``perf_counter`` and CPU ``process_time``: on a busy
machine the CPU time is what the wall time would be on a free core) and once under
``tracemalloc`` for its peak memory. Prints one JSON object: ``<case>_s``, ``<case>_cpu_s`` and
``<case>_mb`` per case, ``max_s``, ``max_cpu_s``, ``max_mb`` and ``met`` (every case ≤ 1 s of
CPU and ≤ 100 MB, the issue's bound).
"""

import json
import time
import tracemalloc

import numpy as np

from hardware_io.codecs.nmea_stream import NmeaStream
from hardware_io.codecs.rplidar import RplidarScanAssembler, ScanNode
from hardware_io.codecs.velodyne import SweepAssembler, Vlp16Packet

MAX_S, MAX_MB = 1.0, 100.0


def nmea_case():
    data = b"$" * 160_000
    return lambda: NmeaStream().feed(data)


def vlp16_case():
    stalled = Vlp16Packet(np.full(12, 18000), np.full((12, 32), 2500), np.zeros((12, 32), int), 0)

    def run():
        asm = SweepAssembler(resolution_deg=0.2)
        for _ in range(20_000):
            asm.feed(stalled)
        return asm.flush()

    return run


def rplidar_case():
    nodes = [ScanNode(15, (i * 64) % 23040, 4000 + i % 1000) for i in range(2_000_000)]

    def run():
        asm = RplidarScanAssembler()
        asm.feed([ScanNode(15, 0, 4000, True)])  # one start flag, then never another
        return asm.feed(nodes)

    return run


def measure(run) -> tuple[float, float, float]:
    t0, c0 = time.perf_counter(), time.process_time()
    run()
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    tracemalloc.start()
    try:
        run()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return seconds, cpu, peak / 2**20


def main() -> None:
    out = {}
    for name, case in (("nmea", nmea_case), ("vlp16", vlp16_case), ("rplidar", rplidar_case)):
        seconds, cpu, mb = measure(case())
        out[f"{name}_s"], out[f"{name}_mb"] = round(seconds, 3), round(mb, 1)
        out[f"{name}_cpu_s"] = round(cpu, 3)  # CPU time: what the wall time is on a quiet core
    out["max_s"] = max(v for k, v in out.items() if k.endswith("_s") and "cpu" not in k)
    out["max_cpu_s"] = max(v for k, v in out.items() if k.endswith("_cpu_s"))
    out["max_mb"] = max(v for k, v in out.items() if k.endswith("_mb"))
    out["met"] = out["max_cpu_s"] <= MAX_S and out["max_mb"] <= MAX_MB
    print(json.dumps(out))


if __name__ == "__main__":
    main()
