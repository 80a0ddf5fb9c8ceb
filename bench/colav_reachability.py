"""Benchmark: can the required CPA be kept at all? Each SB-MPC behaviour held from the start.

For each situation named (default: DNV's situation 17, the one whose CPA misses 0.5 nmi), the
closed loop of ``run_encounter`` is run once per behaviour of the SB-MPC's set (course offset ×
speed factor, Johansen et al. 2016), with the SB-MPC allowed only that behaviour for the first
``--hold`` seconds of simulated time (``--hold`` ≥ the encounter's CPA time; the run stops at
``--hold``). Every target's CPA over that time is recorded. Prints one JSON object:
``situations``: per situation ``best_cpa_m`` per target (the largest CPA any held behaviour
gives, and which behaviour), ``range_at_start_m`` per target, ``safety_distance_m`` and
``reachable`` (some behaviour keeps every target at ≥ the safety distance). This is a lower
bound on what a controller could do (it holds one behaviour; a cleverer sequence might do
better), so ``reachable: false`` is evidence, not proof; a target that starts inside the safety
distance makes the requirement impossible outright.
"""

import argparse
import dataclasses
import json

import numpy as np

from usvdrake.diagrams.encounter_diagram import EncounterConfig, own_ship_params, sbmpc_params
from usvdrake.run.encounter import prepare, run_encounter, shipped_situation
from usvdrake.systems.colav.situation import load_situation


def held_behaviours(path, hold_s: float, config: EncounterConfig) -> dict:
    situation, cfg = prepare(path, config=config)  # cfg at the situation's scale
    base = sbmpc_params(own_ship_params(situation), cfg.safety_distance_m)
    own = situation.own_ship
    ranges = {tgt.id: float(np.hypot(*(tgt.xy[0] - own.xy[0]))) for tgt in situation.targets}
    best = {tid: (-1.0, None) for tid in ranges}
    runs = []
    for chi in base.course_offsets_deg:
        for fac in base.speed_factors:
            one = dataclasses.replace(base, course_offsets_deg=(chi,), speed_factors=(fac,))
            # (run_encounter scales ``config`` itself: it takes the ship-scale one)
            r = run_encounter(path, None, config, duration=hold_s, plot=False, sbmpc=one)
            cpas = {t.target_id: float(t.cpa_m) for t in r["evaluation"].targets}
            runs.append({"offset_deg": chi, "speed_factor": fac, "cpa_m": cpas})
            for tid, c in cpas.items():
                if c > best[tid][0]:
                    best[tid] = (c, {"offset_deg": chi, "speed_factor": fac})
    safe = cfg.safety_distance_m
    reachable = any(min(r["cpa_m"].values()) >= safe for r in runs)
    return {
        "safety_distance_m": safe,
        "range_at_start_m": {str(k): round(v, 1) for k, v in ranges.items()},
        "best_cpa_m": {str(k): {"cpa_m": round(c, 1), **(b or {})} for k, (c, b) in best.items()},
        "behaviours": len(runs),
        "reachable": reachable,
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("situations", nargs="*", default=["traffic_situation_17"])
    parser.add_argument("--hold", type=float, default=600.0, help="simulated seconds [s]")
    args = parser.parse_args()
    out = {"benchmark": "colav_reachability", "hold_s": args.hold, "situations": {}}
    for name in args.situations:
        path = shipped_situation(name) or name
        load_situation(path)  # a clear error for a bad name before the runs
        out["situations"][str(name)] = held_behaviours(path, args.hold, EncounterConfig())
    print(json.dumps(out))


if __name__ == "__main__":
    main()
