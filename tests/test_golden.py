"""Behaviour unchanged, proven: every shipped scenario's metrics match the golden outputs in
``tests/golden`` (recorded before the architecture refactor; README there says how)."""

import json
import math
from pathlib import Path

import pytest

from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.run.campaign import is_timing_key
from usvdrake.run.mission import run_mission
from usvdrake.scenario import available_scenarios

GOLDEN = Path(__file__).parent / "golden"
DURATION = 30.0  # [s] as recorded
REL = 1e-6  # floats: the order of floating-point operations may change when code moves


def _compare(got, want, key: str, errors: list[str]) -> None:
    if isinstance(want, dict):
        for k, v in want.items():
            if not is_timing_key(k):
                _compare(got.get(k) if isinstance(got, dict) else None, v, f"{key}.{k}", errors)
    elif isinstance(want, list):
        if not isinstance(got, list) or len(got) != len(want):
            errors.append(f"{key}: {got!r} != {want!r}")
            return
        for i, (g, w) in enumerate(zip(got, want, strict=True)):
            _compare(g, w, f"{key}[{i}]", errors)
    elif isinstance(want, float) and not isinstance(want, bool):
        ok = isinstance(got, int | float) and math.isclose(got, want, rel_tol=REL, abs_tol=1e-12)
        if not ok:
            errors.append(f"{key}: {got!r} != {want!r}")
    elif got != want:
        errors.append(f"{key}: {got!r} != {want!r}")


@pytest.mark.slow
@pytest.mark.parametrize("name", available_scenarios())
def test_metrics_match_the_golden_outputs(name, tmp_path):
    golden = GOLDEN / f"{name}.json"
    assert golden.is_file(), f"no golden output for {name}: run python tests/golden/record.py"
    scenario = with_overrides(load_scenario(name), duration=DURATION, seed=0)
    metrics = run_mission(scenario, out_dir=tmp_path, record=False).metrics
    report = "fleet.png" if scenario.controller == "taxi" else "report.html"
    assert (tmp_path / "metrics.json").is_file() and (tmp_path / report).is_file()
    errors: list[str] = []
    _compare(metrics, json.loads(golden.read_text()), "", errors)
    assert not errors, f"{name}: {len(errors)} metrics changed:\n" + "\n".join(errors)
