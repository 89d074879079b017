"""Live view in Foxglove (live.foxglove=true): a real run serves what it records over the Foxglove
SDK's WebSocket server; a plain WebSocket client speaking Foxglove's protocol receives camera
images and transforms, byte-identical to the bag. The shipped layout names only what a default
recording has."""

from __future__ import annotations

import json
import re
import socket
import struct
import subprocess
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import IO, Any

import cv2
import numpy as np
import pytest
import tomllib
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from conftest import REPO, run_cli
from simlan_data.errors import EXIT_BAD_INPUT, ConfigError
from simlan_data.recording import schema
from simlan_data.viz.foxglove_layout import LAYOUT_FILENAME, PACKAGED_LAYOUT, build_layout

SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk 0.30's server speaks (the app offers it)
MESSAGE_DATA = 0x01  # binary opcode: u32 subscription id, u64 log time, payload
SMALL = ("cameras=gpss", "cameras.count=2", "cameras.width=480", "cameras.height=270", "progress=false")
CAMERA = "/camera_160/image_raw/compressed"
WANTED = (CAMERA, "/camera_160/camera_info", schema.TF, schema.TF_STATIC)


class Console:
    """One output stream of a run, read on a thread as it comes (the test waits for a line)."""

    def __init__(self, stream: IO[str]) -> None:
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._reader.start()

    def _read(self, stream: IO[str]) -> None:
        for line in stream:
            self.lines.append(line)

    def served_port(self, *, within_s: float) -> int:
        """The port of ``live view on ws://HOST:PORT``: with live.port=0 the run binds any free
        port and prints which (a port chosen here and then bound by the run could be taken in
        between, by a test running in parallel for one)."""
        deadline = time.monotonic() + within_s
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if found := re.search(r"live view on ws://[^\s/]+:(\d+)\b", line):
                    return int(found.group(1))
            if not self._reader.is_alive():
                break
            time.sleep(0.1)
        raise OSError(f"the run did not say where it serves the live view (waited up to {within_s:.0f} s)")

    def text(self) -> str:
        self._reader.join(timeout=10)
        return "".join(self.lines)


class Client:
    """A Foxglove WebSocket client: subscribes to topics as they are advertised, keeps what comes."""

    def __init__(
        self, port: int, topics: tuple[str, ...], stack: ExitStack, *, within_s: float = 90.0
    ) -> None:
        deadline = time.monotonic() + within_s
        while True:  # the run starts its server after checking its inputs: wait for it
            try:
                self.ws: ClientConnection = stack.enter_context(
                    connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=5)  # type: ignore[list-item]
                )
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        self.topics = topics
        self.channels: dict[str, dict[str, Any]] = {}  # topic -> advertised channel
        self.by_subscription: dict[int, str] = {}
        self.subscribed_at: dict[str, float] = {}  # topic -> when it was (last) subscribed
        self.received: dict[str, list[tuple[int, bytes]]] = {t: [] for t in topics}
        self.server_info: dict[str, Any] = {}

    def receive_until(self, done: Any, *, within_s: float) -> None:
        deadline = time.monotonic() + within_s
        while not done(self) and time.monotonic() < deadline:
            try:
                frame = self.ws.recv(timeout=max(0.05, min(1.0, deadline - time.monotonic())))
            except TimeoutError:
                self._subscribe_again()
                continue
            except ConnectionClosed:  # (the run ended: its server closed)
                break
            if isinstance(frame, str):
                self._control(json.loads(frame))
            elif frame[0] == MESSAGE_DATA:
                sub, log_time = struct.unpack_from("<IQ", frame, 1)
                self.received[self.by_subscription[sub]].append((log_time, bytes(frame[13:])))
            self._subscribe_again()

    def _subscribe_again(self) -> None:
        """A subscription that got nothing for 3 s is made again, as Foxglove does when a panel
        re-subscribes: foxglove-sdk 0.30 now and then refuses a subscription that races the
        channel's advertisement ("attempted to subscribe to unknown channel", seen under load
        only); the server's listener then sends a latched topic's last message again."""
        now = time.monotonic()
        for topic, since in list(self.subscribed_at.items()):
            if not self.received[topic] and now - since > 3.0:
                sub = len(self.by_subscription) + 1
                self.by_subscription[sub] = topic
                self.subscribed_at[topic] = now
                channel_id = self.channels[topic]["id"]
                self.ws.send(
                    json.dumps({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": channel_id}]})
                )

    def _control(self, msg: dict[str, Any]) -> None:
        if msg["op"] == "serverInfo":
            self.server_info = msg
        elif msg["op"] == "advertise":
            subscribe = []
            for channel in msg["channels"]:
                if channel["topic"] in self.topics and channel["topic"] not in self.channels:
                    self.channels[channel["topic"]] = channel
                    sub = len(self.by_subscription) + 1
                    self.by_subscription[sub] = channel["topic"]
                    self.subscribed_at[channel["topic"]] = time.monotonic()
                    subscribe.append({"id": sub, "channelId": channel["id"]})
            if subscribe:
                self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscribe}))

    def has_all(self) -> bool:
        return all(self.received[t] for t in self.topics)

    def decode(self, topic: str, data: bytes) -> Any:
        """Decode with the schema the server advertised (not the package's own types)."""
        channel = self.channels[topic]
        assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg"
        record = Schema(id=1, name=channel["schemaName"], encoding="ros2msg", data=channel["schema"].encode())
        decoder = DecoderFactory().decoder_for("cdr", record)
        assert decoder is not None
        return decoder(data)


