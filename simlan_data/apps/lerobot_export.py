"""``python -m simlan_data.export RUN --format lerobot --out DIR [--agent NS] [--task TEXT]``: a
recording as a LeRobot dataset (format v3.0, the layout of ``lerobot`` 0.4; issue 25).

    DIR/meta/info.json                                   features, fps, paths (codebase_version v3.0)
    DIR/meta/stats.json                                  min / max / mean / std / count per feature
    DIR/meta/tasks.parquet                               the task string -> task_index 0
    DIR/meta/episodes/chunk-000/file-000.parquet         one episode: its rows and video spans
    DIR/data/chunk-000/file-000.parquet                  one row per frame
    DIR/videos/observation.images.camera_<id>/chunk-000/file-000.mp4   one AV1 video per camera

One episode per recording, of one agent (``--agent``, default the recording's first agent with a
command topic). A frame is one camera tick at which every camera delivered an image (ticks a
camera lost are left out and counted); its columns:

- ``observation.images.camera_<id>``: the colour image, a video frame (AV1 by PyAV, LeRobot's own
  encoder settings: libsvtav1, yuv420p, GOP 2, CRF 30, preset 12);
- ``observation.state``: the agent's ground truth at the frame's stamp, ``x_m, y_m, yaw_rad`` in
  ``map`` from /ground_truth/poses, and ``v_mps, w_radps`` (forward speed and yaw rate in
  base_link) from its two latest ground-truth poses;
- ``action``: the agent's latest /<agent>/cmd_vel at or before the stamp, ``v_mps, w_radps``
  (zeros before the first command);
- ``stamp_ns``: the frame's bag time (the newest of its images' header stamps); ``timestamp`` is
  ``frame_index / fps`` as LeRobot requires, fps the recorded ``cameras.rate_hz``.

Data flow (streamed: one tick's compressed images in memory, each video written frame by frame)::

    bag, time order --/ground_truth/poses, /<agent>/cmd_vel--> _Agent (latest poses, command)
                    --/camera_<id>/image--> pending {tick: {camera: message}}
                          --every camera, and the bag past the tick's stamp--> _Episode.add:
                             decode -> one frame per camera video, one parquet row, running stats

The ``lerobot`` package itself pins torch < 2.11 and CUDA wheels, so it is not a dependency: the
files follow its v3.0 layout (``lerobot/datasets/utils.py``: paths, info, episodes), written with
the libraries it reads them with (pyarrow, pandas, PyAV), and ``tests/test_export_lerobot.py``
reads them back with those; ``LeRobotDataset(repo_id, root=DIR)`` loads them where lerobot is
installed.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError, RecordingInputError, RunError
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import schema
from simlan_data.recording.bounded import load_yaml_without_aliases
from simlan_data.recording.messages import stamp_ns_of
from simlan_data.recording.reader import RecordingReader

__all__ = ["CODEBASE_VERSION", "INFO_PATH", "LerobotExport", "export_lerobot", "video_key"]

CODEBASE_VERSION = "v3.0"  # lerobot's LeRobotDataset reads this layout (lerobot >= 0.4)
INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
TASKS_PATH = "meta/tasks.parquet"
EPISODES_PATH = "meta/episodes/chunk-000/file-000.parquet"
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
STATE_NAMES = ["x_m", "y_m", "yaw_rad", "v_mps", "w_radps"]
ACTION_NAMES = ["v_mps", "w_radps"]
# lerobot's encode_video_frames defaults (video_utils.py): what its own recordings hold
VIDEO_CODEC, VIDEO_PIX_FMT, VIDEO_OPTIONS = "libsvtav1", "yuv420p", {"g": "2", "crf": "30", "preset": "12"}
ROW_GROUP = 1000  # parquet rows buffered before a row group is written
_STALE_TICKS_S = 1.0  # an incomplete tick this much older than the newest is given up


def video_key(camera_id: str) -> str:
    """The LeRobot feature key of a camera."""
    return f"observation.images.camera_{camera_id}"


@dataclass(frozen=True)
class LerobotExport:
    """What an export wrote: frames, left-out ticks, the agent, fps."""

    frames: int
    incomplete_ticks: int
    agent: str
    fps: int


# --------------------------------------------------------------------------------- inputs


def _camera_ids(reader: RecordingReader) -> dict[str, str]:
    """colour topic -> camera id, cameras in id order."""
    out = {}
    for name in sorted(reader.topics):
        if name.startswith("/camera_") and name.endswith(("/image_raw", "/image_raw/compressed")):
            cid = name[len("/camera_") :].split("/")[0]
            if name in (
                schema.camera_topics(cid, rgb=r, depth=None, semantic=None)["rgb"].name
                for r in ("raw", "jpeg")
            ):
                out[name] = cid
    if not out:
        raise RecordingInputError(
            "no colour images",
            str(reader.path),
            "the run recorded no camera stream rgb",
            "record with cameras.streams=[rgb]",
        )
    return out


def _agents(reader: RecordingReader) -> list[str]:
    """The agents with a command topic, in the ground truth's order."""
    first = reader.first(schema.GROUND_TRUTH_POSES)
    if first is None:
        raise RecordingInputError(
            "no ground truth",
            str(reader.path),
            f"{schema.GROUND_TRUTH_POSES} is missing",
            "export a run recorded by simlan_data.run",
        )
    names = [schema.ground_truth_namespace(t.child_frame_id) for t in first.msg.transforms]
    return [ns for ns in names if schema.agent_topics(ns)["cmd_vel"].name in reader.topics]


