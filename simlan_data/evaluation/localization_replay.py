"""Replay the camera-based localization from a recording's images alone (no simulator).

The localizer sees exactly what the live run's localizer saw (the recorded JPEG bytes, cameras
rebuilt from the recorded camera info and static transforms, the same order of calls), so with
the same algorithm and parameters it reproduces the live estimates exactly; with other parameters
(``--set method=pnp``) it shows what they would have given.

Options (``--set``): ``localizer`` (another algorithm: a registered name or ``module:Class``;
default: the recording's ``algorithms.localizer``), any key of the localizer's config (e.g.
``method``, ``lost_timeout_s``, ``bias_m`` for the built-in ``aruco``; default: the recording's
values when the localizer is the recorded one, else its defaults) and the camera faults ``drop_cameras``, ``yaw_error_deg``, ``yaw_error_cameras`` (default: its ``faults``
section); ``navigation=false`` skips the navigation metrics; ``reader`` is ``auto`` (default:
a forked reading process when a core is free, else a reading thread; see :func:`choose_reader`),
``process`` (Linux) or ``thread``. Every reader gives the same results to the bit.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import queue
import sys
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

import numpy as np
import polars as pl

from simlan_data.algorithms import registry
from simlan_data.algorithms.localization import ImageSearch
from simlan_data.algorithms.markers import MarkerMount
from simlan_data.algorithms.roles import CameraFrame, LocalizerContext, searches
from simlan_data.config.legacy import with_algorithms
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError, RecordingInputError
from simlan_data.evaluation.camera_health import CameraConsistency
from simlan_data.evaluation.metrics import (
    RecordedRows,
    Visibility,
    estimates_from_recording,
    ground_truth,
    localization_metrics,
    navigation_metrics,
    status_table,
    yaw_as_recorded,
)
from simlan_data.evaluation.replay import ReplayContext, register
from simlan_data.recording.messages import compressed_image_data, header_stamp_ns, stamp_ns_of
from simlan_data.recording.reader import RecordingReader
from simlan_data.world.agent_types import MARKER_SIZE_M, agent_type

IMAGE_SUFFIX = "/image_raw/compressed"


# replay options that are not the localizer's config: how to read, which metrics, injected faults
REPLAY_OPTIONS = ("reader", "navigation", "localizer", "drop_cameras", "yaw_error_deg", "yaw_error_cameras")


def selected_localizer(
    config: dict[str, Any], options: dict[str, Any] | None = None
) -> tuple[registry.AlgorithmSpec, Any]:
    """The localizer and its config: the recording's, or ``options["localizer"]`` (a registered
    name or module:Class) with the other options as its config values.

    Raises:
        ConfigError: an unknown name or key, a value its config rejects.
    """
    options = dict(options or {})
    config = with_algorithms(config)  # (an older recording: the built-in, its keys from the old place)
    overrides = {k: v for k, v in options.items() if k not in REPLAY_OPTIONS}
    name = options.get("localizer")
    return registry.from_config(
        config,
        "localizer",
        name=None if name is None else str(name),
        overrides=overrides,
        where="replay --set",
    )


def marker_mounts(config: dict[str, Any]) -> tuple[list[MarkerMount], dict[str, Visibility]]:
    """The marker robots of a run (from its config) and, once cameras are known, their visibility."""
    mounts = []
    for ns, agent in sorted((config.get("agents") or {}).items(), key=lambda kv: (len(kv[0]), kv[0])):
        kind = agent_type(agent.get("type", "pallet_truck"))
        if kind.drive != "diff" or kind.marker_xyz is None:
            continue
        marker_id = agent.get("marker_id")
        if marker_id is None:
            marker_id = int(ns.rsplit("_", 1)[-1])
        mounts.append(
            MarkerMount(
                ns,
                int(marker_id),
                MARKER_SIZE_M,
                kind.marker_xyz[2],
                (kind.marker_xyz[0], kind.marker_xyz[1]),
                kind.accel_mps2,
            )
        )
    return mounts, {}


# (log time, JPEG bytes per camera, commands since the last set, per camera the stamp its header
# carries where it is not the log time: a camera with its own clock, sensors.timing)
FrameSet = tuple[int | None, dict[str, Any], list[tuple[int, str, float, float]], dict[str, int]]


def frame_sets(
    reader: RecordingReader,
    camera_ids: list[str],
    namespaces: list[str],
    recorded: RecordedRows | None = None,
) -> Iterator[FrameSet]:
    """One time-ordered pass over the cameras' images and the robots' velocity commands.

    Yields per frame set: its stamp, the JPEG bytes per camera (a view of the message's bytes:
    no copy, no deserialization), and the commands (stamp, namespace, v, w) read since the
    previous frame set, which include every command up to the next frame set's stamp: a control
    tick's command is known before the filter runs that tick. The reader keeps the small topics it passes for the
    metrics (no second pass over the bag); ``recorded`` (if given) collects the metrics' rows of
    them on the way.
    """
    images = {f"/camera_{c}{IMAGE_SUFFIX}": c for c in camera_ids}
    command_topics = {f"/{ns}/cmd_vel": ns for ns in namespaces}
    pending: dict[str, Any] = {}
    stamps: dict[str, int] = {}
    pending_t: int | None = None
    cmds: list[tuple[int, str, float, float]] = []
    extra = set(recorded.topics) if recorded is not None else set()
    for m in reader.messages([*images, *command_topics, *extra], raw=True):
        if m.topic in extra:
            assert recorded is not None
            recorded.add(reader.deserialize(m))
            if m.topic not in command_topics:
                continue
        ns = command_topics.get(m.topic)
        if ns is not None:
            twist = reader.deserialize(m).msg.twist
            cmds.append((m.stamp_ns, ns, twist.linear.x, twist.angular.z))
            continue
        if m.stamp_ns != pending_t:
            if pending_t is not None:
                yield pending_t, pending, cmds, stamps
                cmds = []
            pending, stamps, pending_t = {}, {}, m.stamp_ns
        # the JPEG bytes without deserializing the message (most images are never searched)
        data = compressed_image_data(m.msg)
        cid = images[m.topic]
        pending[cid] = data if data is not None else reader.deserialize(m).msg.data
        header = header_stamp_ns(m.msg)
        if header is None:
            header = stamp_ns_of(reader.deserialize(m).msg.header.stamp)
        stamp = header - reader.epoch_ns
        if stamp != m.stamp_ns:
            stamps[cid] = stamp
    if pending_t is not None or cmds:
        yield pending_t, pending, cmds, stamps


T = TypeVar("T")


def in_background(items: Iterator[T], *, depth: int) -> Iterator[T]:
    """``items``, produced on a thread of their own up to ``depth`` ahead (reading a bag:
    decompression releases the GIL and overlaps with the searches); its errors are raised here."""
    q: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(entry: tuple[str, Any]) -> bool:
        while not stop.is_set():
            try:
                q.put(entry, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in items:
                if not put(("item", item)):
                    return
            put(("end", None))
        except BaseException as err:  # handed to the consumer, raised there
            put(("error", err))

    thread = threading.Thread(target=produce, name="read", daemon=True)
    thread.start()
    try:
        while True:
            kind, value = q.get()
            if kind == "end":
                return
            if kind == "error":
                raise value
            yield value
    finally:
        stop.set()
        thread.join()


READERS = ("auto", "thread", "process")


def choose_reader(requested: str, *, cpu_count: int | None = None, load_1min: float | None = None) -> str:
    """The reader a replay uses: ``auto`` takes the reading process when a core is about free
    (1-minute load average < cores - 0.5), else the reading thread; off Linux always the thread
    (the reading process forks).

    Measured on the 20 s 12-camera recording, 2 cores (docs/benchmarks/realtime.md, section 5): on a quiet
    or lightly loaded machine the process was 8-35 % faster (the bag's Python record walk leaves the replay's
    GIL); with two busy processes beside it, it was slower (its images cross a pipe, and the
    extra process competes for the cores). The load average lags (a minute): right after other
    work ends it still reads about 1-1.5 on 2 cores, hence the half-core margin.
    """
    if sys.platform != "linux":
        return "thread"
    if requested != "auto":
        return requested
    cores = cpu_count if cpu_count is not None else (os.cpu_count() or 1)
    if load_1min is None:
        try:
            load_1min = os.getloadavg()[0]
        except OSError:
            return "thread"
    return "process" if cores >= 2 and load_1min < cores - 0.5 else "thread"


def _read_frame_sets(
    reader: RecordingReader, camera_ids: list[str], namespaces: list[str], recorded: RecordedRows, conn: Any
) -> None:
    """The reading process: per frame set its stamp, cameras and commands, then each camera's
    JPEG bytes (written straight from the bag's decompressed chunk); then the rows of the
    recording's own topics that the metrics need (collected while it waits for the consumer),
    the small topics the pass kept, and the end; or the error."""
    try:
        try:
            reader.detach_after_fork()
        except Exception:  # (another rosbags layout) open the recording again
            reader = RecordingReader(reader.path, check_format=False)
        for stamp_ns, jpegs, cmds, stamps in frame_sets(reader, camera_ids, namespaces, recorded):
            conn.send(("item", (stamp_ns, list(jpegs), cmds, stamps)))
            for data in jpegs.values():
                conn.send_bytes(data)
        conn.send(("recorded", recorded.rows()))
        small = reader.small_topics()
        conn.send(("small", small is not None))
        if small is not None:
            conn.send_bytes(small)
        conn.send(("end", None))
    except BaseException as err:  # handed to the consumer, raised there
        try:
            conn.send(("error", err))
        except Exception:  # (an error that does not pickle: its text)
            conn.send(("error", RuntimeError(f"{type(err).__name__}: {err}")))
    finally:
        conn.close()


class ReadingProcess:
    """:func:`frame_sets` of a recording, read by a process of its own, started at once (forked:
    no start-up cost, the open recording inherited); it also fills ``recorded`` and hands the
    reader the small topics it kept. Iterate it once; close it (or use it as a context manager)
    to stop the process early.

    Reading a bag is mostly Python (rosbags walks every record of every chunk) and holds the GIL
    against the localizer's own Python; in another process it runs on the other core, and
    collects the metrics' rows of the recorded topics while it waits for the consumer. Its CPU
    time is the replay's too (``replay.cpu_s`` counts child processes). Not the default: the
    hand-over of every image through a pipe and the fork's copy-on-write page faults cost about
    0.2 CPU s per 20 s of the 12-camera recording, and on 2 shared cores it was slower than the
    reading thread (measured 2026-11-23 at load 4, 12 cameras, 20 s: 1.47-1.55 s against
    1.31-1.48 s a replay); it may pay on a machine with cores to spare.
    """

    def __init__(
        self, reader: RecordingReader, camera_ids: list[str], namespaces: list[str], recorded: RecordedRows
    ) -> None:
        self.reader, self.recorded = reader, recorded
        mp = multiprocessing.get_context("fork")
        self._receive, send = mp.Pipe(duplex=False)
        self._proc = mp.Process(
            target=_read_frame_sets, args=(reader, camera_ids, namespaces, recorded, send), name="read"
        )
        self._proc.start()
        send.close()

    def __iter__(self) -> Iterator[FrameSet]:
        receive, proc = self._receive, self._proc
        try:
            while True:
                try:
                    kind, value = receive.recv()
                except EOFError:
                    proc.join()
                    raise RecordingInputError(
                        "replay failed",
                        str(self.reader.path),
                        f"its reading process ended early (exit code {proc.exitcode})",
                        "replay without --set reader=process",
                    ) from None
                if kind == "item":
                    stamp_ns, cids, cmds, stamps = value
                    yield stamp_ns, {c: receive.recv_bytes() for c in cids}, cmds, stamps
                elif kind == "recorded":
                    self.recorded.take(value)
                elif kind == "small":
                    if value:
                        self.reader.adopt_small_topics(receive.recv_bytes())
                elif kind == "error":
                    raise value
                else:
                    return
        finally:
            self.close()

    def close(self) -> None:
        self._receive.close()
        if self._proc.exitcode is None:
            self._proc.terminate()  # (stopped early: the reader may be blocked sending)
        self._proc.join()

    def __enter__(self) -> ReadingProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def image_camera_ids(reader: RecordingReader, config: dict[str, Any]) -> list[str]:
    """The cameras whose images a replay reads: the run's cameras, in its order."""
    recorded = sorted(
        t.split("/")[1].removeprefix("camera_")
        for t in reader.topics
        if t.startswith("/camera_") and t.endswith(IMAGE_SUFFIX)
    )
    return [str(c) for c in (config.get("cameras") or {}).get("ids", recorded)]


def replay_localizer(
    reader: RecordingReader,
    config: dict[str, Any],
    cameras: dict,
    selected: tuple[registry.AlgorithmSpec, Any],
    consistency: CameraConsistency | None = None,
    *,
    reading: ReadingProcess | None = None,
    recorded: RecordedRows | None = None,
) -> tuple[Any, dict[str, pl.DataFrame]]:
    """Run the ``selected`` localizer (spec, config) over the recording; returns it and per-agent
    estimate tables.

    ``consistency`` (if given) gets every frame set's per-camera observations. ``reading``: the
    recording's frame sets from a reading process already started (for at least the cameras
    and agents of ``config``; it fills its own rows of the recorded topics); without it a thread
    reads them, and fills ``recorded`` (if given) on the way.
    """
    mounts, _ = marker_mounts(config)
    camera_order = [str(c) for c in (config.get("cameras") or {}).get("ids", sorted(cameras))]
    camera_order = [c for c in camera_order if c in cameras]
    spec, loc_config = selected
    context = LocalizerContext({c: cameras[c] for c in camera_order}, mounts)
    localizer = registry.Guarded(spec.build(loc_config, context), spec)
    control_ns = round(NS_PER_S / float(config.get("control_rate_hz", 20.0)))
    duration_ns = round(float(config.get("duration_s", reader.duration_ns / NS_PER_S)) * NS_PER_S)
    replay = _LocalizerReplay(
        localizer, camera_order, [m.namespace for m in mounts], control_ns, duration_ns, consistency
    )
    #   reading process (or thread): bag -> (frame set, commands before the next one) --pipe-->
    #   this thread: plan -> search (a worker thread and this one) -> observe in camera order ->
    #   fuse -> control ticks
    sets = (
        reading
        if reading is not None
        else in_background(frame_sets(reader, camera_order, list(replay.rows), recorded), depth=4)
    )
    workers = max(1, min(8, os.cpu_count() or 1) - 1)  # (and this thread)
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="search") as pool:
        for stamp_ns, jpegs, cmds, stamps in sets:
            for t_ns, ns, v, w in cmds:
                replay.commands.setdefault(t_ns, []).append((ns, v, w))
            # (a reading process may read cameras the localizer was not given: a fault)
            if stamp_ns is not None and any(c in jpegs for c in camera_order):
                replay.frame_set(pool, stamp_ns, jpegs, stamps)
    replay.control_until(duration_ns, inclusive=True)
    return localizer, {ns: status_table(est, status) for ns, (est, status) in replay.rows.items()}


