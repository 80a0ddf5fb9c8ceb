"""Foxglove-ready mission logs: every ``foxglove.*`` message of a recorded mission is valid
against Foxglove's official JSON schema, and the transform tree connects the sensors to the
world (issue "What a user reads and sees", item 5)."""

import base64
import dataclasses
import json
import os
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from usvdrake import load_scenario, run_mission
from usvdrake.logs.mission_log import read_log_states, read_mission_log
from usvdrake.logs.mission_log.codecs import decode_point_cloud
from usvdrake.logs.sensor_stream import read_sensor_stream
from usvdrake.sensors.messages import PointCloud
from usvdrake.vessel import load_vessel

SCENARIOS = {"amsterdam_sensors": "lidar3d", "basin_rplidar": "lidar"}
# Foxglove's published JSON schemas, one file per message, written by `make test` from the npm
# package @foxglove/schemas (Makefile target foxglove-schemas); nothing of them is in the repo
SCHEMA_DIR = Path(
    os.environ.get(
        "USVDRAKE_FOXGLOVE_SCHEMAS", Path(__file__).resolve().parents[1] / ".venv/foxglove-schemas"
    )
)


def foxglove_schema(name: str) -> dict:
    path = SCHEMA_DIR / f"{name.removeprefix('foxglove.')}.json"
    if not path.is_file():
        pytest.skip(
            f"no Foxglove JSON schemas in {SCHEMA_DIR}: run `make foxglove-schemas` (needs npm)"
        )
    return json.loads(path.read_text())


@pytest.fixture(scope="module", params=sorted(SCENARIOS))
def mission(request, tmp_path_factory):
    scenario = dataclasses.replace(load_scenario(request.param), duration=5.0)
    out = tmp_path_factory.mktemp(request.param)
    run_mission(scenario, out_dir=out, record=False)
    return request.param, scenario, out / "log.mcap"


def _channels(path) -> dict[str, list]:
    """{topic: [(schema name, schema encoding, message encoding, log time, data)]} of every
    message, read with the mcap package itself."""
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            out.setdefault(channel.topic, []).append(
                (
                    schema.name if schema else "",
                    schema.encoding if schema else "",
                    channel.message_encoding,
                    message.log_time,
                    message.data,
                )
            )
    return out


def test_every_foxglove_message_is_valid_against_the_official_schema(mission):
    name, _, log = mission
    channels = _channels(log)
    validators = {}
    checked = set()
    for topic, messages in channels.items():
        for schema, schema_encoding, encoding, _, data in messages:
            if not schema.startswith("foxglove."):
                continue
            assert (schema_encoding, encoding) == ("jsonschema", "json"), topic
            if schema not in validators:
                official = foxglove_schema(schema)
                cls = jsonschema.validators.validator_for(official)
                cls.check_schema(official)
                validators[schema] = cls(official)
            validators[schema].validate(json.loads(data))
            checked.add(schema)
    wanted = {"foxglove.FrameTransform", "foxglove.PoseInFrame", "foxglove.SceneUpdate"}
    wanted |= {"foxglove.PointCloud"} if name == "amsterdam_sensors" else {"foxglove.LaserScan"}
    assert wanted <= checked