def _fps(reader: RecordingReader) -> int:
    """The camera rate of the recorded config, which LeRobot needs as a whole number."""
    msg = reader.first(schema.CONFIG)
    cfg = load_yaml_without_aliases(str(msg.msg.data)) if msg is not None else None
    rate = cfg.get("cameras", {}).get("rate_hz") if isinstance(cfg, dict) else None
    if not isinstance(rate, int | float) or rate <= 0 or rate != round(rate):
        raise RecordingInputError(
            f"camera rate {rate!r}",
            f"{reader.path} /simlan/config",
            "LeRobot datasets have a whole number of frames per second",
            "record with a whole cameras.rate_hz (e.g. 5)",
        )
    return int(rate)


def _rgb(msg: Any) -> NDArray[np.uint8]:
    """The RGB pixels (H, W, 3) of a colour image message, compressed or raw."""
    if hasattr(msg, "format"):
        image = cv2.imdecode(np.asarray(msg.data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            raise RunError(
                "undecodable colour image", "export", f"format {msg.format!r}", "check the recording"
            )
        return np.asarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB), dtype=np.uint8)  # OpenCV decodes BGR
    data = np.asarray(msg.data, dtype=np.uint8).reshape(int(msg.height), int(msg.step))
    image = data[:, : 3 * int(msg.width)].reshape(int(msg.height), int(msg.width), 3)
    rgb = cv2.cvtColor(image, cv2.COLOR_BGR2RGB) if msg.encoding == "bgr8" else np.ascontiguousarray(image)
    return np.asarray(rgb, dtype=np.uint8)


def _pose(t: Any) -> tuple[float, float, float]:
    tr, r = t.translation, t.rotation
    pose = Transform.from_quat([tr.x, tr.y, tr.z], [r.x, r.y, r.z, r.w])
    return float(pose.translation[0]), float(pose.translation[1]), pose.yaw()


@dataclass
class _Agent:
    """The agent's two latest ground-truth poses (stamp, x, y, yaw) and latest command."""

    namespace: str
    poses: list[tuple[int, float, float, float]] = field(default_factory=list)
    command: tuple[float, float] = (0.0, 0.0)

    def on_poses(self, msg: Any) -> None:
        for t in msg.transforms:
            if schema.ground_truth_namespace(t.child_frame_id) == self.namespace:
                self.poses = [*self.poses[-1:], (stamp_ns_of(t.header.stamp), *_pose(t.transform))]

    def on_command(self, msg: Any) -> None:
        self.command = (float(msg.twist.linear.x), float(msg.twist.angular.z))

    def state(self) -> list[float]:
        """x, y, yaw of the latest pose; v, w from the two latest (zeros with one)."""
        if not self.poses:
            return [math.nan] * len(STATE_NAMES)
        t1, x1, y1, yaw1 = self.poses[-1]
        v = w = 0.0
        if len(self.poses) == 2 and t1 > self.poses[0][0]:
            t0, x0, y0, yaw0 = self.poses[0]
            dt = (t1 - t0) / NS_PER_S
            v = ((x1 - x0) * math.cos(yaw1) + (y1 - y0) * math.sin(yaw1)) / dt
            w = math.remainder(yaw1 - yaw0, math.tau) / dt
        return [x1, y1, yaw1, v, w]


# -------------------------------------------------------------------------------- outputs


