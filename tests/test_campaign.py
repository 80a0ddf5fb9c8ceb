"""Monte Carlo campaigns (usvdrake.run.campaign): randomisation, Dask runs, failures,
reproducibility,
and the plant-only model error behind them."""

import dataclasses
import json
import logging
import os

import numpy as np
import pytest

import usvdrake.run.campaign as campaign_mod
from usvdrake.cli import main
from usvdrake.diagrams import check_scenario, load_scenario, with_overrides
from usvdrake.diagrams.vessel_diagram import build_vessel_diagram
from usvdrake.run.campaign import (
    RANGES,
    dask_client,
    draw_summary,
    is_timing_key,
    randomise,
    run_campaign,
)
from usvdrake.run.mission import run_mission
from usvdrake.typed_yaml import ConfigError
from usvdrake.vessel import load_vessel
from usvdrake.worlds import make_world

CAMPAIGN_SEED = 3


def _physical(metrics: dict) -> dict:
    return {k: v for k, v in metrics.items() if not is_timing_key(k)}


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """4 runs of 10 s of the canal demo on a 2-process LocalCluster."""
    out = tmp_path_factory.mktemp("campaign")
    c = run_campaign(
        load_scenario("canal_demo"),
        runs=4,
        workers=2,
        seed=CAMPAIGN_SEED,
        out_dir=out,
        duration=10.0,
        progress=False,
    )
    return out, c


def test_local_workers_get_one_thread_and_the_parent_keeps_its_environment(monkeypatch):
    """Dask's nanny writes its pre-spawn environment into this process too: the campaign puts
    the parent's values back (a notebook's numba, whose thread pool is running, refused to
    compile after a campaign had left NUMBA_NUM_THREADS=1 behind)."""
    monkeypatch.setenv("MKL_NUM_THREADS", "2")
    for unset in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS"):
        monkeypatch.delenv(unset, raising=False)

    def parent_kept() -> bool:
        return os.environ["MKL_NUM_THREADS"] == "2" and not {
            "NUMBA_NUM_THREADS",
            "OMP_NUM_THREADS",
        } & set(os.environ)

    with dask_client(1, None) as client:
        seen = client.run(lambda: (os.environ.get("NUMBA_NUM_THREADS"), os.getpid()))
        assert [v[0] for v in seen.values()] == ["1"]
        assert all(v[1] != os.getpid() for v in seen.values())
        assert parent_kept()
        # the closing-heartbeat traceback (dask/distributed#7105) is filtered in the workers
        quiet = client.run(_heartbeat_record_passes)
        assert list(quiet.values()) == [(False, True)]
    assert parent_kept()


def _heartbeat_record_passes() -> tuple[bool, bool]:
    """In a worker: (would the lost-heartbeat record be logged, would another ERROR be)."""
    logger = logging.getLogger("distributed.worker")

    def passes(msg: str) -> bool:
        record = logger.makeRecord(logger.name, logging.ERROR, __file__, 0, msg, (), None)
        return logger.filter(record)

    return passes(campaign_mod.HEARTBEAT_LOST + "."), passes("Worker stream died")


def test_campaign_accounts_for_every_run(campaign):
    out, c = campaign
    s = c["summary"]
    assert [r["index"] for r in c["rows"]] == [0, 1, 2, 3]
    assert s["runs"] == 4 and s["completed"] + s["failed"] == 4 and s["completed"] == 4
    assert len({r["worker_pid"] for r in c["rows"]}) == 2  # both worker processes ran
    assert len({r["seed"] for r in c["rows"]}) == 4
    for r in c["rows"]:
        assert r["status"] == "completed" and r["error"] is None
        assert (out / r["yaml"]).is_file() and r["yaml"] == f"runs/run_{r['index']:04d}.yaml"
        assert r["metrics"]["sim_time_s"] == pytest.approx(10.0)
    assert json.loads((out / "campaign.json").read_text()) == c
    st = s["metrics"]["path_length_m"]
    assert st["n"] == 4 and st["min"] <= st["p5"] <= st["median"] <= st["p95"] <= st["max"]
    assert "min_clearance_m" in s["metrics"] and "mission_complete" not in s["metrics"]
    assert s["success_rate"] == 0.0  # 10 s do not finish the canal
    report = (out / "report.html").read_text()
    assert report.count("<img") == len(s["metrics"]) and "Failed runs (0)" in report


