"""Serve a running simulation to Foxglove: what the recording writes, live, over a WebSocket.

The Foxglove SDK's WebSocket server (``foxglove-sdk``, the ``live`` extra) publishes each message
the recording writes, on the same topic, with the same ROS 2 CDR bytes and the same ``ros2msg``
schema the bag embeds, so a Foxglove layout made for the recordings works live too::

    simulation -> RecordingWriter --(file thread: add_listener)--> LiveView.on_message
                                                                     | channel per topic (cdr, ros2msg)
                                                                     v
                  Foxglove app <--- ws://host:port <--- foxglove.start_server (its own threads)
                                          |
                  client subscribes ------+--> on_subscribe: the latched topics' last message again

Nobody connected: a channel's ``log`` returns at once (the SDK drops messages that no client
subscribed to), so the run keeps its speed (docs/foxglove.md has the measurement).
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any

from simlan_data.config.live import LiveConfig
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError
from simlan_data.recording.schema import CLOCK, LATCHED_TOPICS
from simlan_data.viz.foxglove_layout import build_layout, write_layout

log = logging.getLogger(__name__)

CDR = "cdr"  # message encoding of every channel (as in the bag)
LAYOUT_AFTER_NS = NS_PER_S  # every camera stream has a message in the first simulated second


def _foxglove() -> Any:
    """The Foxglove SDK, an optional install (``pip install -e ".[live]"``); without it one line says so."""
    try:
        import foxglove
    except ImportError as err:
        raise ConfigError(
            "live.foxglove=true needs the Foxglove SDK",
            "this installation",
            f"foxglove-sdk is not installed ({err})",
            'install the live extra: pip install -e ".[live]" (or set live.foxglove=false)',
        ) from None
    return foxglove


class LiveView:
    """A Foxglove WebSocket server fed by a recording writer's listener (``on_message``)."""

    def __init__(self, cfg: LiveConfig, *, name: str, layout_path: Path | None = None) -> None:
        """Start the server on ``cfg.host:cfg.port``; write the Foxglove layout for the run's
        topics to ``layout_path`` once the first simulated second is written (every camera
        stream has been then), and again at the end (topics that began later).

        Raises:
            ConfigError: the SDK is missing, or the address cannot be bound (port taken).
        """
        fg = _foxglove()
        from foxglove.websocket import Capability

        # the SDK logs its start and stop at INFO; the run says where the server is in its own line
        logging.getLogger("foxglove").setLevel(max(logging.WARNING, logging.getLogger("foxglove").level))

        self._fg = fg
        self._context = fg.Context()  # this run's channels only
        self._channels: dict[str, Any] = {}
        self._latched: dict[str, tuple[int, bytes]] = {}  # topic -> (log time, bytes) of its last message
        self._lock = threading.Lock()  # the file thread adds channels, the server's threads read them
        self._failed = False
        self._pace_origin: tuple[float, float] | None = None  # (wall s, simulated s) when pacing began
        self.realtime = cfg.realtime
        self.layout_path = layout_path
        self._topics: set[str] = set()
        self._first_ns: int | None = None
        self._layout_due = layout_path is not None
        try:
            self.server = fg.start_server(
                name=f"simlan_data {name}",
                host=cfg.host,
                port=cfg.port,
                capabilities=[Capability.Time],  # the simulated clock is the viewer's clock
                server_listener=self,
                context=self._context,
            )
        except RuntimeError as err:  # the SDK says FoxgloveError: Failed to bind port: ...
            why = str(err).removeprefix("FoxgloveError: ")
            raise ConfigError(
                f"cannot serve the live view on {cfg.host}:{cfg.port}",
                "live.host/live.port",
                why,
                "choose another live.port (0: any free port) or stop what uses it",
            ) from None
        self.port = int(self.server.port)
        self.host = cfg.host

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    # ---------------------------------------------------------------- the recording's listener
    def on_message(self, connection: Any, log_time_ns: int, data: bytes) -> None:
        """Publish one written message (on the recording's file thread; never raises into it)."""
        if self._failed:
            return
        try:
            topic = connection.topic
            channel = self._channels.get(topic)
            if channel is None:
                channel = self._channel(topic, connection.msgtype, connection.msgdef.data)
                self._topics.add(topic)
            if self._layout_due:
                self._first_ns = log_time_ns if self._first_ns is None else self._first_ns
                if log_time_ns - self._first_ns >= LAYOUT_AFTER_NS:
                    self._write_layout()
            if topic in LATCHED_TOPICS:
                with self._lock:
                    self._latched[topic] = (log_time_ns, data)
            channel.log(data, log_time=log_time_ns)
            if topic == CLOCK:
                self.server.broadcast_time(log_time_ns)
        except Exception as err:  # the recording matters more than the view: keep recording
            self._failed = True
            log.warning(
                "live view stopped publishing (the recording goes on): %s: %s", type(err).__name__, err
            )

    def _channel(self, topic: str, msgtype: str, msgdef: str) -> Any:
        schema = self._fg.Schema(name=msgtype, encoding="ros2msg", data=msgdef.encode())
        channel = self._fg.Channel(topic, message_encoding=CDR, schema=schema, context=self._context)
        with self._lock:
            self._channels[topic] = channel
        return channel

    # ------------------------------------------------------------- the server's listener
    def on_subscribe(self, client: Any, channel: Any) -> None:  # noqa: ARG002 - SDK signature
        """A client subscribed: give it the last message of a latched topic (a ROS latched
        publisher's behaviour: /tf_static, the config, the labels... are published once). The
        SDK cannot address one client, so the channel's other subscribers get it again too."""
        with self._lock:
            last = self._latched.get(channel.topic)
            target = self._channels.get(channel.topic)
        if last is not None and target is not None:
            target.log(last[1], log_time=last[0])

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        """Nothing to do (the SDK calls every listener method; a missing one logs an error)."""

    # -------------------------------------------------------------------------- pacing
    def pace(self, simulated_s: float) -> None:
        """With ``live.realtime``: wait until the wall clock has caught up with the simulated one."""
        if not self.realtime:
            return
        now = time.monotonic()
        if self._pace_origin is None:
            self._pace_origin = (now, simulated_s)
            return
        wall0, sim0 = self._pace_origin
        ahead = (simulated_s - sim0) - (now - wall0)
        if ahead > 0:
            time.sleep(ahead)

    def _write_layout(self) -> None:
        self._layout_due = False
        if self.layout_path is not None:
            write_layout(self.layout_path, build_layout(self._topics))

    def close(self) -> None:
        """Stop the server (clients are disconnected; the recording stays for Foxglove to open)
        and write the layout for every topic the run wrote."""
        self.server.stop()
        if self.layout_path is not None and self._topics:
            self._write_layout()
