"""Generate the canal-scale traffic situations shipped in ``usvdrake/systems/colav/data/canal/``.

DNV's ``trafficgen`` (Sæter et al. 2023; ``pip install trafficgen``, a generator only, never
imported by the package) draws each target's bearing, speed and start so that it meets the
own ship at a given time, as for DNV's standard set, but here for Roboat II (2 m × 1 m, 1 m/s)
among canal boats of 2-5 m at most 4 kn (Amsterdam's canal limit is 7.5 km/h). The times are
DNV's settings Froude-scaled to a 2 m boat (√(2/122) ≈ 0.13: a 30 min situation becomes 4 min,
a 15 min meeting time 2 min). The same 5 situation types as the standard set: the 5 single
encounters, then pairs and triples; a draw where trafficgen finds no start for some target is
redrawn (the seed moves on), so every file has all its targets.

    .venv/bin/python bench/canal_situations.py [--out usvdrake/systems/colav/data/canal]

Deterministic for a given trafficgen version (``random.seed`` per situation). Prints one JSON
object (the files written and the seeds used).
"""

import argparse
import json
import random
import tempfile
from pathlib import Path

from trafficgen.ship_traffic_generator import generate_traffic_situations
from trafficgen.types import EncounterSettings, ShipStatic, SituationInput
from trafficgen.write_traffic_situation_to_file import write_traffic_situations_to_json_file

OUT = Path(__file__).resolve().parents[1] / "usvdrake/systems/colav/data/canal"
OWN_SPEED_KN = 1.9  # ≈ 0.98 m/s: trafficgen writes speeds to 0.1 kn (1 m/s = 1.94 kn)
START = {"lat": 52.3845, "lon": 4.8900}  # the IJ by Amsterdam, open water (land check off)

OWN_SHIP = {
    "id": 1,
    "name": "ROBOAT II",
    "mmsi": 244000001,  # a placeholder Dutch MMSI
    "dimensions": {"length": 2.0, "width": 1.0, "height": 1.0, "a": 1.0, "b": 1.0, "c": 0.5,
                   "d": 0.5},
    "shipType": "Other",
    "sogMax": 3.9,
}  # fmt: skip
TARGETS = [
    {"id": 10, "name": "canal_robot", "shipType": "Other", "sogMax": 4.0,
     "dimensions": {"length": 2.0, "width": 1.0, "height": 1.0, "a": 1.0, "b": 1.0, "c": 0.5,
                    "d": 0.5}},
    {"id": 11, "name": "motorboat", "shipType": "Pleasure craft", "sogMax": 4.0,
     "dimensions": {"length": 3.5, "width": 1.5, "height": 1.0, "a": 1.75, "b": 1.75,
                    "c": 0.75, "d": 0.75}},
    {"id": 12, "name": "sloep", "shipType": "Pleasure craft", "sogMax": 4.0,
     "dimensions": {"length": 5.0, "width": 2.0, "height": 1.2, "a": 2.5, "b": 2.5, "c": 1.0,
                    "d": 1.0}},
]  # fmt: skip
# DNV's classification sectors and relative speeds; the times Froude-scaled to 2 m [min].
SETTINGS = {
    "classification": {"theta13Criteria": 67.5, "theta14Criteria": 5.0,
                       "theta15Criteria": 5.0, "theta15": [112.5, 247.5]},
    "relativeSpeed": {"overtakingStandOn": [1.5, 2], "overtakingGiveWay": [0.25, 0.75],
                      "headOn": [0.5, 1.5], "crossingGiveWay": [0.5, 1.5],
                      "crossingStandOn": [0.5, 1.5]},
    "situationLength": 4.0,
    "maxMeetingDistance": 0.0,
    "commonVector": 0.65,
    "situationDevelopTime": 2.0,
    "disableLandCheck": True,
}  # fmt: skip
CODES = {"HO": "head-on", "CR-GW": "crossing-give-way", "CR-SO": "crossing-stand-on",
         "OT-GW": "overtaking-give-way", "OT-SO": "overtaking-stand-on"}  # fmt: skip
