"""Localization and navigation metrics from a recording (or from replayed estimates).

Tables are polars DataFrames keyed by ``stamp_ns``. The same functions score a live run (from
its bag) and a replay (its recomputed estimates against the bag's ground truth), so that a replay
with the same algorithm version reproduces the live metrics exactly.

Localization (per agent and overall, at control ticks):
- ``ate_xy_rmse_m``, ``ate_xy_max_m``: absolute trajectory error of base_link in the plane, no
  alignment (the cameras are fixed in the world), over ticks with a valid estimate;
- ``yaw_rmse_deg``;
- ``availability``: share of control ticks with a fresh estimate (``observed``) among the ticks
  at which the marker is in at least one camera's view (from ground truth: all four corners on
  valid pixels inside the image, facing the camera, at least ``MIN_SIDE_PX`` wide: ``algorithms.markers.markers_in_view``);
- ``latency_s``: mean age of the newest fix (image capture to the tick that uses it).

Navigation (per agent ``navigation.<ns>.*`` and summed ``navigation.*``): ``goals_reached``,
``goals_total``, ``goals_failed`` and ``goals_failed.<reason>`` for each reason of
:data:`~simlan_data.algorithms.navigation.FAILURE_REASONS` (``unreachable``: no path;
``blocked``: no progress for ``BLOCKED_AFTER_S`` when the run ended; ``timeout``: the run ended
first), read from the ``failed_<reason>`` states of the recorded navigation status. A recording
that does not say why (format 1.0, or cut short by a crash) counts a failure it records as
``unreachable`` (the only reason then) and a goal left at its end as ``timeout``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import polars as pl
from numpy.typing import NDArray

from simlan_data.algorithms.markers import markers_in_view
from simlan_data.algorithms.navigation import FAILURE_REASONS, failure_reason
from simlan_data.constants import NS_PER_S
from simlan_data.evaluation.fleet_metrics import Status, fleet_metrics
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.rotations import wrap_angle
from simlan_data.recording import schema
from simlan_data.recording.reader import Message, RecordingReader
from simlan_data.world.agent_types import MARKER_SIZE_M, AgentType

POSE_SCHEMA = {"stamp_ns": pl.Int64, "x": pl.Float64, "y": pl.Float64, "yaw": pl.Float64}


def _yaw(q: object) -> float:
    return _yaw_xyzw(q.x, q.y, q.z, q.w)  # type: ignore[attr-defined]


def _yaw_xyzw(x: float, y: float, z: float, w: float) -> float:
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def yaw_as_recorded(yaw_rad: float) -> float:
    """The yaw a reader gets back from the planar quaternion a recording stores for ``yaw_rad``.

    Replays score their estimates through this, so that they compare bit for bit with the live
    run's metrics, which are computed from the recorded messages.
    """
    return _yaw_xyzw(0.0, 0.0, float(np.sin(yaw_rad / 2)), float(np.cos(yaw_rad / 2)))


class RecordedRows:
    """What the metrics read from a recording's own topics (ground truth, the live estimates and
    localization status, navigation status and collisions), as plain rows, collected message by
    message: :func:`ground_truth`, :func:`estimates_from_recording` and
    :func:`navigation_metrics` read through it, and a replay's reading process collects them
    while it reads (plain rows pickle cheaply; its tables are built here).
    """

    def __init__(
        self, *, truth: bool = True, estimates_of: Iterable[str] = (), navigation_of: Iterable[str] = ()
    ) -> None:
        self.truth: dict[str, list[tuple]] = {}
        self.estimates: dict[str, tuple[list[tuple], list[tuple]]] = {}
        self.navigation: dict[str, tuple[Any, int, bool]] = {}  # last status, collisions, in collision
        self.statuses: dict[str, list[Status]] = {}  # every status (the fleet metrics' timeline)
        self._handlers: dict[str, tuple[Any, ...]] = {}
        if truth:
            self._handlers[schema.GROUND_TRUTH_POSES] = (self._truth,)
        for ns in estimates_of:
            topics = schema.agent_topics(ns)
            est, status = self.estimates[ns] = ([], [])
            self._handlers[topics["pose_estimate"].name] = (self._estimate, est)
            self._handlers[topics["localization"].name] = (self._status, status)
        for ns in navigation_of:
            topics = schema.agent_topics(ns)
            self.navigation[ns] = (None, 0, False)
            self.statuses[ns] = []
            self._handlers[topics["navigation"].name] = (self._navigation, ns)
            self._handlers[topics["collision"].name] = (self._collision, ns)

    def rows(self) -> tuple[Any, ...]:
        """The rows collected (plain data: to hand to another process, see :meth:`take`)."""
        return self.truth, self.estimates, self.navigation, self.statuses

    def take(self, rows: tuple[Any, ...]) -> None:
        """Rows another collector of the same topics collected (its :meth:`rows`)."""
        self.truth, self.estimates, self.navigation, self.statuses = rows

    @property
    def topics(self) -> list[str]:
        return list(self._handlers)

    def add(self, m: Message) -> None:
        """One message (decoded) of one of :attr:`topics`, in log-time order."""
        handler, *args = self._handlers[m.topic]
        handler(m, *args)

    def _truth(self, m: Message) -> None:
        for tf in m.msg.transforms:
            ns = schema.ground_truth_namespace(tf.child_frame_id)  # (old recordings' names too)
            p = tf.transform.translation
            self.truth.setdefault(ns, []).append((m.stamp_ns, p.x, p.y, _yaw(tf.transform.rotation)))

    @staticmethod
    def _estimate(m: Message, rows: list[tuple]) -> None:
        pose = m.msg.pose.pose
        rows.append((m.stamp_ns, pose.position.x, pose.position.y, _yaw(pose.orientation)))

    @staticmethod
    def _status(m: Message, rows: list[tuple]) -> None:
        rows.append((m.stamp_ns, m.msg.observed, m.msg.valid, m.msg.fix_age_s))

    def _navigation(self, m: Message, ns: str) -> None:
        last, hits, prev = self.navigation[ns]
        status = m.msg
        failed = dict(last[3]) if last is not None else dict.fromkeys(FAILURE_REASONS, 0)
        new_failures = int(status.goals_failed) - sum(failed.values())
        if new_failures > 0:  # (a recording without reasons only ever failed for want of a path)
            failed[failure_reason(str(status.state)) or "unreachable"] += new_failures
        self.statuses[ns].append(
            (
                m.stamp_ns,
                int(status.goals_total),
                int(status.goals_reached),
                int(status.goals_failed),
                tuple(status.blocked_by),
            )
        )
        self.navigation[ns] = (
            (int(status.goals_reached), int(status.goals_total), float(status.planned_length_m), failed),
            hits,
            prev,
        )

    def _collision(self, m: Message, ns: str) -> None:
        last, hits, prev = self.navigation[ns]
        hit = bool(m.msg.in_collision)
        self.navigation[ns] = (last, hits + int(hit and not prev), hit)

    def read(self, reader: RecordingReader) -> RecordedRows:
        for m in reader.messages(self.topics):
            self.add(m)
        return self

    def truth_tables(self) -> dict[str, pl.DataFrame]:
        return {ns: pl.DataFrame(r, schema=POSE_SCHEMA, orient="row") for ns, r in self.truth.items()}

    def estimate_tables(self) -> dict[str, pl.DataFrame]:
        return {ns: status_table(est, status) for ns, (est, status) in self.estimates.items()}


def ground_truth(reader: RecordingReader) -> dict[str, pl.DataFrame]:
    """map -> ground_truth/<ns>/base_link of every agent from /ground_truth/poses, by namespace."""
    return RecordedRows().read(reader).truth_tables()


def emergency_stops(reader: RecordingReader, ns: str) -> list[int]:
    """Stamps where the robot's applied command drops from driving (>= 0.5 m/s) to standing."""
    stamps, prev = [], 0.0
    for m in reader.messages([f"/{ns}/cmd_vel"]):
        v = float(m.msg.twist.linear.x)
        if prev >= 0.5 and abs(v) <= 0.05:
            stamps.append(m.stamp_ns)
        prev = v
    return stamps


