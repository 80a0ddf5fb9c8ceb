"""Benchmark: bad input end to end — a fixed corpus of bad scenarios and damaged logs, each run
as a user runs it (``usvdrake run`` / ``slam2d`` / ``slam3d`` in its own process).

Scenario cases: every number of five shipped scenarios (canal_demo, river_tracking, canal_survey,
basin_explore, canal_taxi) replaced in turn by one of NaN, ±inf, ±1e300, a string, null or a
list, plus hand-written cases (empty and garbage files, duplicate keys, names outside their
folders, an alias bomb, wrong shapes, bad command-line overrides). Log cases: a short recorded
mission with a 2D lidar, one with a 3D lidar and a CARMEN log, damaged by
``bench/corrupt.py`` (bit flips, truncations, zeroed blocks, huge record lengths, garbage,
empty), each given to the SLAM command that reads it.

Each case gets ``--timeout`` seconds (default 10). A case ends as one of: ``clean_error``
(exit 2, one line on stderr, no traceback), ``ran`` (exit 0, no traceback: the input was usable,
or the damage was skipped and counted), ``traceback`` (a Python traceback on stderr), ``hang``
(killed at the timeout), ``unclear`` (any other exit code, or a refusal of more than one line).
Peak memory is each case's own maximum resident set (``wait4``). Prints one JSON object:
``scenario_cases``, ``log_cases``, ``clean_errors``, ``ran``, ``tracebacks``, ``hangs``,
``unclear``, ``peak_rss_mb_max``, ``slowest_case_s`` and ``problems`` (the cases that were
not clean, with their last stderr line).
"""

import argparse
import copy
import itertools
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from tqdm import tqdm

from usvdrake.scenario import SCENARIO_DIR

sys.path.insert(0, str(Path(__file__).parent))
from corrupt import corrupt_variants  # noqa: E402 - bench/corrupt.py, beside this file

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "usvdrake.cli"]
BASES = ("canal_demo", "river_tracking", "canal_survey", "basin_explore", "canal_taxi")
BAD_VALUES = (float("nan"), float("inf"), float("-inf"), 1e300, -1e300, "abc", None, [1, 2])
RUN = ("--duration", "2", "--quiet", "--no-replay")
PER_BASE = 24  # generated cases per base scenario, spread over its numbers


# --- running one case ---------------------------------------------------------------------------
def run_case(cmd: list[str], timeout: float, cwd: Path) -> dict:
    """Run ``cmd``; its outcome, wall time and own peak memory (wait4's rusage)."""
    with tempfile.TemporaryFile() as err:
        t0 = time.monotonic()
        child = subprocess.Popen(
            cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=err, start_new_session=True
        )
        status, usage, hung = None, None, False
        while status is None:
            pid, st, ru = os.wait4(child.pid, os.WNOHANG)
            if pid:
                status, usage = st, ru
            elif time.monotonic() - t0 > timeout:
                os.killpg(child.pid, signal.SIGKILL)  # the case and anything it started
                _, status, usage = os.wait4(child.pid, 0)
                hung = True
            else:
                time.sleep(0.02)
        child.returncode = os.waitstatus_to_exitcode(status)
        wall = time.monotonic() - t0
        err.seek(0)
        stderr = err.read().decode("utf-8", "replace")
    lines = [s for s in stderr.splitlines() if s.strip()]
    code = child.returncode
    if hung:
        outcome = "hang"
    elif "Traceback (most recent call last)" in stderr:
        outcome = "traceback"
    elif code == 2 and len(lines) == 1:
        outcome = "clean_error"
    elif code == 0:
        outcome = "ran"
    else:
        outcome = "unclear"
    return {
        "outcome": outcome,
        "exit": code,
        "wall_s": wall,
        "rss_mb": usage.ru_maxrss / 1024.0,  # Linux: kB
        "last_line": lines[-1][:200] if lines else "",
    }