def _bag(run_dir: Path) -> tuple[dict[str, list[tuple[int, bytes]]], dict[str, bytes]]:
    """Every message of the run's bag by topic (log time, bytes), and each topic's schema text."""
    (path,) = (run_dir / "recording").glob("*.mcap")
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        schemas = {c.topic: summary.schemas[c.schema_id].data for c in summary.channels.values()}
        out: dict[str, list[tuple[int, bytes]]] = {}
        for _, channel, message in reader.iter_messages():
            out.setdefault(channel.topic, []).append((message.log_time, message.data))
    return out, schemas


@pytest.fixture(scope="module")
def live_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Client, Client, subprocess.Popen[str]]:
    """A real run served live (at the wall clock's pace, 5 s); one client from the start, and one
    that connects once the simulation has been running (the latched topics were published then)."""
    run_dir = tmp_path_factory.mktemp("live") / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "simlan_data.run", *SMALL, "duration_s=5", f"hydra.run.dir={run_dir}"]
        + ["live.foxglove=true", "live.port=0", "live.realtime=true"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None and proc.stderr is not None
    out, errors = Console(proc.stdout), Console(proc.stderr)
    got: dict[str, int] = {}
    try:
        port = out.served_port(within_s=180)  # (a loaded machine starts slowly)
        with ExitStack() as stack:
            early = Client(port, WANTED, stack, within_s=30)
            early.receive_until(Client.has_all, within_s=90)
            got = {t: len(v) for t, v in early.received.items()}
            late = Client(port, (schema.TF_STATIC, schema.CONFIG), stack, within_s=0)  # the run is under way
            late.receive_until(Client.has_all, within_s=10)
        proc.wait(timeout=120)
    except OSError as err:
        proc.kill()
        proc.wait()
        raise AssertionError(
            f"{err}; the first client got {got}; the run said: {out.text()[-2000:]} {errors.text()[-2000:]}"
        ) from err
    finally:
        proc.kill()
    return run_dir, early, late, proc


def test_a_live_run_streams_camera_and_tf_messages_as_recorded(live_run: Any) -> None:
    run_dir, early, _, proc = live_run
    assert proc.returncode == 0
    assert early.has_all(), {t: len(v) for t, v in early.received.items()}
    assert "time" in early.server_info["capabilities"]  # the simulated clock drives the viewer
    bag, schemas = _bag(run_dir)
    for topic in WANTED:  # same topic, same bytes at the same log time, same schema as the bag
        assert early.channels[topic]["schema"].encode() == schemas[topic]
        assert set(early.received[topic]) <= set(bag[topic]), topic
    image = early.decode(CAMERA, early.received[CAMERA][-1][1])
    assert "jpeg" in image.format and image.header.frame_id == schema.camera_frame(160)
    pixels = cv2.imdecode(np.frombuffer(bytes(image.data), np.uint8), cv2.IMREAD_COLOR)
    assert pixels.shape == (270, 480, 3) and pixels.std() > 10  # a real picture, not a blank
    tf = early.decode(schema.TF, early.received[schema.TF][-1][1])
    (moved,) = tf.transforms
    assert (moved.header.frame_id, moved.child_frame_id) == (
        schema.odom_frame("robot_agent_1"),
        schema.base_link_frame("robot_agent_1"),
    )
    assert np.isfinite([moved.transform.translation.x, moved.transform.rotation.w]).all()


def test_a_client_that_connects_late_still_gets_the_latched_topics(live_run: Any) -> None:
    run_dir, early, late, _ = live_run
    bag, _ = _bag(run_dir)
    # the late client connected after the first had an image, so after /tf_static was published
    assert bag[schema.TF_STATIC][0][0] <= early.received[CAMERA][0][0]
    assert late.received[schema.TF_STATIC] and late.received[schema.CONFIG]
    assert late.received[schema.TF_STATIC][0] == bag[schema.TF_STATIC][0]  # published once, at the start
    static = late.decode(schema.TF_STATIC, late.received[schema.TF_STATIC][0][1])
    children = {t.child_frame_id for t in static.transforms}
    assert {schema.camera_frame(160), schema.camera_frame(161)} <= children


def test_a_taken_port_is_refused_in_one_line_before_anything_is_written(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        run_dir = tmp_path / "run"
        proc = run_cli(
            *SMALL, "duration_s=1", f"hydra.run.dir={run_dir}", "live.foxglove=true", f"live.port={port}"
        )
    assert proc.returncode == EXIT_BAD_INPUT, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"cannot serve the live view on 127.0.0.1:{port}" in lines[0], proc.stderr
    assert "live.port" in lines[0] and not run_dir.exists()


def test_without_the_sdk_the_live_view_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    from simlan_data.config.live import LiveConfig
    from simlan_data.viz.foxglove_live import LiveView

    monkeypatch.setitem(sys.modules, "foxglove", None)  # what Python does when it is not installed
    with pytest.raises(ConfigError) as caught:
        LiveView(LiveConfig(foxglove=True, port=0), name="default")
    line = caught.value.line()
    assert caught.value.exit_code == EXIT_BAD_INPUT and "\n" not in line
    assert 'pip install -e ".[live]"' in line and "foxglove-sdk is not installed" in line


def test_the_sdk_is_an_extra_that_the_tests_install() -> None:
    extras = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert not [d for d in extras["dependencies"] if d.startswith("foxglove")]
    assert extras["optional-dependencies"]["live"] == ["foxglove-sdk>=0.30,<0.31"]
    assert "simlan-data[live]" in extras["optional-dependencies"]["test"]


# ------------------------------------------------------------------------------------- layout
def _topic_of(path: str, topics: set[str]) -> str:
    """The topic a Foxglove message path starts with (the longest recorded name that prefixes it)."""
    return max((t for t in topics if path == t or path.startswith(t + ".")), key=len, default=path)


def test_a_live_run_writes_the_layout_of_its_recordings_topics(live_run: Any) -> None:
    run_dir, *_ = live_run
    bag, _ = _bag(run_dir)
    assert json.loads((run_dir / LAYOUT_FILENAME).read_text()) == build_layout(bag)


def test_the_packaged_layout_is_the_default_runs_and_names_only_recorded_topics(short_run: Path) -> None:
    """Regenerate the packaged layout from a default run (`python -m simlan_data.run duration_s=3`)
    with: python -m simlan_data.view RUN_DIR --foxglove-layout simlan_data/viz/foxglove_layout.json
    (remove the old file first)."""
    layout = json.loads(PACKAGED_LAYOUT.read_text())
    bag, _ = _bag(short_run)
    assert layout == build_layout(bag)
    recorded = set(bag)
    panels = layout["configById"]
    named: set[str] = set()
    for panel_id, config in panels.items():
        if panel_id.startswith("Image!"):
            named |= {config["imageMode"]["imageTopic"], config["imageMode"]["calibrationTopic"]}
        elif panel_id.startswith("3D!"):
            named |= set(config["topics"])
        elif panel_id.startswith("Plot!"):
            for series in config["paths"]:
                if not series["value"].startswith("/foxglove_script/"):  # a user script's output
                    named.add(_topic_of(series["value"], recorded))
    for script in layout["userNodes"].values():
        inputs = json.loads(script["sourceCode"].split("export const inputs = ", 1)[1].split(";", 1)[0])
        named |= set(inputs)
    assert named - recorded == set()
    cameras = {t.split("/")[1] for t in named if t.startswith("/camera_")}
    assert len(cameras) == 11  # every camera of the default set, RGB, depth and labels
    assert any("/depth/" in t for t in named) and any("/semantic/" in t for t in named)


def test_the_layouts_message_paths_and_frames_resolve_on_recorded_messages(short_run: Path) -> None:
    """Plot paths walk fields that the recorded messages have; the error script's ground-truth
    frame is one /ground_truth/poses carries."""
    layout = json.loads(PACKAGED_LAYOUT.read_text())
    (path,) = (short_run / "recording").glob("*.mcap")
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        first: dict[str, Any] = {}
        for _, channel, _, msg in reader.iter_decoded_messages():
            first.setdefault(channel.topic, msg)
    for config in layout["configById"].values():
        for series in config.get("paths", []):
            if series["value"].startswith("/foxglove_script/"):
                continue
            topic = _topic_of(series["value"], set(first))
            value = first[topic]
            for field in series["value"][len(topic) + 1 :].split("."):
                value = getattr(value, field)
            assert isinstance(value, float), series["value"]
    frames = {t.child_frame_id for t in first[schema.GROUND_TRUTH_POSES].transforms}
    for script in layout["userNodes"].values():
        frame = script["sourceCode"].split('const TRUTH_FRAME = "', 1)[1].split('"', 1)[0]
        assert frame in frames