def test_run_yaml_reproduces_the_run(campaign, tmp_path):
    """`usvdrake run DIR/runs/run_0002.yaml` repeats run 2 of the campaign bit for bit."""
    out, c = campaign
    row = c["rows"][2]
    args = ["run", str(out / row["yaml"]), "--quiet", "--no-replay", "--out", str(tmp_path)]
    assert main(args) == 0
    again = json.loads((tmp_path / "metrics.json").read_text())
    assert _physical(again) == _physical(row["metrics"])
    # and run i of the campaign is randomise() on child i of the campaign seed
    base = with_overrides(load_scenario("canal_demo"), duration=10.0)
    child = np.random.SeedSequence(CAMPAIGN_SEED).spawn(4)[2]
    s = randomise(base, np.random.default_rng(child))
    loaded = load_scenario(out / row["yaml"])
    assert loaded.name == "canal_demo_run_0002" and loaded.seed == row["seed"]
    assert dataclasses.replace(loaded, name=s.name, description=s.description) == s


def test_failed_runs_are_recorded_not_fatal(monkeypatch, tmp_path):
    """Run 1 raises in the worker, run 2 cannot be randomised: both recorded, the rest run.
    (An in-process cluster via ``scheduler=`` so that the monkeypatches reach the worker.)"""
    from dask.distributed import LocalCluster

    real_run, real_randomise = campaign_mod.run_mission, campaign_mod.randomise
    calls = []

    def flaky_run(scenario, **kw):
        if scenario.name.endswith("_run_0001"):
            raise RuntimeError("thrusters on fire\nsecond line")
        return real_run(scenario, **kw)

    def flaky_randomise(scenario, rng, ranges=RANGES):
        calls.append(1)
        if len(calls) == 3:
            raise ConfigError("test", "initial_state", "free water", "land")
        return real_randomise(scenario, rng, ranges)

    monkeypatch.setattr(campaign_mod, "run_mission", flaky_run)
    monkeypatch.setattr(campaign_mod, "randomise", flaky_randomise)
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        c = run_campaign(
            load_scenario("ntnu_round_open_water"),
            runs=4,
            scheduler=cluster.scheduler_address,
            out_dir=tmp_path,
            duration=2.0,
            progress=False,
        )
    rows, s = c["rows"], c["summary"]
    assert [r["status"] for r in rows] == ["completed", "failed", "failed", "completed"]
    assert rows[1]["error"] == "RuntimeError: thrusters on fire" and rows[1]["yaml"]
    assert "thrusters on fire" in rows[1]["traceback"]
    assert rows[2]["error"].startswith("ConfigError: test: key 'initial_state'")
    assert rows[2]["yaml"] is None and rows[2]["metrics"] is None
    assert (s["runs"], s["completed"], s["failed"], s["success_rate"]) == (4, 2, 2, 0.0)
    report = (tmp_path / "report.html").read_text()
    assert "Failed runs (2)" in report and "RuntimeError: thrusters on fire" in report