class _Stats:
    """Running min / max / mean / std of a vector feature (float64 sums)."""

    def __init__(self, size: int) -> None:
        self.count = 0
        self.sum, self.sumsq = np.zeros(size), np.zeros(size)
        self.min, self.max = np.full(size, np.inf), np.full(size, -np.inf)

    def add(
        self,
        values: NDArray[np.float64],
        squares: NDArray[np.float64] | None = None,
        lo: NDArray[np.float64] | None = None,
        hi: NDArray[np.float64] | None = None,
    ) -> None:
        self.count += 1
        self.sum += values
        self.sumsq += values**2 if squares is None else squares
        self.min = np.minimum(self.min, values if lo is None else lo)
        self.max = np.maximum(self.max, values if hi is None else hi)

    def to_dict(self, shape: tuple[int, ...]) -> dict[str, Any]:
        n = max(self.count, 1)
        mean = self.sum / n
        std = np.sqrt(np.maximum(self.sumsq / n - mean**2, 0.0))
        return {
            "min": self.min.reshape(shape).tolist(),
            "max": self.max.reshape(shape).tolist(),
            "mean": mean.reshape(shape).tolist(),
            "std": std.reshape(shape).tolist(),
            "count": [self.count],
        }


class _Video:
    """One camera's MP4, opened at its first frame (the size), written frame by frame."""

    def __init__(self, path: Path, fps: int) -> None:
        self.path, self.fps = path, fps
        self.container: Any = None
        self.stream: Any = None
        self.frames = 0
        self.shape: tuple[int, int] = (0, 0)

    def add(self, rgb: NDArray[np.uint8]) -> None:
        import av

        if self.container is None:
            self.path.parent.mkdir(parents=True)
            self.container = av.open(str(self.path), "w")
            self.stream = self.container.add_stream(VIDEO_CODEC, rate=self.fps, options=dict(VIDEO_OPTIONS))
            self.stream.pix_fmt = VIDEO_PIX_FMT
            self.shape = (rgb.shape[0], rgb.shape[1])
            self.stream.height, self.stream.width = self.shape
            self.stream.time_base = Fraction(1, self.fps)
        if rgb.shape[:2] != self.shape:  # (a camera's size is fixed in a run)
            raise RunError(
                "image size changed",
                str(self.path),
                f"{rgb.shape[:2]} after {self.shape}",
                "check the recording",
            )
        frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
        frame.pts = self.frames
        for packet in self.stream.encode(frame):
            self.container.mux(packet)
        self.frames += 1

    def close(self) -> None:
        if self.container is not None:
            for packet in self.stream.encode():
                self.container.mux(packet)
            self.container.close()

    def info(self) -> dict[str, Any]:
        return {
            "video.height": self.shape[0],
            "video.width": self.shape[1],
            "video.codec": "av1",
            "video.pix_fmt": VIDEO_PIX_FMT,
            "video.is_depth_map": False,
            "video.fps": self.fps,
            "video.channels": 3,
            "has_audio": False,
        }


