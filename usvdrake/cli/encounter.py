"""``usvdrake encounter SITUATION.json --out DIR``: one DNV traffic situation, own ship under
SB-MPC collision avoidance on AIS tracks; evaluation and tracks in DIR."""

from usvdrake.cli._format import num
from usvdrake.diagrams.encounter_diagram import SHIP, EncounterConfig
from usvdrake.errors import ConfigError
from usvdrake.run.encounter import run_encounter, situation_paths
from usvdrake.systems.colav.sbmpc import NMI


def add_arguments(p) -> None:
    p.add_argument(
        "situation",
        help="a trafficgen traffic-situation JSON file, or a shipped one's name "
        "(traffic_situation_01 ... _40: DNV's standard set; canal_situation_01 ... _25: the "
        "canal-scale set)",
    )
    p.add_argument("--out", default="out/encounter", help="output folder (default: out/encounter)")
    add_config_arguments(p)
    p.add_argument(
        "--duration", type=float, default=None, help="simulated time limit [s] (default: 2.5 × "
        "the route's planned time + 600 s)"
    )  # fmt: skip
    p.add_argument(
        "--replay", action="store_true",
        help="also write DIR/replay.html: a Meshcat replay with every ship to scale",
    )  # fmt: skip
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def add_config_arguments(p) -> None:
    """The options ``encounter`` and ``encounters`` share."""
    p.add_argument(
        "--safety-distance", type=float, default=0.5 * NMI,
        help="required CPA [m] for DNV's 122 m own ship (default: 926, 0.5 nmi); × L / 122 m "
        "for a smaller own ship or vessel (canal set, roboat2: 15.2 m)",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="AIS noise seed (default: 0)")
    p.add_argument(
        "--own", default=SHIP, help="own ship: 'ship' (built from the situation's dimensions; "
        "default) or a usvdrake vessel (e.g. roboat2: the situation is Froude-scaled to it)",
    )  # fmt: skip


def config_from(args) -> EncounterConfig:
    if not args.safety_distance > 0.0:
        raise ConfigError("command line", "--safety-distance", "a distance > 0 [m]",
                          args.safety_distance)  # fmt: skip
    if args.seed < 0:
        raise ConfigError("command line", "--seed", "an integer >= 0", args.seed)
    return EncounterConfig(safety_distance_m=args.safety_distance, seed=args.seed)


def run(args) -> int:
    paths = situation_paths([args.situation])
    if len(paths) != 1:
        raise ConfigError(args.situation, "", "one situation file (use encounters for a set)",
                          f"{len(paths)} files")  # fmt: skip
    r = run_encounter(
        paths[0],
        args.out,
        config_from(args),
        args.duration,
        progress=not args.quiet,
        own=args.own,
        replay=args.replay,
    )
    e = r["evaluation"]
    print(
        f"usvdrake encounter {e.situation} ({e.title}): {r['sim_time_s']:.0f} s simulated in "
        f"{r['wall_s']:.1f} s wall, {r['decisions']} SB-MPC decisions"
    )
    if r["own"] != SHIP:
        print(
            f"  own ship {r['own']}: situation Froude-scaled by k = {r['length_scale']:.4g}, "
            f"safety distance {r['safety_distance_m']:.3g} m"
        )
    for t in e.targets:
        verdict = "compliant" if t.compliant else "NOT compliant"
        print(
            f"  target {t.target_id}: {t.encounter:<6} CPA {num(t.cpa_m, '.4g', ' m')} at "
            f"{num(t.t_cpa_s, '.0f', ' s')}, {verdict}" + ("; collision" if t.collision else "")
        )
        for reason in t.reasons:
            print(f"    - {reason}")
    print(
        f"  arrived {e.arrived} ({e.final_distance_m:.3g} m from the last waypoint), path "
        f"{e.path_length_m:.4g} m = {e.path_ratio:.3f} × route"
    )
    for name, path in r["files"].items():
        print(f"  {name:<15} {path}")
    return 0  # the verdict is printed and in encounter.json; 1 is for runs that fail