def test_every_other_json_channel_is_valid_against_the_schema_it_declares(mission):
    """Our own channels (usvdrake.*) carry a JSON Schema that Foxglove reads to show their
    fields (Raw Messages, Plot panels): every message must match it. The one binary channel,
    the range image, has a foxglove.PointCloud twin for display."""
    _, _, log = mission
    validators, binary, topics, checked = {}, set(), set(), 0
    with open(log, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            topics.add(channel.topic)
            if schema.name.startswith("foxglove."):
                continue
            assert schema.encoding == "jsonschema", channel.topic
            if channel.message_encoding != "json":
                binary.add(channel.topic)
                continue
            if schema.id not in validators:
                declared = json.loads(schema.data)
                cls = jsonschema.validators.validator_for(declared)
                cls.check_schema(declared)
                validators[schema.id] = cls(declared)
            validators[schema.id].validate(json.loads(message.data))
            checked += 1
    assert checked > 100
    for topic in binary:
        assert f"{topic}_foxglove" in topics, f"{topic} has no channel Foxglove can draw"


def test_the_transform_tree_connects_the_lidar_to_the_world(mission):
    name, scenario, log = mission
    channels = _channels(log)
    parents: dict[str, str] = {}
    static: dict[str, dict] = {}
    world_to_body = []
    for _, _, _, _, data in channels["/tf"]:
        m = json.loads(data)
        parents[m["child_frame_id"]] = m["parent_frame_id"]
        if m["parent_frame_id"] == "base_link":
            static[m["child_frame_id"]] = m
        else:
            world_to_body.append(m)
    lidar = SCENARIOS[name]
    frame, chain = lidar, [lidar]
    while frame in parents:
        frame = parents[frame]
        chain.append(frame)
    assert chain == [lidar, "base_link", "world"]
    # the static mounts are the scenario's
    mount = getattr(scenario.sensors, "lidar3d" if lidar == "lidar3d" else "lidar2d").mount
    t = static[lidar]["translation"]
    np.testing.assert_allclose([t["x"], t["y"], t["z"]], mount[:3])
    assert set(static) == {lidar, "imu"} | ({"gps"} if name == "amsterdam_sensors" else set())
    # world → base_link at the recorder's rate, from the ground truth
    times, states = read_log_states(log, "/ground_truth")
    assert len(world_to_body) == len(times)
    xy = np.array([[m["translation"]["x"], m["translation"]["y"]] for m in world_to_body])
    np.testing.assert_allclose(xy, states[:, :2])
    yaw = [2 * np.arctan2(m["rotation"]["z"], m["rotation"]["w"]) for m in world_to_body]
    np.testing.assert_allclose(np.cos(yaw), np.cos(states[:, 2]), atol=1e-12)
    # the sensor messages name the frames
    if lidar == "lidar3d":
        frames = {json.loads(d)["frame_id"] for *_, d in channels["/lidar_points_foxglove"]}
    else:
        frames = {json.loads(d)["frame_id"] for *_, d in channels["/lidar_scan"]}
    assert frames == {lidar}


def test_the_vessel_pose_and_hull(mission):
    _, scenario, log = mission
    channels = _channels(log)
    times, states = read_log_states(log, "/ground_truth")
    poses = [json.loads(d) for *_, d in channels["/vessel_pose"]]
    assert len(poses) == len(times) and {p["frame_id"] for p in poses} == {"world"}
    hull = channels["/vessel_hull"]
    assert len(hull) == 1
    (entity,) = json.loads(hull[0][-1])["entities"]
    assert entity["frame_id"] == "base_link" and entity["frame_locked"]
    (cube,) = entity["cubes"]
    h = load_vessel(scenario.vessel).hull
    assert (cube["size"]["x"], cube["size"]["y"]) == (h.length, h.beam)


def test_the_foxglove_cloud_matches_the_range_image_and_our_readers_still_read(mission):
    name, _, log = mission
    channels = _channels(log)
    if name != "amsterdam_sensors":  # no 3D lidar
        assert "/lidar_points_foxglove" not in channels
        return
    previews = channels["/lidar_points_foxglove"]
    sweeps = {
        round(t, 6): m for _, t, m in read_mission_log(log, ["/lidar_points"])
    }  # our own reader: still the range image
    assert all(isinstance(m, PointCloud) for m in sweeps.values())
    assert 1 <= len(previews) < len(sweeps)  # at most 1 Hz of the 10 Hz sweeps
    for *_, log_time, data in previews:
        m = json.loads(data)
        assert m["point_stride"] == 16
        assert [f["name"] for f in m["fields"]] == ["x", "y", "z", "time"]
        assert len(base64.b64decode(m["data"])) % 16 == 0
        pts = decode_point_cloud(data)
        sweep = sweeps[round(log_time * 1e-9, 6)]
        assert len(pts) == np.isfinite(sweep.range_image).sum() > 0
        # the same returns (ours on the nominal beam directions, 1 mm range quantum)
        r_fox = np.sort(np.linalg.norm(pts[:, :3], axis=1))
        r_ours = np.sort(sweep.range_image[np.isfinite(sweep.range_image)])
        np.testing.assert_allclose(r_fox, r_ours, atol=2e-3)
    stream = list(read_sensor_stream(log))
    assert {m.kind for m in stream} == {"lidar", "imu", "gps"}
