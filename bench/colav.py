"""Benchmark: SB-MPC decision time in its LeafSystem, and (``--set``) DNV's 40 situations.

``colav_ms_median`` is the time of one SB-MPC decision (``Sbmpc.decide``, Johansen et al.
2016) as the ``SbmpcColav`` LeafSystem measures it inside its periodic update and reports on
its ``colav_diagnostics`` port (``decide_ms``): the real path of the diagram, without the rest
of the simulation. The geometries come from the 40 situations of DNV's standard encounter set
(Sæter et al. 2023): at every ``--every`` seconds up to 15 min, the own ship on its planned
route and every target on its waypoints, given to the system as tracks (one system per
situation, so its remembered roles carry over as in a run). Also ``colav_ms_median_active``
(decisions with a target in range, the ones that simulate the behaviours), ``colav_ms_p90``,
``decisions``. Target (issue 37): median ≤ 10 ms.

``--set`` also runs the 40 situations through ``run_encounters`` on ``--workers`` Dask workers
(default 2) and adds ``situations``, ``collisions``, ``min_cpa_m``, ``cpa_met`` (situations
whose every CPA ≥ the safety distance), ``colreg_compliance``, ``arrived``, ``max_path_ratio``,
``path_ratio_met`` (situations with path ≤ 1.2 × route), ``wall_s`` (the whole set, cluster
start included; target ≤ 300 s) and ``colav_ms_median_in_loop`` (every decision of every run).
``--canal`` runs the canal-scale set (``usvdrake/systems/colav/data/canal``, Roboat II as own
ship, safety distance 0.5 nmi × 2 m / 122 m ≈ 15.2 m) the same way; its keys start ``canal_``.
Prints one JSON object.
"""

import argparse
import json
import os
import tempfile

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator

from usvdrake.diagrams.encounter_diagram import (
    SHIP,
    EncounterConfig,
    own_ship_params,
    sbmpc_params,
)
from usvdrake.run.encounter import CANAL, STANDARD, run_encounters, situation_paths
from usvdrake.systems.colav.sbmpc_colav import DIAGNOSTICS, SbmpcColav
from usvdrake.systems.colav.situation import load_situation
from usvdrake.systems.colav.tracking import Track

TARGET_MS = 10.0
TARGET_WALL_S = 300.0
MAX_PATH_RATIO = 1.2


def _decision_times(path, every: float, safety_distance: float) -> tuple[list, list]:
    """decide_ms of the SbmpcColav decisions along one situation's planned geometry."""
    situation = load_situation(path)
    colav = SbmpcColav(sbmpc_params(own_ship_params(situation), safety_distance), period=every)
    context = colav.CreateDefaultContext()
    simulator = Simulator(colav, context)
    own = situation.own_ship
    times, active = [], []
    for t in np.arange(0.0, 900.0 + 1e-9, every):
        x, y, psi, speed = (v[0] for v in own.state_at(t))
        colav.GetInputPort("state").FixValue(context, [x, y, psi, speed, 0.0, 0.0])
        colav.GetInputPort("nominal").FixValue(context, [psi, speed])
        tracks = []
        for ship in situation.targets:
            tx, ty, tpsi, tspeed = (v[0] for v in ship.state_at(t))
            velocity = tspeed * np.array([np.cos(tpsi), np.sin(tpsi)])
            tracks.append(Track(ship.id, t, np.array([tx, ty]), velocity, np.eye(4), 0.0, 10))
        colav.GetInputPort("tracks").FixValue(context, AbstractValue.Make(tracks))
        simulator.AdvanceTo(t + 0.5 * every)  # the update at t, on these inputs
        diag = dict(
            zip(DIAGNOSTICS, colav.GetOutputPort("colav_diagnostics").Eval(context), strict=True)
        )
        times.append(diag["decide_ms"])
        active.append(diag["active"] > 0)
    return times, active


def _set_summary(which: str, own: str, cfg, args, prefix: str) -> dict:
    """Run a set through ``run_encounters`` and score it against issue 37's must-holds (keys
    prefixed ``prefix``); the safety distance is the run's (Froude-scaled for a small own ship)."""
    with tempfile.TemporaryDirectory() as tmp:
        out_dir = args.out and f"{args.out}/{which}"
        s = run_encounters(
            [which], out_dir or tmp, workers=args.workers, config=cfg, progress=False, own=own
        )
    entries = s["entries"]
    safety = s["safety_distance_m"]
    cpa_met = sum(e["min_cpa_m"] >= safety for e in entries)
    summary = {
        "workers": s["workers"],
        "situations": s["situations"],
        "failed": len(s["failed"]),
        "safety_distance_m": round(safety, 3),
        "collisions": s["collisions"],
        "min_cpa_m": round(s["min_cpa_m"], 2),
        "cpa_met": cpa_met,
        # which, and the range at the start of their nearest target: a CPA can only be kept by
        # a ship that starts outside it (bench/colav_reachability.py tries every behaviour)
        "cpa_missed": [e["situation"] for e in entries if e["min_cpa_m"] < safety],
        "colreg_compliance": round(s["colreg_compliance"], 4),
        "encounters": s["encounters"],
        "arrived": s["arrived"],
        "max_path_ratio": round(s["max_path_ratio"], 3),
        "path_ratio_met": sum(e["path_ratio"] <= MAX_PATH_RATIO for e in entries),
        "wall_s": round(s["wall_s"], 1),
        "colav_ms_median_in_loop": round(s["colav_ms_median"], 3),
        "met_set": (
            s["collisions"] == 0
            and cpa_met == s["situations"]
            and s["colreg_compliance"] >= 0.95
            and s["arrived"] == s["situations"]
            and s["max_path_ratio"] <= MAX_PATH_RATIO
            and s["wall_s"] <= TARGET_WALL_S
        ),
    }
    return {f"{prefix}{k}": v for k, v in summary.items()}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--set", action="store_true", help="also run the 40 situations (Dask)")
    parser.add_argument(
        "--canal", action="store_true", help="also run the canal-scale set with Roboat II (Dask)"
    )
    parser.add_argument("--workers", type=int, default=2, help="Dask workers for --set/--canal")
    parser.add_argument("--every", type=float, default=30.0, help="geometry spacing [s]")
    parser.add_argument("--out", default=None, help="--set output folder (default: temporary)")
    args = parser.parse_args()
    cfg = EncounterConfig()
    paths = situation_paths([STANDARD])
    times, active = [], []
    for path in paths:
        t, a = _decision_times(path, args.every, cfg.safety_distance_m)
        times += t
        active += a
    times, active = np.array(times), np.array(active)
    median = float(np.median(times))
    out = {
        "benchmark": "colav",
        "measured": "SbmpcColav update (Sbmpc.decide), decide_ms from colav_diagnostics",
        "cpus": os.cpu_count(),
        "load_average_before": round(os.getloadavg()[0], 2),
        "situations_sampled": len(paths),
        "decisions": int(times.size),
        "colav_ms_median": round(median, 3),
        "colav_ms_median_active": round(float(np.median(times[active])), 3),
        "colav_ms_p90": round(float(np.percentile(times, 90)), 3),
        "target_ms": TARGET_MS,
        "met_ms": median <= TARGET_MS,
    }
    if args.set:
        out |= _set_summary(STANDARD, SHIP, cfg, args, "")
    if args.canal:
        out |= _set_summary(CANAL, "roboat2", cfg, args, "canal_")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