class _LocalizerReplay:
    """The localizer fed as live: control ticks (estimate, commands) between frame sets."""

    def __init__(
        self,
        localizer: Any,
        camera_order: list[str],
        namespaces: list[str],
        control_ns: int,
        duration_ns: int,
        consistency: CameraConsistency | None,
    ) -> None:
        self.localizer, self.camera_order, self.consistency = localizer, camera_order, consistency
        self.searching = searches(localizer)
        self.ticks = iter(range(0, duration_ns + 1, control_ns))
        self.next_tick = next(self.ticks, None)
        self.rows: dict[str, tuple[list, list]] = {ns: ([], []) for ns in namespaces}
        self.commands: dict[int, list[tuple[str, float, float]]] = {}

    def control_until(self, t_ns: int, *, inclusive: bool) -> None:
        """Run the control ticks before ``t_ns`` (or at it): estimate, record, pass the commands."""
        localizer = self.localizer
        while self.next_tick is not None and (
            self.next_tick < t_ns or (inclusive and self.next_tick == t_ns)
        ):
            tick = self.next_tick
            est = localizer.estimate(tick)
            for ns, v, w in self.commands.pop(tick, ()):
                localizer.command(tick, ns, v, w)
            for ns, (est_rows, status_rows) in self.rows.items():
                e = est.get(ns)
                status_rows.append(
                    (
                        tick,
                        e is not None and e.observed,
                        e is not None and e.valid,
                        e.age_s if e is not None else -1.0,
                    )
                )
                if e is not None and e.valid:
                    # scored as the live run is: from the yaw its recorded quaternion gives back
                    est_rows.append((tick, e.x_m, e.y_m, yaw_as_recorded(e.yaw_rad)))
            self.next_tick = next(self.ticks, None)

    def frame_set(
        self, pool: ThreadPoolExecutor, pending_t: int, pending: dict[str, Any], stamps: dict[str, int]
    ) -> None:
        """Localize one frame set between the control ticks before it and the one at it; each image
        at the stamp its camera wrote (``stamps``, where it is not the set's)."""
        self.control_until(pending_t, inclusive=False)
        localizer = self.localizer
        ids = [cid for cid in self.camera_order if cid in pending]
        if not self.searching:  # the localizer takes the frames whole, as live
            frames = {c: CameraFrame(c, stamps.get(c, pending_t), bytes(pending[c])) for c in ids}
            localizer.observe(pending_t, frames)
            self.control_until(pending_t, inclusive=True)
            return
        self._search(pool, pending_t, pending, ids, stamps)
        localizer.close_frame(pending_t)
        if self.consistency is not None and hasattr(localizer, "last_observations"):
            self.consistency.add(localizer.last_observations)
        self.control_until(pending_t, inclusive=True)

    def _search(
        self,
        pool: ThreadPoolExecutor,
        pending_t: int,
        pending: dict[str, Any],
        ids: list[str],
        stamps: dict[str, int],
    ) -> None:
        """Search the planned images on the workers and this thread; observe them in camera order."""
        # the planned images of a frame set are decoded and searched, and the markers' poses
        # computed, on worker threads at once (Localizer.detect is a pure function; OpenCV
        # releases the GIL); what they found is taken in camera order, exactly as the live run
        # and process_image do
        localizer = self.localizer
        if stamps:  # cameras with clocks of their own: each planned at its own stamp, as live
            planned = [(cid, localizer.search_plans(stamps.get(cid, pending_t), [cid])[0]) for cid in ids]
        else:
            planned = list(zip(ids, localizer.search_plans(pending_t, ids)))
        jobs = [
            (cid, plan, pool.submit(localizer.detect, cid, plan, jpeg=pending[cid]))
            for cid, plan in planned
            if plan
        ]
        # this thread searches too, from the last image back, each one no worker has started
        # (a cancelled future is never run): no idle wait, fewer hand-overs between threads
        own: dict[str, ImageSearch] = {}
        for cid, plan, job in reversed(jobs):
            if not job.cancel():
                break
            own[cid] = localizer.detect(cid, plan, jpeg=pending[cid])
        for cid, plan, job in jobs:
            found = own[cid] if cid in own else job.result()
            localizer.observe_search(stamps.get(cid, pending_t), cid, plan, found)


