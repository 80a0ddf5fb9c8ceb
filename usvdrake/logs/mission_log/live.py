"""Live streaming of a running mission to Foxglove (``usvdrake run --foxglove``): every channel the
mission log writes is also published on a Foxglove WebSocket server (the ``foxglove-sdk``
package), so Foxglove's app connects to ``ws://localhost:PORT`` and draws the run as it happens,
with the same schemas, topics and frames as the recorded ``log.mcap``.

Message times are the simulated times shifted to the wall clock at the start (Foxglove's live
timeline is wall time). The one channel Foxglove cannot decode, our compact range-image
encoding of ``/lidar_points``, is not streamed; its ``foxglove.PointCloud`` twin is.
"""

import json
import time

import foxglove


class FoxgloveLive:
    """A Foxglove WebSocket server on ``host:port`` (localhost only by default; port 0: any free
    one, see :attr:`port`) that mirrors what a :class:`MissionLogWriter` writes."""

    def __init__(self, port: int = 8765, host: str = "127.0.0.1"):
        self._context = foxglove.Context()
        self._server = foxglove.start_server(
            name="usvdrake", host=host, port=port, context=self._context
        )
        self._channels: dict[int, foxglove.Channel] = {}
        self._t0_ns = time.time_ns()
        self.messages = 0  # streamed so far

    @property
    def port(self) -> int:
        return self._server.port

    @property
    def url(self) -> str:
        return f"ws://localhost:{self.port}"

    def add_channel(self, channel_id: int, topic: str, schema: dict, encoding: str) -> None:
        if encoding != "json":
            return  # our binary range image: its PointCloud twin is what Foxglove draws
        fox_schema = foxglove.Schema(
            name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
        )
        self._channels[channel_id] = foxglove.Channel(
            topic, schema=fox_schema, message_encoding="json", context=self._context
        )

    def log(self, channel_id: int, log_time_ns: int, data: bytes) -> None:
        channel = self._channels.get(channel_id)
        if channel is not None:
            channel.log(data, log_time=self._t0_ns + log_time_ns)
            self.messages += 1

    def close(self) -> None:
        for channel in self._channels.values():
            channel.close()
        self._server.stop()