# --- the scenario corpus ------------------------------------------------------------------------
def _number_paths(node, path=()):
    """Paths (keys and indices) to every number of a parsed YAML tree."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _number_paths(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _number_paths(v, (*path, i))
    elif isinstance(node, int | float) and not isinstance(node, bool):
        yield path


def _set(tree, path, value):
    tree = copy.deepcopy(tree)
    node = tree
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    return tree


def generated_scenarios() -> list[tuple[str, str]]:
    """(name, YAML text): numbers of each base scenario (``PER_BASE``, spread evenly over its
    numbers) replaced by a bad value in turn."""
    cases = []
    values = itertools.cycle(BAD_VALUES)
    for base in BASES:
        tree = yaml.safe_load((SCENARIO_DIR / f"{base}.yaml").read_text())
        paths = list(_number_paths(tree))
        step = max(1, len(paths) // PER_BASE)
        for path in paths[::step][:PER_BASE]:
            value = next(values)
            key = ".".join(str(p) for p in path)
            text = yaml.safe_dump(_set(tree, path, value), sort_keys=False)
            cases.append((f"{base}:{key}={value!r}", text))
    return cases


GOOD = "vessel: roboat2\nworld: canal_demo\nduration: 10.0\nmission: {waypoints: [[10.0, 0.0]]}\n"
ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, "
    f"*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}]\n"
    for i in range(9)
)
HAND_WRITTEN = [
    ("empty file", ""),
    ("only a comment", "# nothing\n"),
    ("a list, not a mapping", "- 1\n- 2\n"),
    ("a bare string", "hello\n"),
    ("tabs", "vessel:\troboat2\n\tworld: x\n"),
    ("unclosed bracket", "mission: {waypoints: [[1, 2]\n"),
    ("duplicate key", GOOD + "duration: 20.0\n"),
    ("unknown key", GOOD + "colour: red\n"),
    ("unknown nested key", GOOD + "environment: {wind: {speed: 3}}\n"),
    ("vessel outside its folder", GOOD.replace("roboat2", "../scenarios/canal_demo")),
    ("absolute vessel path", GOOD.replace("roboat2", "/etc/passwd")),
    ("world outside its folder", GOOD.replace("world: canal_demo", "world: ../../x")),
    ("unknown vessel", GOOD.replace("roboat2", "titanic")),
    ("unknown world", GOOD.replace("world: canal_demo", "world: atlantis")),
    ("unknown estimator", GOOD + "estimator: crystal_ball\n"),
    ("unknown controller", GOOD + "controller: autopilot9000\n"),
    ("unknown slam method", GOOD + "slam: {method: magic}\n"),
    ("seed -1", GOOD + "seed: -1\n"),
    ("seed 1e30", GOOD + "seed: 1.0e30\n"),
    ("seed a float", GOOD + "seed: 0.5\n"),
    ("duration a string", GOOD.replace("10.0", "'ten'")),
    ("duration a date", GOOD.replace("10.0", "2026-11-27")),
    ("waypoints a number", GOOD.replace("[[10.0, 0.0]]", "5")),
    ("waypoint of one value", GOOD.replace("[[10.0, 0.0]]", "[[10.0]]")),
    ("waypoint of three values", GOOD.replace("[[10.0, 0.0]]", "[[1, 2, 3]]")),
    ("no waypoints", GOOD.replace("[[10.0, 0.0]]", "[]")),
    ("waypoint on land", GOOD.replace("[[10.0, 0.0]]", "[[500.0, 500.0]]")),
    ("initial_state of 3", GOOD + "initial_state: [0, 0, 0]\n"),
    ("initial_state a mapping", GOOD + "initial_state: {x: 1}\n"),
    ("model_error of 2", GOOD + "model_error: [1, 1]\n"),
    ("alias bomb", ALIAS_BOMB),
    ("python object tag", GOOD + "seed: !!python/object/apply:os.system ['true']\n"),
    ("binary garbage", bytes(range(256)).decode("latin-1")),
    ("10 MB of keys", "".join(f"k{i}: {i}\n" for i in range(600_000))),
    ("deep nesting", "a: " + "[" * 5000 + "]" * 5000 + "\n"),
    ("waves components 1e8", GOOD + "environment: {waves: {components: 100000000}}\n"),
    ("nmpc horizon 1e6", GOOD + "nmpc: {horizon: 1000000}\n"),
    ("a 1e6-waypoint route", GOOD.replace("[[10.0, 0.0]]", "[" + "[1, 0]," * 1_000_000 + "]")),
]
OVERRIDES = [
    ("--duration nan", ["canal_demo", "--duration", "nan"]),
    ("--duration inf", ["canal_demo", "--duration", "inf"]),
    ("--duration -1", ["canal_demo", "--duration", "-1"]),
    ("--duration 0", ["canal_demo", "--duration", "0"]),
    ("--duration 1e9", ["canal_demo", "--duration", "1e9"]),
    ("--duration abc", ["canal_demo", "--duration", "abc"]),
    ("--seed -5", ["canal_demo", "--seed", "-5"]),
    ("--seed 1.5", ["canal_demo", "--seed", "1.5"]),
    ("no such scenario", ["no_such_scenario"]),
    ("a folder as scenario", ["."]),
    ("a name outside the folder", ["../vessels/roboat2"]),
    ("--out is a file", ["canal_demo", "--out", "pyproject.toml"]),
]


def scenario_cases(tmp: Path) -> list[tuple[str, list[str]]]:
    """(name, command) of every bad-scenario case."""
    cases = []
    for i, (name, text) in enumerate(HAND_WRITTEN + generated_scenarios()):
        path = tmp / f"scenario_{i:04d}.yaml"
        path.write_text(text)
        cases.append((name, [*CLI, "run", str(path), "--out", str(tmp / f"out_{i}"), *RUN]))
    for name, args in OVERRIDES:
        out = [] if "--out" in args else ["--out", str(tmp / "out_override")]
        cases.append((name, [*CLI, "run", *args, *out, *RUN[2:]]))
    return cases


# --- the log corpus -----------------------------------------------------------------------------
def _record(scenario: str, duration: float, out: Path) -> Path:
    cmd = [*CLI, "run", scenario, "--duration", str(duration), "--out", str(out), *RUN[2:]]
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return out / "log.mcap"


def log_cases(tmp: Path, per_log: int) -> list[tuple[str, list[str]]]:
    """(name, command): damaged copies of a 2D-lidar mission log, a 3D-lidar mission log and a
    CARMEN log, each read by the SLAM command for it."""
    sources = [
        ("basin_rplidar", _record("basin_rplidar", 20.0, tmp / "rec2d"), "slam2d"),
        ("canal_survey", _record("canal_survey", 4.0, tmp / "rec3d"), "slam3d"),
        ("carmen", ROOT / "tests/data/carmen/intel-first200.clf.bz2", "slam2d"),
    ]
    cases = []
    for label, path, command in sources:
        data = path.read_bytes()
        suffix = "".join(path.suffixes)
        for j, (kind, damaged) in enumerate(corrupt_variants(data, seed=0)[:per_log]):
            bad = tmp / f"{label}_{j:03d}{suffix}"
            bad.write_bytes(damaged)
            out = ["--out", str(tmp / f"slam_{label}_{j:03d}")]
            cases.append((f"{label}:{kind}", [*CLI, command, str(bad), *out, "--json", "--quiet"]))
    return cases


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timeout", type=float, default=10.0, help="[s] per case")
    parser.add_argument("--logs-per-source", type=int, default=30, help="damaged copies per log")
    parser.add_argument("--quick", action="store_true", help="every 10th case only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="usvdrake_robustness_") as d:
        tmp = Path(d)
        scen = scenario_cases(tmp)
        logs = log_cases(tmp, args.logs_per_source)
        cases = [("scenario", n, c) for n, c in scen] + [("log", n, c) for n, c in logs]
        if args.quick:
            cases = cases[::10]
        results = []
        for kind, name, cmd in tqdm(cases, desc="robustness", unit="case", file=sys.stderr):
            results.append({"kind": kind, "name": name, **run_case(cmd, args.timeout, ROOT)})
    count = {o: sum(r["outcome"] == o for r in results) for o in ("clean_error", "ran")}
    bad = [r for r in results if r["outcome"] not in ("clean_error", "ran")]
    out = {
        "scenario_cases": sum(r["kind"] == "scenario" for r in results),
        "log_cases": sum(r["kind"] == "log" for r in results),
        "clean_errors": count["clean_error"],
        "ran": count["ran"],
        "tracebacks": sum(r["outcome"] == "traceback" for r in results),
        "hangs": sum(r["outcome"] == "hang" for r in results),
        "unclear": sum(r["outcome"] == "unclear" for r in results),
        "peak_rss_mb_max": round(max(r["rss_mb"] for r in results), 1),
        "slowest_case_s": round(max(r["wall_s"] for r in results), 2),
        "timeout_s": args.timeout,
        "problems": [
            {k: r[k] for k in ("kind", "name", "outcome", "exit", "last_line")} for r in bad
        ],
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