def estimates_from_recording(reader: RecordingReader, namespaces: Iterable[str]) -> dict[str, pl.DataFrame]:
    """Pose estimates joined with localization status, per agent: stamp, x, y, yaw, observed, valid, age."""
    return RecordedRows(truth=False, estimates_of=namespaces).read(reader).estimate_tables()


def status_table(estimates: list[tuple], status: list[tuple]) -> pl.DataFrame:
    est = pl.DataFrame(estimates, schema=POSE_SCHEMA, orient="row")
    st = pl.DataFrame(
        status,
        schema={"stamp_ns": pl.Int64, "observed": pl.Boolean, "valid": pl.Boolean, "age_s": pl.Float64},
        orient="row",
    )
    return st.join(est, on="stamp_ns", how="left").sort("stamp_ns")


@dataclass(frozen=True)
class Visibility:
    cameras: dict[str, CameraModel]
    kind: AgentType

    def in_view(self, x: float, y: float, yaw: float) -> bool:
        return bool(self.in_view_many(np.array([[x, y, yaw]]))[0])

    def in_view_many(self, poses_xyyaw: NDArray[np.float64]) -> NDArray[np.bool_]:
        """For base_link poses (N, 3): is the whole marker seen by some camera (``markers_in_view``)?"""
        assert self.kind.marker_xyz is not None
        return markers_in_view(self.cameras.values(), self.kind.marker_xyz, poses_xyyaw, size_m=MARKER_SIZE_M)