@register("localization")
def localization(ctx: ReplayContext) -> dict[str, float]:
    """Recompute localization from the images; metrics against ground truth; estimates.parquet."""
    config = ctx.config
    selected = selected_localizer(config, ctx.options)
    read_in = _reader_option(ctx.options)
    wall0 = time.perf_counter()
    consistency = CameraConsistency()
    mounts, _ = marker_mounts(config)
    kinds = {ns: agent_type(a.get("type", "pallet_truck")) for ns, a in (config.get("agents") or {}).items()}
    drives = [ns for ns, k in kinds.items() if k.drive == "diff"]
    recorded = RecordedRows(
        estimates_of=[m.namespace for m in mounts],
        navigation_of=drives if ctx.options.get("navigation", True) else (),
    )
    in_process = read_in == "process"
    # the reading process starts before the cameras are known: it reads while they are built
    with (
        ReadingProcess(
            ctx.reader, image_camera_ids(ctx.reader, config), [m.namespace for m in mounts], recorded
        )
        if in_process
        else contextlib.nullcontext()
    ) as reading:
        localizer, tables = replay_localizer(
            ctx.reader,
            config,
            ctx.believed_cameras,
            selected,
            consistency,
            reading=reading,
            recorded=recorded,
        )
    wall = time.perf_counter() - wall0
    # the recording's own topics (ground truth, live estimates, navigation): read on the way
    truth = recorded.truth_tables()
    visibility = {m.namespace: Visibility(ctx.cameras, kinds[m.namespace]) for m in mounts}
    metrics = localization_metrics(truth, tables, visibility)
    if hasattr(localizer, "last_observations"):  # per-camera marker poses: the camera-health metrics
        metrics.update(consistency.metrics("replay.localization."))
    metrics["replay.localization.wall_s"] = wall
    metrics["replay.localization.reading_process"] = float(in_process)  # (which reader auto took)
    metrics.update(_frame_timings(localizer, ctx))
    diffs = _diffs_to_live(tables, recorded.estimate_tables())
    if diffs:
        metrics["replay.localization.max_diff_to_live_m"] = max(diffs)
    frames_out = [t.with_columns(pl.lit(ns).alias("namespace")) for ns, t in tables.items()]
    if frames_out:
        pl.concat(frames_out).write_parquet(ctx.out_dir / "estimates.parquet")
    if ctx.options.get("navigation", True):
        metrics.update(navigation_metrics(recorded, truth, drives, kinds=kinds))
    return metrics


