"""Damaged logs (issue 40, item 3): ``usvdrake slam2d`` and ``slam3d`` skip and count what is
broken, or refuse the file in one line with exit 2 — never a traceback, never a silent half-read.

The damage is ``bench/corrupt.py``'s (bit flips, truncations, zeroed blocks, corrupt record
lengths, swapped blocks, garbage, empty files), applied to a short recorded mission (2D and 3D
lidar, IMU, GPS), to the CARMEN test log (plain and bzip2) and to a ROS 1 bag.
"""

import bz2
import dataclasses
import gzip
import json
import re
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from usvdrake.cli import main
from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.errors import ConfigError
from usvdrake.logs.carmen import read_carmen
from usvdrake.logs.damage import ReadDamage
from usvdrake.logs.mission_log import log_summary, read_log_scans, read_mission_log
from usvdrake.run.mission import run_mission

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from corrupt import corrupt_variants, mcap_record_offsets  # noqa: E402 - bench/corrupt.py
from test_slam_offline import write_bag  # noqa: E402 - tests/ is on the path under pytest

CARMEN = Path(__file__).parent / "data" / "carmen" / "intel-first200.clf.bz2"
# damage a reader always notices: a record length that cannot be, a cut that is not at a
# record boundary (checked below), the whole file flipped
ALWAYS_SEEN = ("length_", "bitflips_everywhere")


@pytest.fixture(scope="module")
def mission_log(tmp_path_factory) -> Path:
    """3 s of the canal survey with a 2D lidar added: /lidar_scan, /lidar_points, /imu, /gps."""
    s = with_overrides(load_scenario("canal_survey"), duration=3.0)
    enabled = ["lidar2d", "lidar3d", "imu", "gps"]
    s = dataclasses.replace(s, sensors=dataclasses.replace(s.sensors, enabled=enabled))
    out = tmp_path_factory.mktemp("mission")
    run_mission(s, out_dir=out, record=False)
    return out / "log.mcap"


