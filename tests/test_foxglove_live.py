"""``usvdrake run --foxglove``: a Foxglove client connected to the live server is told of the
mission log's channels (same topics and schemas) and receives their messages while the run goes."""

import asyncio
import json
import struct
import threading

import pytest
from tornado.websocket import websocket_connect

from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.logs.mission_log.live import FoxgloveLive
from usvdrake.logs.mission_log.reader import log_summary
from usvdrake.run.mission import run_mission

SUBPROTOCOL = "foxglove.sdk.v1"  # the SDK server's name for the Foxglove WebSocket protocol


class Client(threading.Thread):
    """A minimal Foxglove WebSocket client: collects advertised channels and subscribes to
    ``topic`` as soon as it is advertised, counting the binary messageData frames."""

    def __init__(self, url: str, topic: str):
        super().__init__(daemon=True)
        self.url, self.topic = url, topic
        self.channels: dict[str, dict] = {}
        self.payloads: list[bytes] = []
        self.connected = threading.Event()
        self.stop = threading.Event()

    def run(self):
        asyncio.run(self._main())

    async def _main(self):
        ws = await websocket_connect(self.url, subprotocols=[SUBPROTOCOL])
        self.connected.set()
        while not self.stop.is_set():
            try:
                msg = await asyncio.wait_for(ws.read_message(), 0.2)
            except asyncio.TimeoutError:
                continue
            if msg is None:
                break
            if isinstance(msg, str):
                data = json.loads(msg)
                if data.get("op") == "advertise":
                    for ch in data["channels"]:
                        self.channels[ch["topic"]] = ch
                        if ch["topic"] == self.topic:
                            await self._subscribe(ws, ch["id"])
                elif data.get("op") == "status" and "Unknown channel" in data.get("message", ""):
                    # the SDK server can advertise a channel a moment before it accepts a
                    # subscription to it (seen with the suite's other worker busy): ask again
                    await asyncio.sleep(0.05)
                    await self._subscribe(ws, self.channels[self.topic]["id"])
            elif msg[0] == 1:  # messageData: opcode, subscription id, log time, payload
                (sub_id,) = struct.unpack_from("<I", msg, 1)
                assert sub_id == 1
                self.payloads.append(bytes(msg[13:]))
        ws.close()

    async def _subscribe(self, ws, channel_id: int) -> None:
        sub = {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel_id}]}
        await ws.write_message(json.dumps(sub))


@pytest.mark.slow
def test_a_foxglove_client_sees_the_logs_channels_and_receives_the_pose_live(tmp_path):
    live = FoxgloveLive(port=0)
    client = Client(live.url, "/vessel_pose")
    client.start()
    assert client.connected.wait(10)
    try:
        scenario = with_overrides(load_scenario("canal_demo"), duration=20.0)
        run_mission(scenario, tmp_path, record=False, realtime_rate=5.0, live=live)
    finally:
        client.stop.set()
        client.join(5)
        live.close()
    logged = log_summary(tmp_path / "log.mcap")["topics"]
    assert {"/vessel_pose", "/tf"} <= set(client.channels) <= set(logged)
    for topic, ch in client.channels.items():  # the recorded schemas, streamed as they are
        assert ch["schemaName"] == logged[topic]["schema"] and ch["encoding"] == "json"
    assert client.channels["/vessel_pose"]["schemaName"] == "foxglove.PoseInFrame"
    assert len(client.payloads) > 20  # 4 s of wall time at the log's 10 Hz pose
    pose = json.loads(client.payloads[-1])
    assert pose["frame_id"] == "world" and "position" in pose["pose"]
    assert live.messages > len(client.payloads)
