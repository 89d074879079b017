"""Replay and score the person detector: the recorded images through it again, against ground truth.

    python -m simlan_data.replay REC --out DIR --algorithms people
    python -m simlan_data.replay REC --out DIR --algorithms people --set detector=segmentation_oracle

Data flow (what the live loop runs, from the recording alone)::

    per camera tick t: recorded JPEG per camera (rgb) or segmentation image (the oracle)
        + every robot where GPSS believed it at the control tick before t (its recorded
          estimate, else its last valid one, else its spawn pose), and the people who walked
          at the previous camera tick (never absorbed into the background)
        --> PersonDetector --> fuse_people --> PersonTracker --> tracked people at t
        v
    against the people's ground truth at t: missed, position error, latency, false tracks

With the recorded detector and ``people`` config the detections equal the recorded
``/people/detections`` (``replay.people.count_diff_to_live`` and
``max_diff_to_live_m`` are 0); ``--set detector=...`` and any other
key of the ``people`` section (``--set threshold=40``) show what another one would have seen. The
oracle needs the segmentation recorded at every camera tick (``recording.semantic_rate_hz`` equal
to ``cameras.rate_hz``).

Metrics (camera ticks; a person is *in view* when its feet and head project into some camera's
image, shelves ignored, so occlusion counts as missed for every detector):
``people.missed_share`` (in-view person-ticks with no track within ``match_m``),
``people.position_error_mean_m`` / ``_p95_m`` (matched tracks), ``people.latency_max_s`` /
``_mean_s`` (from a person coming into view to its first track), ``people.false_tracks_per_tick``
(tracks near no person).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.people import ORACLE, PeopleParams, PersonDetector, PersonTracker, fuse_people
from simlan_data.config.legacy import with_algorithms
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError, RecordingInputError
from simlan_data.evaluation.replay import ReplayContext, register
from simlan_data.evaluation.safety_inputs import SafetyRecording, read_safety_recording
from simlan_data.evaluation.safety_replay import people_params
from simlan_data.geometry.camera import CameraModel
from simlan_data.recording.codecs import decode_compressed
from simlan_data.recording.reader import RecordingReader

MATCH_M = 1.0  # a track this close to a person is that person
PREFIX = "replay.people."
Positions = list[tuple[float, float]]


def replay_params(config: dict[str, Any], options: Mapping[str, Any]) -> PeopleParams:
    """The recorded ``people`` config with the ``--set`` options over it.

    Raises:
        ConfigError: an unknown key or a value the config refuses.
    """
    recorded = people_params(config)
    if "detector" not in (with_algorithms(config).get("people") or {}):
        recorded = replace(recorded, detector=ORACLE)  # (recorded before the RGB detector: the oracle)
    known = set(PeopleParams.__dataclass_fields__)
    unknown = sorted(set(options) - known)
    if unknown:
        raise ConfigError(
            f"unknown people option {unknown[0]!r}",
            "replay --set",
            f"known: {', '.join(sorted(known))}",
            "drop it",
        )
    return replace(recorded, **dict(options))


def camera_images(
    reader: RecordingReader, camera_ids: list[str], *, labels: bool
) -> Iterator[tuple[int, dict[str, NDArray[np.uint8]]]]:
    """Per camera tick (log time): each camera's decoded colour image (BGR, as the live detector
    decodes the recorded JPEG) or, with ``labels``, its segmentation image."""
    suffix = "/semantic/image_raw/compressed" if labels else "/image_raw/compressed"
    topics = {f"/camera_{c}{suffix}": c for c in camera_ids}
    pending: dict[str, NDArray[np.uint8]] = {}
    pending_t: int | None = None
    for m in reader.messages([t for t in topics if t in reader.topics]):
        if m.stamp_ns != pending_t:
            if pending_t is not None:
                yield pending_t, pending
            pending, pending_t = {}, m.stamp_ns
        data = np.frombuffer(bytes(m.msg.data), np.uint8)
        image = decode_compressed(m.msg.format, data) if labels else cv2.imdecode(data, cv2.IMREAD_COLOR)
        pending[topics[m.topic]] = np.asarray(image, dtype=np.uint8)
    if pending_t is not None:
        yield pending_t, pending


def believed_robots(rec: SafetyRecording, t_ns: int) -> dict[str, tuple[float, float, float]]:
    """Where GPSS believed every robot at the last control tick before ``t_ns`` (the live
    detector's view: its valid estimate, else its last known pose) and where static agents stand."""
    i = int(np.searchsorted(rec.ticks, t_ns)) - 1
    out = {}
    for ns, spec in rec.specs.items():
        if spec.kind == "static":
            out[ns] = rec.spawn[ns]
        elif spec.kind == "robot":
            e = rec.estimates[ns][i] if i >= 0 and ns in rec.estimates else None
            pose = rec.spawn[ns] if e is None else (e.pose if e.pose is not None else e.last_pose)
            out[ns] = pose if pose is not None else rec.spawn[ns]
    return out


def run_detector(
    rec: SafetyRecording, reader: RecordingReader, cameras: Mapping[str, CameraModel], params: PeopleParams
) -> list[tuple[int, Positions, Positions]]:
    """Per camera tick: the fused detections and the tracked people (as the live loop makes them)."""
    footprints = {ns: s.footprint for ns, s in rec.specs.items() if s.kind in ("robot", "static")}
    detector = PersonDetector(cameras, params, footprints)
    tracker = PersonTracker(params)
    out = []
    oracle = params.detector == ORACLE
    walked: list[tuple[float, float]] = []  # people who walked, at the previous camera tick
    for t, images in camera_images(reader, sorted(cameras), labels=oracle):
        poses = believed_robots(rec, t)
        found = []
        for cid in sorted(images):
            image = images[cid]
            found += detector.detect(
                cid,
                labels=image if oracle else None,
                bgr=None if oracle else image,
                robot_poses=poses,
                people_xy=walked,
            )
        fused = fuse_people(found, params.cluster_m)
        tracker.update(t, fused)
        walked = tracker.walked(t)
        out.append((t, fused, [(p.x_m, p.y_m) for p in tracker.people(t)]))
    return out


def in_view(cameras: Mapping[str, CameraModel], x: float, y: float, height_m: float) -> bool:
    """True if a person at (x, y) has feet and head inside some camera's image (occlusion ignored)."""
    pts = np.array([[x, y, 0.05], [x, y, height_m]])
    for cam in cameras.values():
        uv, ok = cam.project(pts)
        if ok.all() and ((uv >= 0) & (uv < [cam.width, cam.height])).all():
            return True
    return False


def score(
    rec: SafetyRecording,
    cameras: Mapping[str, CameraModel],
    ticks: list[tuple[int, Positions, Positions]],
    params: PeopleParams,
    *,
    prefix: str = PREFIX,
) -> dict[str, float]:
    """Missed share, position error, latency and false tracks of ``ticks`` against ground truth."""
    people = [ns for ns, s in rec.specs.items() if s.kind == "person" and ns in rec.truth]
    errors: list[float] = []
    latencies: list[float] = []
    seen_since: dict[str, int | None] = dict.fromkeys(people)
    tracked_once: dict[str, bool] = dict.fromkeys(people, False)
    missed = in_view_n = false_tracks = 0
    for t, _fused, tracks in ticks:
        i = rec.index(t)
        truth = {ns: rec.truth[ns].at(i)[:2] for ns in people}
        used: set[int] = set()
        for ns in people:
            x, y = truth[ns]
            if not in_view(cameras, x, y, params.height_m):
                seen_since[ns], tracked_once[ns] = None, False
                continue
            in_view_n += 1
            if seen_since[ns] is None:
                seen_since[ns] = t
            d = [(float(np.hypot(tx - x, ty - y)), k) for k, (tx, ty) in enumerate(tracks) if k not in used]
            best = min(d) if d else None
            if best is None or best[0] > MATCH_M:
                missed += 1
                continue
            used.add(best[1])
            errors.append(best[0])
            if not tracked_once[ns]:
                tracked_once[ns] = True
                latencies.append((t - int(seen_since[ns] or t)) / NS_PER_S)
        false_tracks += sum(
            1
            for k, (tx, ty) in enumerate(tracks)
            if k not in used and all(np.hypot(tx - x, ty - y) > MATCH_M for x, y in truth.values())
        )
    nan = float("nan")
    return {
        prefix + "in_view_ticks": float(in_view_n),
        prefix + "missed_share": missed / in_view_n if in_view_n else nan,
        prefix + "position_error_mean_m": float(np.mean(errors)) if errors else nan,
        prefix + "position_error_p95_m": float(np.quantile(errors, 0.95)) if errors else nan,
        prefix + "latency_max_s": max(latencies) if latencies else nan,
        prefix + "latency_mean_s": float(np.mean(latencies)) if latencies else nan,
        prefix + "false_tracks_per_tick": false_tracks / len(ticks) if ticks else nan,
    }


def diff_to_live(
    ticks: list[tuple[int, Positions, Positions]], recorded: list[tuple[int, Positions]]
) -> tuple[float, float]:
    """Camera ticks whose replayed detections differ in number from the recorded ones, and the
    largest coordinate difference over the others."""
    live = dict(recorded)
    worst, counts = 0.0, 0
    for t, fused, _ in ticks:
        got = live.get(t, [])
        if len(got) != len(fused):
            counts += 1
            continue
        for (ax, ay), (bx, by) in zip(sorted(fused), sorted(got)):
            worst = max(worst, abs(ax - bx), abs(ay - by))
    return float(counts), worst


@register("people")
def people(ctx: ReplayContext) -> dict[str, float]:
    """Re-run the person detector (the recorded one, or ``--set detector=...``) on the recorded
    images and score it against the people's ground truth."""
    params = replay_params(ctx.config, ctx.options)
    rec = read_safety_recording(ctx.reader, ctx.config)
    if not any(s.kind == "person" for s in rec.specs.values()):
        raise RecordingInputError(
            "no people", str(ctx.reader.path), "the run has no walking person", "replay a run with people"
        )
    ticks = run_detector(rec, ctx.reader, ctx.believed_cameras, params)
    metrics = score(rec, ctx.cameras, ticks, params)
    counts, worst = diff_to_live(ticks, rec.people)
    metrics[PREFIX + "count_diff_to_live"] = counts
    metrics[PREFIX + "max_diff_to_live_m"] = worst
    return metrics