def _run_cli(args: list[str], capsys) -> tuple[int, dict | None, str]:
    """(exit code, the metrics printed as JSON or None, stderr) of ``usvdrake ARGS --json``
    run in this process; a traceback would fail the test here."""
    code = main([*args, "--json"])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    assert code in (0, 2), err
    if code == 2:
        lines = [line for line in err.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("usvdrake: error: "), err
        return code, None, err
    return code, json.loads(out), err


def _boundaries(data: bytes) -> set[int]:
    """File sizes at which an MCAP file ends exactly after a record (a cut there is clean)."""
    ends = {len(data)}
    for pos in mcap_record_offsets(data):
        ends.add(pos + 9 + struct.unpack_from("<Q", data, pos + 1)[0])
    return ends


def _must_count(kind: str, bad: bytes, whole: bytes) -> bool:
    """Whether the damage of this variant is sure to be seen by a reader of the whole file."""
    if kind.startswith("truncate") and kind != "truncate_and_garbage":
        return len(bad) > 8 and len(bad) not in _boundaries(whole)
    return kind.startswith(ALWAYS_SEEN)


# --- the mission log reader -------------------------------------------------------------------
def test_a_corrupt_length_mid_file_is_skipped_and_the_rest_still_read(mission_log):
    data = mission_log.read_bytes()
    offsets = mcap_record_offsets(data)
    scans = read_log_scans(mission_log)
    for length in (3 << 30, 1 << 63, len(data)):  # 3 GiB, 2^63, just past the end
        bad = bytearray(data)
        pos = offsets[len(offsets) // 2]
        struct.pack_into("<Q", bad, pos + 1, length)
        path = mission_log.with_name(f"bad_{length}.mcap")
        path.write_bytes(bytes(bad))
        damage = ReadDamage()
        got = read_log_scans(path, damage=damage)
        # one record lost at most (if it was a scan), not the half after it
        assert len(scans) - 1 <= len(got) <= len(scans)
        assert damage.records == 1 and 0 < damage.unread_bytes < len(data) // 10
        assert log_summary(path)["skipped_records"] == 1


def test_a_cut_log_reads_up_to_the_cut_and_says_what_it_left(mission_log):
    data = mission_log.read_bytes()
    offsets = mcap_record_offsets(data)
    cut_at = offsets[len(offsets) // 2] + 20  # 20 bytes into a record
    path = mission_log.with_name("cut.mcap")
    path.write_bytes(data[:cut_at])
    damage = ReadDamage()
    messages = list(read_mission_log(path, damage=damage, log_time_order=False))
    full = list(read_mission_log(mission_log, log_time_order=False))
    # every message before the cut, in order
    assert 0 < len(messages) < len(full)
    assert [(topic, t) for topic, t, _ in messages] == [(topic, t) for topic, t, _ in full][
        : len(messages)
    ]
    assert damage.records == 1 and damage.unread_bytes == 20
    assert "incomplete last record" in next(iter(damage.reasons()))
    assert not log_summary(path)["complete"]


def test_a_message_that_does_not_decode_is_skipped_and_counted(mission_log):
    data = mission_log.read_bytes()
    at = data.index(b'"ranges":[')  # the first scan's JSON, broken
    path = mission_log.with_name("undecodable.mcap")
    path.write_bytes(data[:at] + b"\x00" + data[at + 1 :])
    damage = ReadDamage()
    got = read_log_scans(path, damage=damage)
    assert len(got) == len(read_log_scans(mission_log)) - 1
    assert damage.reasons() == {"undecodable /lidar_scan message": 1}
    # counted once however often the file is read into the same count
    log_summary(path, damage)
    read_log_scans(path, damage=damage)
    assert damage.records == 1


def test_a_file_that_is_not_mcap_is_refused(tmp_path):
    path = tmp_path / "x.mcap"
    path.write_bytes(b"PK\x03\x04 a zip file, not a log")
    with pytest.raises(ConfigError, match="MCAP"):
        list(read_mission_log(path))


def test_chunked_files_of_other_writers_are_read_and_a_bad_chunk_counted(tmp_path):
    from mcap.writer import CompressionType, Writer

    path = tmp_path / "chunked.mcap"
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.NONE, chunk_size=200)
        w.start()
        channel = w.register_channel("/k", "json", w.register_schema("k", "jsonschema", b"{}"))
        for k in range(20):
            w.add_message(channel, k * 10**8, json.dumps({"k": k}).encode(), k * 10**8)
        w.finish()
    assert [m["k"] for _, _, m in read_mission_log(path)] == list(range(20))
    data = bytearray(path.read_bytes())
    # the last chunk (the first holds the channel) claims to unpack to 1 TiB
    chunk = [p for p in mcap_record_offsets(bytes(data)) if data[p] == 0x06][-1]
    struct.pack_into("<Q", data, chunk + 9 + 16, 1 << 40)
    path.write_bytes(bytes(data))
    damage = ReadDamage()
    got = [m["k"] for _, _, m in read_mission_log(path, damage=damage)]
    assert 0 < len(got) < 20 and got == list(range(len(got)))
    assert damage.reasons() == {"chunk with an impossible size": 1}


@settings(
    max_examples=40,
    deadline=None,
    derandomize=True,  # the same examples every run: a corpus, not a flaky test
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 7)), max_size=6),
    keep=st.floats(0.0, 1.0),
)
def test_any_flips_and_cut_are_read_without_an_exception(mission_log, flips, keep):
    data = bytearray(mission_log.read_bytes())
    for where, bit in flips:
        data[8 + int(where * (len(data) - 9))] ^= 1 << bit
    data = bytes(data[: max(int(keep * len(data)), 1)])
    path = mission_log.with_name("hypothesis.mcap")
    path.write_bytes(data)
    damage = ReadDamage()
    messages = list(read_mission_log(path, damage=damage))  # every topic decoded
    if len(data) > 8 and len(data) not in _boundaries(mission_log.read_bytes()) and not flips:
        assert damage.records >= 1  # a cut mid-record is said
    assert len(messages) <= log_summary(mission_log)["messages"] + len(flips)


# --- the commands -----------------------------------------------------------------------------
@pytest.mark.parametrize("command", ["slam2d", "slam3d"])
def test_every_damaged_mission_log_runs_or_is_refused_in_one_line(
    mission_log, command, tmp_path, capsys
):
    data = mission_log.read_bytes()
    extra = ["--out", str(tmp_path / "out"), "--max-scans", "6", "--inline"]
    for j, (kind, bad) in enumerate(corrupt_variants(data, seed=0)):
        path = tmp_path / f"{j:02d}.mcap"
        path.write_bytes(bad)
        code, metrics, err = _run_cli(
            [command, str(path), "--quiet", *(extra if command == "slam2d" else [])], capsys
        )
        if code == 0:
            assert metrics["skipped_records"] >= 0 and metrics["unread_bytes"] >= 0
            if _must_count(kind, bad, data):
                assert metrics["skipped_records"] >= 1, (kind, metrics["skip_reasons"])