class _Episode:
    """The dataset being written: videos, data rows (in row groups), stats; ``finish`` writes meta."""

    def __init__(self, out: Path, cameras: list[str], fps: int, task: str) -> None:
        import pyarrow as pa

        self.out, self.cameras, self.fps, self.task = out, cameras, fps, task
        self.videos = {
            cid: _Video(out / VIDEO_PATH.format(video_key=video_key(cid), chunk_index=0, file_index=0), fps)
            for cid in cameras
        }
        self.schema = pa.schema(
            [
                ("observation.state", pa.list_(pa.float32(), len(STATE_NAMES))),
                ("action", pa.list_(pa.float32(), len(ACTION_NAMES))),
                ("stamp_ns", pa.int64()),
                ("timestamp", pa.float32()),
                ("frame_index", pa.int64()),
                ("episode_index", pa.int64()),
                ("index", pa.int64()),
                ("task_index", pa.int64()),
            ]
        )
        self.rows: dict[str, list[Any]] = {name: [] for name in self.schema.names}
        self.writer: Any = None
        self.stats = {"observation.state": _Stats(len(STATE_NAMES)), "action": _Stats(len(ACTION_NAMES))}
        self.stats.update({video_key(cid): _Stats(3) for cid in cameras})
        self.frames = 0

    def add(
        self, images: dict[str, NDArray[np.uint8]], state: list[float], action: list[float], stamp_ns: int
    ) -> None:
        for cid in self.cameras:
            rgb = images[cid]
            self.videos[cid].add(rgb)
            mean, std = (np.asarray(v, dtype=np.float64).ravel() / 255 for v in cv2.meanStdDev(rgb))
            # per channel with OpenCV: numpy's min over axis 0 of (H*W, 3) costs 10 ms at 960x540
            lo, hi = zip(*(cv2.minMaxLoc(plane)[:2] for plane in cv2.split(rgb)), strict=True)
            self.stats[video_key(cid)].add(mean, std**2 + mean**2, np.asarray(lo) / 255, np.asarray(hi) / 255)
        self.stats["observation.state"].add(np.asarray(state, dtype=np.float32).astype(np.float64))
        self.stats["action"].add(np.asarray(action, dtype=np.float32).astype(np.float64))
        row = {
            "observation.state": state,
            "action": action,
            "stamp_ns": stamp_ns,
            "timestamp": self.frames / self.fps,
            "frame_index": self.frames,
            "episode_index": 0,
            "index": self.frames,
            "task_index": 0,
        }
        for name, value in row.items():
            self.rows[name].append(value)
        self.frames += 1
        if len(self.rows["index"]) >= ROW_GROUP:
            self._flush()

    def _flush(self) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        if self.writer is None:
            path = self.out / DATA_PATH.format(chunk_index=0, file_index=0)
            path.parent.mkdir(parents=True)
            self.writer = pq.ParquetWriter(path, self.schema)
        self.writer.write_table(pa.Table.from_pydict(self.rows, schema=self.schema))
        self.rows = {name: [] for name in self.schema.names}

    def finish(self, info: dict[str, Any]) -> None:
        import pandas as pd

        self._flush()
        self.writer.close()
        for video in self.videos.values():
            video.close()
        (self.out / "meta" / "episodes" / "chunk-000").mkdir(parents=True)
        pd.DataFrame({"task_index": [0]}, index=pd.Index([self.task], name="task")).to_parquet(
            self.out / TASKS_PATH
        )
        episode: dict[str, Any] = {
            "episode_index": [0],
            "tasks": [[self.task]],
            "length": [self.frames],
            "data/chunk_index": [0],
            "data/file_index": [0],
            "dataset_from_index": [0],
            "dataset_to_index": [self.frames],
        }
        for cid in self.cameras:
            key = video_key(cid)
            episode |= {
                f"videos/{key}/chunk_index": [0],
                f"videos/{key}/file_index": [0],
                f"videos/{key}/from_timestamp": [0.0],
                f"videos/{key}/to_timestamp": [self.frames / self.fps],
            }
        episode |= {"meta/episodes/chunk_index": [0], "meta/episodes/file_index": [0]}
        pd.DataFrame(episode).to_parquet(self.out / EPISODES_PATH, index=False)
        features = _features(self.videos)
        stats = {
            key: s.to_dict((3, 1, 1) if key.startswith("observation.images.") else (-1,))
            for key, s in self.stats.items()
        }
        (self.out / STATS_PATH).write_text(json.dumps(stats, indent=1, sort_keys=True) + "\n")
        (self.out / INFO_PATH).write_text(
            json.dumps(
                {
                    "codebase_version": CODEBASE_VERSION,
                    "robot_type": info["robot_type"],
                    "total_episodes": 1,
                    "total_frames": self.frames,
                    "total_tasks": 1,
                    "chunks_size": 1000,
                    "data_files_size_in_mb": 100,
                    "video_files_size_in_mb": 200,
                    "fps": self.fps,
                    "splits": {"train": "0:1"},
                    "data_path": DATA_PATH,
                    "video_path": VIDEO_PATH,
                    "features": features,
                    "source": info["source"],
                },
                indent=1,
            )
            + "\n"
        )


def _features(videos: dict[str, _Video]) -> dict[str, Any]:
    """info.json's features: the videos, state, action, then LeRobot's bookkeeping columns."""
    out: dict[str, Any] = {
        video_key(cid): {
            "dtype": "video",
            "shape": [v.shape[0], v.shape[1], 3],
            "names": ["height", "width", "channels"],
            "info": v.info(),
        }
        for cid, v in videos.items()
    }
    out["observation.state"] = {"dtype": "float32", "shape": [len(STATE_NAMES)], "names": STATE_NAMES}
    out["action"] = {"dtype": "float32", "shape": [len(ACTION_NAMES)], "names": ACTION_NAMES}
    out["stamp_ns"] = {"dtype": "int64", "shape": [1], "names": None}
    out["timestamp"] = {"dtype": "float32", "shape": [1], "names": None}
    for name in ("frame_index", "episode_index", "index", "task_index"):
        out[name] = {"dtype": "int64", "shape": [1], "names": None}
    return out