def _reader_option(options: dict[str, Any]) -> str:
    """Check the ``reader`` option and choose the reader it asks for."""
    read_in = str(options.get("reader", READERS[0]))
    if read_in not in READERS:
        raise ConfigError(
            f"unknown reader {read_in!r}",
            "replay --set reader",
            f"known: {', '.join(READERS)}",
            "use auto",
        )
    return choose_reader(read_in)


def _frame_timings(localizer: Any, ctx: ReplayContext) -> dict[str, float]:
    """Summarize the localizer's frame timings (per mode) and write frame_timings.parquet."""
    if not hasattr(localizer, "timings"):  # a localizer that keeps none: no figure, not "0 frames"
        return {}
    frames = [t.seconds for t in localizer.timings]
    metrics = {"replay.localization.frames_processed": float(len(frames))}
    if frames:
        metrics["replay.localization.frame_ms_median"] = float(np.median(frames) * 1e3)
        for mode in ("full", "roi"):
            sel = [t.seconds for t in localizer.timings if t.mode == mode]  # (frames: it has timings)
            metrics[f"replay.localization.frames_{mode}"] = float(len(sel))
            if sel:
                metrics[f"replay.localization.frame_ms_median_{mode}"] = float(np.median(sel) * 1e3)
        pl.DataFrame(
            [(t.camera_id, t.stamp_ns, t.mode, t.seconds, t.detections) for t in localizer.timings],
            schema={
                "camera_id": pl.String,
                "stamp_ns": pl.Int64,
                "mode": pl.String,
                "seconds": pl.Float64,
                "detections": pl.Int64,
            },
            orient="row",
        ).write_parquet(ctx.out_dir / "frame_timings.parquet")
    return metrics