def localization_metrics(
    truth: dict[str, pl.DataFrame], estimates: dict[str, pl.DataFrame], visibility: dict[str, Visibility]
) -> dict[str, float]:
    """``localization.*`` over all agents with a marker, and per agent ``localization.<ns>.*``."""
    out: dict[str, float] = {}
    all_err, all_yaw, all_avail, all_age = [], [], [], []
    for ns in sorted(estimates):
        table = estimates[ns].join(
            truth[ns].rename({"x": "gx", "y": "gy", "yaw": "gyaw"}), on="stamp_ns", how="inner"
        )
        valid = table.filter(pl.col("valid") & pl.col("x").is_not_null())
        err = np.hypot((valid["x"] - valid["gx"]).to_numpy(), (valid["y"] - valid["gy"]).to_numpy())
        yaw_err = np.degrees(np.abs(wrap_angle((valid["yaw"] - valid["gyaw"]).to_numpy())))
        vis = visibility[ns]
        in_view = vis.in_view_many(table.select("gx", "gy", "gyaw").to_numpy())
        observed = table["observed"].to_numpy()
        avail = observed[in_view] if in_view.any() else np.array([])
        ages = valid["age_s"].to_numpy()
        prefix = f"localization.{ns}."
        out[prefix + "ate_xy_rmse_m"] = float(np.sqrt(np.mean(err**2))) if len(err) else float("nan")
        out[prefix + "ate_xy_max_m"] = float(err.max()) if len(err) else float("nan")
        out[prefix + "yaw_rmse_deg"] = float(np.sqrt(np.mean(yaw_err**2))) if len(yaw_err) else float("nan")
        out[prefix + "availability"] = float(avail.mean()) if len(avail) else float("nan")
        out[prefix + "latency_s"] = float(ages.mean()) if len(ages) else float("nan")
        out[prefix + "ticks_in_view"] = float(in_view.sum())
        out[prefix + "ticks_valid"] = float(len(valid))
        all_err.append(err)
        all_yaw.append(yaw_err)
        all_avail.append(avail)
        all_age.append(ages)
    if estimates:
        err, yaw_err, avail, ages = (
            np.concatenate(a) if a else np.array([]) for a in (all_err, all_yaw, all_avail, all_age)
        )
        out["localization.ate_xy_rmse_m"] = float(np.sqrt(np.mean(err**2))) if len(err) else float("nan")
        out["localization.ate_xy_max_m"] = float(err.max()) if len(err) else float("nan")
        out["localization.yaw_rmse_deg"] = (
            float(np.sqrt(np.mean(yaw_err**2))) if len(yaw_err) else float("nan")
        )
        out["localization.availability"] = float(avail.mean()) if len(avail) else float("nan")
        out["localization.latency_s"] = float(ages.mean()) if len(ages) else float("nan")
    return out


def navigation_metrics(
    reader: RecordingReader | RecordedRows,
    truth: dict[str, pl.DataFrame],
    namespaces: Iterable[str],
    *,
    kinds: Mapping[str, AgentType] | None = None,
) -> dict[str, float]:
    """``navigation.*`` from the recorded navigation status, collision sensor and ground truth
    (read from ``reader``, or already collected); with the robots' ``kinds`` also ``fleet.*``
    (:mod:`~simlan_data.evaluation.fleet_metrics`)."""
    namespaces = list(namespaces)
    rows = (
        reader
        if isinstance(reader, RecordedRows)
        else RecordedRows(truth=False, navigation_of=namespaces).read(reader)
    )
    out: dict[str, float] = {}
    reached = total = collisions = 0
    failed_all = dict.fromkeys(FAILURE_REASONS, 0)
    ratios = []
    for ns in namespaces:
        last, hits, _ = rows.navigation[ns]
        gt = truth.get(ns)
        driven = (
            float(np.sum(np.hypot(np.diff(gt["x"].to_numpy()), np.diff(gt["y"].to_numpy()))))
            if gt is not None and gt.height > 1
            else 0.0
        )
        prefix = f"navigation.{ns}."
        g_reached, g_total, planned, failed = (
            last if last is not None else (0, 0, 0.0, dict.fromkeys(FAILURE_REASONS, 0))
        )
        failed = dict(failed)
        failed["timeout"] += max(0, g_total - g_reached - sum(failed.values()))  # left, not recorded
        out[prefix + "goals_reached"] = float(g_reached)
        out[prefix + "goals_total"] = float(g_total)
        out[prefix + "goals_failed"] = float(sum(failed.values()))
        for reason, count in failed.items():
            out[prefix + "goals_failed." + reason] = float(count)
            failed_all[reason] += count
        out[prefix + "collisions"] = float(hits)
        out[prefix + "driven_m"] = driven
        if planned > 0 and g_reached == g_total:
            out[prefix + "path_length_ratio"] = driven / planned
            ratios.append(driven / planned)
        reached += g_reached
        total += g_total
        collisions += hits
    out["navigation.goals_reached"] = float(reached)
    out["navigation.goals_total"] = float(total)
    out["navigation.goals_failed"] = float(sum(failed_all.values()))
    for reason, count in failed_all.items():
        out["navigation.goals_failed." + reason] = float(count)
    out["navigation.collisions"] = float(collisions)
    if ratios:
        out["navigation.path_length_ratio"] = float(np.mean(ratios))
    if kinds is not None:
        out.update(fleet_metrics(truth, {ns: rows.statuses[ns] for ns in namespaces}, kinds))
    return out


def seconds(stamp_ns: int) -> float:
    return stamp_ns / NS_PER_S