# Each target meets the own ship at its own time [min], so a pair or triple is a sequence.
VECTOR_TIMES = ([1.5, 1.8], [2.3, 2.6], [3.0, 3.3])
SITUATIONS = [
    ["HO"], ["CR-GW"], ["CR-SO"], ["OT-GW"], ["OT-SO"],
    ["HO", "CR-GW"], ["HO", "CR-SO"], ["CR-GW", "HO"], ["CR-GW", "CR-SO"], ["CR-SO", "HO"],
    ["CR-SO", "CR-GW"], ["OT-GW", "HO"], ["OT-GW", "CR-SO"], ["OT-SO", "CR-GW"],
    ["HO", "OT-SO"],
    ["HO", "CR-GW", "CR-SO"], ["CR-GW", "HO", "CR-SO"], ["CR-SO", "CR-GW", "HO"],
    ["HO", "CR-SO", "CR-GW"], ["OT-GW", "HO", "CR-GW"], ["OT-GW", "CR-SO", "HO"],
    ["OT-SO", "HO", "CR-GW"], ["CR-GW", "OT-SO", "CR-SO"], ["HO", "OT-GW", "CR-SO"],
    ["CR-SO", "HO", "OT-SO"],
]  # fmt: skip


def situation_input(codes: list[str]) -> dict:
    return {
        "title": ", ".join(codes),
        "description": f"Canal scale (Roboat II, 1 m/s): {len(codes)} target(s), "
        + ", ".join(CODES[c] for c in codes)
        + ".",
        "ownShip": {
            "initial": {
                "position": dict(START),
                "sog": OWN_SPEED_KN,
                "cog": 90.0,
                "heading": 90.0,
                "navStatus": "Under way using engine",
            },
        },  # fmt: skip
        "encounters": [
            {"desiredEncounterType": CODES[c], "vectorTime": list(VECTOR_TIMES[i])}
            for i, c in enumerate(codes)
        ],
    }


def _snake(d):
    """trafficgen's pydantic models take snake_case keys (its file reader converts them)."""
    if isinstance(d, dict):
        return {
            "".join(f"_{ch.lower()}" if ch.isupper() else ch for ch in k).lstrip("_"): _snake(v)
            for k, v in d.items()
        }
    return [_snake(v) for v in d] if isinstance(d, list) else d


def generate(codes: list[str], seed: int):
    """One situation for ``codes``: (trafficgen TrafficSituation, seed used); redraws until
    every target is found."""
    for s in range(seed, seed + 200):
        random.seed(s)
        situation = generate_traffic_situations(
            SituationInput(**_snake(situation_input(codes))),
            ShipStatic(**_snake(OWN_SHIP)),
            [ShipStatic(**_snake(t)) for t in TARGETS],
            EncounterSettings(**_snake(SETTINGS)),
        )[0]
        if len(situation.target_ships or []) == len(codes):
            return situation, s
    raise RuntimeError(f"trafficgen found no situation for {codes}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    made, seeds = [], []
    for i, codes in enumerate(SITUATIONS):
        situation, seed = generate(codes, 1000 * (i + 1))
        seeds.append(seed)
        with tempfile.TemporaryDirectory() as tmp:
            write_traffic_situations_to_json_file([situation], Path(tmp))
            text = (Path(tmp) / "traffic_situation_01.json").read_text()
        path = args.out / f"canal_situation_{i + 1:02d}.json"
        path.write_text(text)
        made.append(path.name)
    (args.out / "encounter_settings.json").write_text(json.dumps(SETTINGS, indent=4) + "\n")
    print(json.dumps({"situations": len(made), "files": made, "seeds": seeds}))


if __name__ == "__main__":
    main()