def _diffs_to_live(tables: dict[str, pl.DataFrame], live: dict[str, pl.DataFrame]) -> list[float]:
    """Measure, per agent, the largest distance between the replayed and the live estimates."""
    diffs = []
    for ns, table in tables.items():
        joined = table.join(live[ns], on="stamp_ns", how="inner", suffix="_live").filter(
            pl.col("x").is_not_null() & pl.col("x_live").is_not_null()
        )
        if joined.height:
            diffs.append(
                float(
                    np.hypot(
                        (joined["x"] - joined["x_live"]).to_numpy(),
                        (joined["y"] - joined["y_live"]).to_numpy(),
                    ).max()
                )
            )
    return diffs


def recording_metrics(reader: RecordingReader, config: dict[str, Any], cameras: dict) -> dict[str, float]:
    """Localization and navigation metrics of a live run, from its recording."""
    truth = ground_truth(reader)
    mounts, _ = marker_mounts(config)
    kinds = {ns: agent_type(a.get("type", "pallet_truck")) for ns, a in (config.get("agents") or {}).items()}
    metrics: dict[str, float] = {}
    if mounts and (config.get("localization") or {}).get("source", "camera") == "camera":
        tables = estimates_from_recording(reader, [m.namespace for m in mounts])
        visibility = {m.namespace: Visibility(cameras, kinds[m.namespace]) for m in mounts}
        metrics.update(localization_metrics(truth, tables, visibility))
    metrics.update(
        navigation_metrics(reader, truth, [ns for ns, k in kinds.items() if k.drive == "diff"], kinds=kinds)
    )
    return metrics
