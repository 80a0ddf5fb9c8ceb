"""What a mission log holds besides its signals, so that a replay can be measured as the run was:
the scenario (``/scenario``, its complete YAML, written at the start) and the run's final values
(``/run_summary``, written at the end: diagnostics vectors, the SLAM's summary, the final map).

Values are JSON with float64 written exactly (``repr``), arrays as lists, an occupancy grid's
cells as base64 bytes; :func:`read_run_summary` turns them back into the objects the metrics
take (:class:`~usvdrake.systems.slam.slam_summary.Slam2DSummary`, ...).
"""

import base64
import dataclasses
import json
from pathlib import Path

import numpy as np

from usvdrake.logs.mission_log import MissionLogWriter, read_mission_log
from usvdrake.systems.slam.slam_summary import Slam2DSummary, Slam3DSummary
from usvdrake.worlds.world import OccupancyGrid

SCENARIO_TOPIC = "/scenario"
RUN_SUMMARY_TOPIC = "/run_summary"
_SCHEMA = {"type": "object"}  # free-form: the reader below is the only consumer
_TYPES = {"Slam2DSummary": Slam2DSummary, "Slam3DSummary": Slam3DSummary}


def _encode(value):
    if isinstance(value, Slam2DSummary | Slam3DSummary):
        fields = {f.name: _encode(getattr(value, f.name)) for f in dataclasses.fields(value)}
        return {"__type__": type(value).__name__, **fields}
    if isinstance(value, OccupancyGrid):
        data = np.ascontiguousarray(value.data, np.int8)
        return {
            "__type__": "OccupancyGrid",
            "origin": [float(v) for v in value.origin],
            "resolution": float(value.resolution),
            "shape": list(data.shape),
            "data": base64.b64encode(data.tobytes()).decode(),
        }
    if isinstance(value, np.ndarray):
        return {"__type__": "ndarray", "dtype": str(value.dtype), "value": value.tolist()}
    if isinstance(value, dict):
        return {str(k): _encode(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_encode(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _decode(value):
    if isinstance(value, list):
        return [_decode(v) for v in value]
    if not isinstance(value, dict):
        return value
    kind = value.get("__type__")
    if kind == "ndarray":
        return np.array(value["value"], dtype=value["dtype"])
    if kind == "OccupancyGrid":
        data = np.frombuffer(base64.b64decode(value["data"]), np.int8).reshape(value["shape"])
        return OccupancyGrid(tuple(value["origin"]), value["resolution"], data.copy())
    if kind in _TYPES:
        fields = {k: _decode(v) for k, v in value.items() if k != "__type__"}
        return _TYPES[kind](**fields)
    return {k: _decode(v) for k, v in value.items()}


def write_scenario(writer: MissionLogWriter, yaml_text: str) -> None:
    """The run's complete scenario (what :func:`read_run_summary` rebuilds it from)."""
    channel = writer.channel(SCENARIO_TOPIC, {"title": "usvdrake.Scenario", **_SCHEMA})
    writer.write(channel, 0.0, json.dumps({"t": 0.0, "yaml": yaml_text}).encode())


def write_run_summary(writer: MissionLogWriter, t: float, finals: dict) -> None:
    """The run's final values at simulated time ``t`` [s] (``finals``: port name → value)."""
    channel = writer.channel(RUN_SUMMARY_TOPIC, {"title": "usvdrake.RunSummary", **_SCHEMA})
    message = {"t": float(t), "finals": _encode(finals)}
    writer.write(channel, float(t), json.dumps(message).encode())


def read_run_summary(path: str | Path) -> tuple[str | None, dict | None]:
    """(scenario YAML, final values) of a mission log; None for what it does not hold (a log
    cut short before the run ended has no summary)."""
    yaml_text, finals = None, None
    for topic, _, message in read_mission_log(path, [SCENARIO_TOPIC, RUN_SUMMARY_TOPIC]):
        if topic == SCENARIO_TOPIC:
            yaml_text = message["yaml"]
        else:
            finals = _decode(message["finals"])
    return yaml_text, finals
