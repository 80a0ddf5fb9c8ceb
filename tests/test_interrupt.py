"""A run stopped by SIGINT or SIGTERM writes every output, marked ``interrupted``, and exits
128 + the signal (130 / 143) without a traceback; one killed by SIGKILL leaves a log that the
``mcap`` package's own reader opens. Each waits for the run to be under way (its log holds
ground truth), not for a wall-clock time, so a loaded machine only makes it slower."""

import json
import signal
import subprocess
import sys
import time

import pytest
from mcap.reader import make_reader

from usvdrake.logs.mission_log import log_summary

OUTPUTS = (
    "metrics.json",
    "report.html",
    "replay.html",
    "ground_truth.tum",
    "log.mcap",
    "diagram.dot",
)


def _start(out):
    # canal_survey's tour takes ~25 simulated minutes: no chance of ending before the signal
    cmd = [
        sys.executable,
        "-m",
        "usvdrake.cli",
        "run",
        "canal_survey",
        "--out",
        str(out),
        "--quiet",
    ]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_until_under_way(child, log, timeout: float = 300.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert child.poll() is None, child.communicate()
        if log.is_file() and log.stat().st_size > 0:
            topics = log_summary(log)["topics"]
            if topics.get("/ground_truth", {}).get("messages", 0) > 20:
                return
        time.sleep(0.2)
    child.kill()
    pytest.fail("the run never got under way")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_the_run_and_every_output_is_written(tmp_path, sig):
    child = _start(tmp_path)
    try:
        _wait_until_under_way(child, tmp_path / "log.mcap")
        child.send_signal(sig)
        out, err = child.communicate(timeout=300)
    finally:
        child.kill()
    assert child.returncode == 128 + sig, err
    assert "Traceback" not in err
    assert f"interrupted by {sig.name}" in err
    for name in OUTPUTS:
        assert (tmp_path / name).is_file(), name
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["interrupted"] is True and metrics["interrupted_by"] == sig.name
    assert metrics["mission_complete"] is False
    assert log_summary(tmp_path / "log.mcap")["complete"]  # closed properly, with its index


def test_sigkill_leaves_a_log_the_mcap_package_reads(tmp_path):
    child = _start(tmp_path)
    log = tmp_path / "log.mcap"
    try:
        _wait_until_under_way(child, log)
        child.send_signal(signal.SIGKILL)
        child.communicate(timeout=60)
    finally:
        child.kill()
    ours = log_summary(log)
    assert not ours["complete"] and ours["messages"] > 0
    with open(log, "rb") as f:
        theirs = sum(1 for _ in make_reader(f).iter_messages())
    assert theirs == ours["messages"]