# ---------------------------------------------------------------------------------- export


def _require_libraries() -> None:
    """PyAV, pyarrow and pandas (the ``lerobot`` extra), checked before anything is written."""
    for module in ("av", "pyarrow.parquet", "pandas"):
        try:
            __import__(module)
        except ImportError as err:
            raise ConfigError(
                "--format lerobot unavailable",
                "export arguments",
                f"{module.split('.')[0]} is not installed ({err})",
                "pip install 'simlan-data[lerobot]'",
            ) from None


def _choose(agents: list[str], agent: str | None, where: str) -> str:
    if not agents:
        raise RecordingInputError(
            "no agent with commands", where, "no /<agent>/cmd_vel topic", "export a run with robots"
        )
    if agent is None:
        return agents[0]
    if agent not in agents:
        raise ConfigError.invalid(
            "--agent",
            agent,
            f"not an agent of the recording with commands ({', '.join(agents)})",
            f"use e.g. --agent {agents[0]}",
            where="export arguments",
        )
    return agent


def export_lerobot(
    run: str | Path, out: Path, *, agent: str | None = None, task: str | None = None
) -> LerobotExport:
    """Write the LeRobot dataset of one agent of ``run`` into ``out`` (new or empty).

    Raises:
        ConfigError: an unknown agent, or the ``lerobot`` extra missing (nothing written).
        RecordingInputError: no colour images, no ground truth or commands, a camera rate that is
            not a whole number (nothing written); no tick with every camera's image.
    """
    _require_libraries()
    os.environ.setdefault("SVT_LOG", "1")  # SVT-AV1 prints its configuration to stderr unless told
    with RecordingReader(run) as reader:
        cameras = _camera_ids(reader)
        chosen = _choose(_agents(reader), agent, str(reader.path))
        fps = _fps(reader)
        track = _Agent(chosen)
        command_topic = schema.agent_topics(chosen)["cmd_vel"].name
        ids = sorted(set(cameras.values()), key=lambda c: (len(c), c))
        out.mkdir(parents=True, exist_ok=True)
        episode = _Episode(out, ids, fps, task or f"drive {chosen} to its goals")
        pending: dict[int, dict[str, Any]] = {}  # tick -> camera -> image message
        ready: list[tuple[int, dict[str, Any]]] = []  # complete ticks (stamp, images) the bag has not passed
        incomplete = 0

        def emit(stamp_ns: int, images: dict[str, Any]) -> None:
            rgb = {cid: _rgb(msg) for cid, msg in images.items()}
            episode.add(rgb, track.state(), list(track.command), stamp_ns)

        for m in reader.messages([schema.GROUND_TRUTH_POSES, command_topic, *cameras]):
            while ready and ready[0][0] < m.stamp_ns:  # everything stamped up to it has been read
                emit(*ready.pop(0))
            if m.topic == schema.GROUND_TRUTH_POSES:
                track.on_poses(m.msg)
                continue
            if m.topic == command_topic:
                track.on_command(m.msg)
                continue
            tick = round((stamp_ns_of(m.msg.header.stamp) - reader.start_ns) * fps / NS_PER_S)
            group = pending.setdefault(tick, {})
            group[cameras[m.topic]] = m.msg
            if len(group) == len(ids):
                del pending[tick]
                ready.append((max(stamp_ns_of(g.header.stamp) for g in group.values()), group))
            given_up = [
                k for k in pending if k < tick - _STALE_TICKS_S * fps or (len(group) == len(ids) and k < tick)
            ]
            for k in given_up:
                del pending[k]
            incomplete += len(given_up)
        for item in ready:
            emit(*item)
        incomplete += len(pending)
        if episode.frames == 0:
            raise RecordingInputError(
                "no complete camera tick",
                str(reader.path),
                "no tick has an image from every camera",
                "check the recording's camera streams",
            )
        robot_type = "simlan_" + chosen.rstrip("0123456789").rstrip("_")
        episode.finish(
            {"robot_type": robot_type, "source": f"simlan_data recording {reader.path.name}, agent {chosen}"}
        )
    return LerobotExport(frames=episode.frames, incomplete_ticks=incomplete, agent=chosen, fps=fps)