def test_model_error_changes_the_plant_not_the_autonomy():
    base = with_overrides(load_scenario("ntnu_round_open_water"), duration=5.0)
    heavy = dataclasses.replace(base, model_error=[1.2, 1.0, 1.0, 1.0, 1.0, 1.0])
    nominal = load_vessel(base.vessel).hydrodynamics
    diagram = build_vessel_diagram(heavy)
    plant = diagram.GetSubsystemByName("station").GetSubsystemByName("plant")
    assert plant.params.hydrodynamics.m11 == pytest.approx(1.2 * nominal.m11)
    assert plant.params.hydrodynamics.Nr == nominal.Nr
    controller = diagram.GetSubsystemByName("autonomy").GetSubsystemByName(
        "heading_speed_controller"
    )
    assert controller._xi == nominal
    nominal_run, heavy_run = run_mission(base, record=False), run_mission(heavy, record=False)
    k = np.searchsorted(nominal_run.times, 1.0)  # same commands at first, slower response
    assert heavy_run.states[k, 3] < 0.95 * nominal_run.states[k, 3]
    assert abs(heavy_run.states[-1, 0] - nominal_run.states[-1, 0]) > 0.01

    # the NMPC and NMHE of river_tracking keep the nominal model too
    river = load_scenario("river_tracking")
    river = dataclasses.replace(river, model_error=[1.2, 0.8, 1.1, 0.9, 1.2, 0.8])
    autonomy = build_vessel_diagram(river).GetSubsystemByName("autonomy")
    roboat = load_vessel(river.vessel).hydrodynamics
    assert autonomy.GetSubsystemByName("nmpc").problem.xi == roboat
    assert autonomy.GetSubsystemByName("nmhe").problem.xi == roboat


@pytest.mark.parametrize("bad", [[1.0] * 5, [1.0, 1.0, 0.0, 1.0, 1.0, 1.0]])
def test_model_error_is_validated(bad):
    s = dataclasses.replace(load_scenario("ntnu_round_open_water"), model_error=bad)
    with pytest.raises(ConfigError, match="key 'model_error': expected 6 positive") as e:
        check_scenario(s)
    assert "\n" not in str(e.value)


def test_randomise_respects_its_ranges_and_stays_in_free_water():
    base = load_scenario("canal_demo")
    hull = load_vessel(base.vessel).hull.length
    draws = []
    for child in np.random.SeedSequence(11).spawn(25):
        s = randomise(base, np.random.default_rng(child))
        d = draw_summary(base, s)
        draws.append(d)
        for key in ("current_factor", "wind_factor", "gust_factor"):
            assert 0.5 <= d[key] <= 1.5
        assert d["wave_height_factor"] is None  # a calm sea stays calm
        assert s.environment.waves.significant_height == 0.0
        for key in ("current", "wind", "wave"):
            assert abs(d[f"{key}_direction_offset_deg"]) <= 30.0
        assert d["start_offset_m"] <= hull and abs(d["heading_offset_deg"]) <= 15.0
        assert all(0.8 <= f <= 1.2 for f in d["model_error"])
        assert s.initial_state[3:] == base.initial_state[3:]
        assert s.mission == base.mission and s.controller == base.controller
        world = make_world(s.world, s.seed)  # the run's own world (its layout follows the seed)
        x, y = s.initial_state[:2]
        assert world.in_water(x, y) and world.clearance(x, y) > 0.0
    # the draws spread over their ranges
    assert np.ptp([d["wind_factor"] for d in draws]) > 0.5
    assert np.ptp([d["heading_offset_deg"] for d in draws]) > 15.0
    # deterministic: the same generator state gives the same scenario
    child = np.random.SeedSequence(11).spawn(25)[7]
    a, b = (randomise(base, np.random.default_rng(child)) for _ in range(2))
    assert a == b


def test_cli_campaign_rejects_bad_input(capsys, tmp_path):
    assert main(["campaign", "no_such_scenario", "--runs", "2"]) == 2
    assert main(["campaign", "canal_demo", "--runs", "0"]) == 2
    bad_scheduler = ["--scheduler", "nonsense://x", "--out", str(tmp_path), "--quiet"]
    assert main(["campaign", "canal_demo", "--runs", "1", *bad_scheduler]) == 2
    err = capsys.readouterr().err
    assert err.count("usvdrake: error:") == 3 and "--runs" in err and "'scheduler'" in err