def test_the_summary_shows_what_was_skipped(mission_log, tmp_path, capsys):
    data = bytearray(mission_log.read_bytes())
    offsets = mcap_record_offsets(bytes(data))
    struct.pack_into("<Q", data, offsets[len(offsets) // 2] + 1, 3 << 30)
    path = tmp_path / "bad.mcap"
    path.write_bytes(bytes(data))
    args = ["slam2d", str(path), "--out", str(tmp_path / "o"), "--quiet", "--inline"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert re.search(r"skipped_records +1\n", out) and "damaged region 1" in out
    assert json.loads((tmp_path / "o" / "metrics.json").read_text())["skipped_records"] == 1


@pytest.mark.parametrize("form", ["plain", "bz2", "gz"])
def test_every_damaged_carmen_log_runs_or_is_refused_in_one_line(form, tmp_path, capsys):
    text = bz2.decompress(CARMEN.read_bytes())
    data = {"plain": text, "bz2": CARMEN.read_bytes(), "gz": gzip.compress(text)}[form]
    variants = corrupt_variants(data, seed=1)
    for j, (kind, bad) in enumerate(variants[:: {"plain": 2, "bz2": 4, "gz": 3}[form]]):
        path = tmp_path / f"{j:02d}.clf"
        path.write_bytes(bad)
        extra = ["--out", str(tmp_path / "out"), "--max-scans", "5", "--inline", "--quiet"]
        code, metrics, _ = _run_cli(["slam2d", str(path), *extra], capsys)
        if code == 0 and form == "plain" and kind.startswith(("length_", "zero_block")):
            # 0xFF or NUL bytes in a text log: the line they are on is not a CARMEN line
            assert metrics["skipped_records"] >= 1, kind


def test_carmen_lines_that_are_broken_are_counted(tmp_path):
    text = bz2.decompress(CARMEN.read_bytes()).decode()
    lines = text.splitlines(keepends=True)
    flaser = [i for i, line in enumerate(lines) if line.startswith("FLASER")]
    lines[flaser[3]] = lines[flaser[3]].replace(" ", " x", 1)  # a beam count that is no number
    lines[flaser[5]] = "\x00\x01garbage\n"
    lines[flaser[7]] = lines[flaser[7]][:40] + "\n"  # cut short
    path = tmp_path / "broken.clf"
    path.write_text("".join(lines))
    damage = ReadDamage()
    scans = list(read_carmen(path, damage=damage))
    assert len(scans) == 197
    assert damage.reasons() == {"malformed FLASER line": 2, "not a CARMEN line": 1}
    # a compressed log cut in its second half: what was decoded is kept, the rest counted
    gz = tmp_path / "cut.clf.gz"
    packed = gzip.compress(text.encode())
    gz.write_bytes(packed[: len(packed) * 3 // 4])
    damage = ReadDamage()
    scans = list(read_carmen(gz, damage=damage))
    assert 100 < len(scans) < 200
    assert "broken compressed stream (the rest of the file unread)" in damage.reasons()


def test_a_damaged_bag_is_refused_in_one_line_or_its_bad_messages_counted(tmp_path, capsys):
    bag = tmp_path / "room.bag"
    write_bag(bag, n=12)
    data = bag.read_bytes()
    for j, (_, bad) in enumerate(corrupt_variants(data, seed=2)[::3]):
        path = tmp_path / f"{j:02d}.bag"
        path.write_bytes(bad)
        out = ["--out", str(tmp_path / "out"), "--max-scans", "4", "--inline", "--quiet"]
        _run_cli(["slam2d", str(path), *out], capsys)


def test_the_real_command_prints_no_traceback(mission_log, tmp_path):
    """As a user runs it, in its own process: a 3 GiB record length runs (counted), garbage is
    one line and exit 2."""
    data = bytearray(mission_log.read_bytes())
    offsets = mcap_record_offsets(bytes(data))
    struct.pack_into("<Q", data, offsets[len(offsets) // 3] + 1, 3 << 30)
    bad, garbage = tmp_path / "bad.mcap", tmp_path / "garbage.mcap"
    bad.write_bytes(bytes(data))
    garbage.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 8)
    cli = [sys.executable, "-m", "usvdrake.cli", "slam3d", "--quiet", "--json"]
    ran = subprocess.run([*cli, str(bad)], capture_output=True, text=True, timeout=120)
    assert ran.returncode == 0 and "Traceback" not in ran.stderr
    assert json.loads(ran.stdout)["skipped_records"] == 1
    refused = subprocess.run([*cli, str(garbage)], capture_output=True, text=True, timeout=120)
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1
