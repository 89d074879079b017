"""GPSS localization on real rendered frames of a real run: per-camera marker poses, fusion,
the filter's observability report, replay == live, and our ATE against evo's APE."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import polars as pl
import pytest

from conftest import run_cli
from simlan_data.algorithms.localization import Localizer, LocalizerParams
from simlan_data.algorithms.markers import POSE_METHODS, MarkerDetector, MarkerMount, fuse
from simlan_data.constants import NS_PER_S
from simlan_data.evaluation.metrics import (
    Visibility,
    estimates_from_recording,
    ground_truth,
    localization_metrics,
)
from simlan_data.geometry.rotations import wrap_angle
from simlan_data.geometry.transforms import Transform
from simlan_data.recording.cameras import cameras_in_recording
from simlan_data.recording.reader import RecordingReader
from simlan_data.world.agent_types import AGENT_TYPES, MARKER_SIZE_M

NS = "robot_agent_1"
TRUCK = AGENT_TYPES["pallet_truck"]
assert TRUCK.marker_xyz is not None
MOUNT = MarkerMount(NS, 1, MARKER_SIZE_M, TRUCK.marker_xyz[2], (TRUCK.marker_xyz[0], TRUCK.marker_xyz[1]))


@pytest.fixture(scope="module")
def frames(short_run: Path):
    """Every camera image of the short run with the truck's true marker pose at its stamp."""
    with RecordingReader(short_run / "recording") as reader:
        cameras = cameras_in_recording(reader)
        truth = ground_truth(reader)[NS]
        images = [
            (m.stamp_ns, m.topic.split("/")[1].removeprefix("camera_"), bytes(m.msg.data))
            for m in reader.messages([f"/camera_{c}/image_raw/compressed" for c in cameras])
        ]
    gt = {row[0]: row[1:] for row in truth.iter_rows()}
    out = []
    for stamp, cid, jpeg in images:
        x, y, yaw = gt[stamp]
        marker = Transform.from_pose2d(x, y, yaw) @ Transform.from_pose2d(
            *MOUNT.offset_xy_m, 0.0, MOUNT.height_m
        )
        gray = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_GRAYSCALE)
        out.append((stamp, cid, gray, (*marker.translation[:2], marker.yaw())))
    return cameras, out


def _observations(cameras, frames, method: str):
    """Per (stamp, camera): the observation of marker 1 and its true pose."""
    detector = MarkerDetector()
    pose = POSE_METHODS[method]
    out = {}
    for stamp, cid, gray, true_pose in frames:
        dets = [d for d in detector.detect(cid, gray) if d.marker_id == 1]
        if dets:
            obs = pose(cameras[cid], dets[0], MOUNT)
            if obs is not None:
                out[(stamp, cid)] = (obs, true_pose)
    return out


def _errors(obs, true_pose) -> tuple[float, float]:
    return float(np.hypot(obs.x_m - true_pose[0], obs.y_m - true_pose[1])), float(
        np.degrees(abs(wrap_angle(obs.yaw_rad - true_pose[2])))
    )


@pytest.mark.parametrize(
    ("method", "max_median_cm", "max_median_deg"), [("ground", 0.8, 1.0), ("pnp", 6.0, 2.0)]
)
def test_per_camera_marker_poses_against_ground_truth(frames, method, max_median_cm, max_median_deg) -> None:
    cameras, images = frames
    observations = _observations(cameras, images, method)
    assert len({cid for _, cid in observations}) >= 2, "the truck is seen by at least two cameras"
    errors = np.array([_errors(o, t) for o, t in observations.values()])
    assert len(errors) >= 20
    assert np.median(errors[:, 0]) * 100 < max_median_cm, np.median(errors[:, 0])
    assert np.median(errors[:, 1]) < max_median_deg
    # the uncertainty model is honest: errors mostly within 3 sigma of position
    sigmas = np.array([o.sigma_xy_m for o, _ in observations.values()])
    assert np.mean(errors[:, 0] < 3 * sigmas) > 0.8


CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)


def _undistort_iter(src, K, D, *, criteria):
    """OpenCV 4's undistortPointsIter; OpenCV 5 folded it into undistortPoints."""
    if hasattr(cv2, "undistortPointsIter"):
        return cv2.undistortPointsIter(src, K, D, None, None, criteria)
    return cv2.undistortPoints(src, K, D, criteria=criteria)


def test_ground_constraint_pose_against_an_opencv_reference(frames) -> None:
    """The ground-constraint pose (plain floats) step by step with OpenCV: corners undistorted by
    cv2.undistortPointsIter, rays onto the marker's plane, the square's centre and yaw, the ideal
    square back through cv2.projectPoints for the reprojection error."""
    cameras, images = frames
    detector = MarkerDetector()
    checked = 0
    for _, cid, gray, _ in images[::2]:
        cam = cameras[cid]
        for det in detector.detect(cid, gray):
            if det.marker_id != 1:
                continue
            obs = POSE_METHODS["ground"](cam, det, MOUNT)
            assert obs is not None
            pixels = det.corners_px.reshape(-1, 1, 2)
            xy = _undistort_iter(pixels, cam.K, cam.D, criteria=CRITERIA).reshape(-1, 2)
            rays = cam.world_from_camera.rotation @ np.c_[xy, np.ones(4)].T
            s = (MOUNT.height_m - cam.position[2]) / rays[2]
            p = cam.position[:2, None] + s * rays[:2]  # (2, 4): TL, TR, BR, BL on the plane
            x_axis = (p[:, 1] - p[:, 0]) + (p[:, 2] - p[:, 3])
            y_axis = (p[:, 0] - p[:, 3]) + (p[:, 1] - p[:, 2])
            v = x_axis / np.linalg.norm(x_axis) + np.array([y_axis[1], -y_axis[0]]) / np.linalg.norm(y_axis)
            yaw = np.arctan2(v[1], v[0])
            np.testing.assert_allclose([obs.x_m, obs.y_m], p.mean(axis=1), rtol=0, atol=1e-7)
            assert abs(wrap_angle(obs.yaw_rad - yaw)) < 1e-7
            ideal = Transform.from_pose2d(obs.x_m, obs.y_m, obs.yaw_rad, MOUNT.height_m).apply(
                MARKER_SIZE_M / 2 * np.array([[-1.0, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]])
            )
            rvec, _ = cv2.Rodrigues(cam.camera_from_world.rotation)
            uv, _ = cv2.projectPoints(ideal, rvec, cam.camera_from_world.translation, cam.K, cam.D)
            reproj = np.sqrt(np.mean(np.sum((uv.reshape(-1, 2) - det.corners_px) ** 2, axis=1)))
            assert abs(obs.reprojection_px - reproj) < 1e-6
            side = np.linalg.norm(det.corners_px - np.roll(det.corners_px, 1, axis=0), axis=1).mean()
            assert abs(obs.side_px - side) < 1e-9
            checked += 1
    assert checked >= 10


@pytest.mark.slow
def test_ground_constraint_beats_pnp_in_position(frames) -> None:
    cameras, images = frames
    ground = _observations(cameras, images, "ground")
    pnp = _observations(cameras, images, "pnp")
    common = sorted(set(ground) & set(pnp))
    g = np.array([_errors(*ground[k])[0] for k in common])
    p = np.array([_errors(*pnp[k])[0] for k in common])
    assert np.sqrt(np.mean(g**2)) < np.sqrt(np.mean(p**2))


def test_fusing_two_cameras_beats_either_alone(frames) -> None:
    cameras, images = frames
    obs = _observations(cameras, images, "ground")
    by_stamp: dict[int, dict[str, tuple]] = {}
    for (stamp, cid), v in obs.items():
        by_stamp.setdefault(stamp, {})[cid] = v
    pairs: dict[tuple[str, str], list[tuple[float, float, float]]] = {}
    for views in by_stamp.values():
        cids = sorted(views)
        for i, a in enumerate(cids):
            for b in cids[i + 1 :]:
                true_pose = views[a][1]
                x, y, _, _, _ = fuse([views[a][0], views[b][0]])
                fused = float(np.hypot(x - true_pose[0], y - true_pose[1]))
                pairs.setdefault((a, b), []).append((_errors(*views[a])[0], _errors(*views[b])[0], fused))
    assert pairs, "some frame shows the truck in two cameras"
    (a, b), rows = max(pairs.items(), key=lambda kv: len(kv[1]))
    err = np.array(rows)
    assert len(err) >= 5
    rmse = np.sqrt(np.mean(err**2, axis=0))
    assert rmse[2] < rmse[0] and rmse[2] < rmse[1], (a, b, rmse)


def test_an_agent_whose_marker_disappears_is_reported_unobserved_then_lost(frames) -> None:
    """Feed real frames, then the same frames with the marker painted over (real OpenCV on real
    images): the estimate stays observed, turns unobserved after 0.5 s, invalid after 1.5 s, and
    comes back as soon as the marker is seen again."""
    cameras, images = frames
    # a lost agent is searched for in the whole image of each camera every n-th frame (staggered
    # over the cameras); n = 2 here so that the 3 s recording shows the agent found again
    params = LocalizerParams(full_search_every=2)
    loc = Localizer(cameras, [MOUNT], params)
    stamps = sorted({s for s, *_ in images})
    period = stamps[1] - stamps[0]
    by_stamp: dict[int, list] = {}
    for stamp, cid, gray, _ in images:
        by_stamp.setdefault(stamp, []).append((cid, gray))
    hidden_from, shown_again = stamps[2], stamps[2] + 2 * NS_PER_S
    states = []
    for t in stamps:
        hide = hidden_from <= t < shown_again
        for cid, gray in by_stamp[t]:
            if hide:
                gray = gray.copy()
                for d in MarkerDetector().detect(cid, gray):
                    cv2.fillPoly(gray, [np.round(d.corners_px).astype(np.int32)], 128)
            if loc.search_plan(t, cid):
                loc.process_image(t, cid, gray=gray)
        loc.close_frame(t)
        e = loc.estimate(t).get(NS)
        states.append((t, hide, e is not None and e.observed, e is not None and e.valid))
    found_by = shown_again + (params.full_search_every - 1) * period
    assert found_by < stamps[-1]
    for t, hide, observed, valid in states:
        age = (t - hidden_from + period) / NS_PER_S  # since the last frame that showed the marker
        if t < hidden_from or t >= found_by:
            assert observed and valid, t
        elif hide and age > 0.5 + 1e-9:
            assert not observed, t
            assert valid == (age <= 1.5 + 1e-9), t
    assert any(h and not v for _, h, _, v in states), "the hidden period outlasts lost_timeout_s"


def test_replay_reproduces_the_live_estimates_exactly(short_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "replay"
    proc = run_cli(str(short_run / "recording"), "--out", str(out), module="simlan_data.replay")
    assert proc.returncode == 0, proc.stderr
    replayed = json.loads((out / "metrics.json").read_text())
    live = json.loads((short_run / "metrics.json").read_text())
    assert replayed["replay.localization.max_diff_to_live_m"] == 0.0
    for key in ("localization.ate_xy_rmse_m", "localization.yaw_rmse_deg", "localization.availability"):
        # estimates are identical; the recorded yaw went through a quaternion (1e-15 rad)
        assert replayed[key] == pytest.approx(live[key], rel=1e-12, abs=1e-12), key
    assert live["localization.ate_xy_rmse_m"] < 0.02
    assert live["localization.availability"] >= 0.995
    table = pl.read_parquet(out / "estimates.parquet")
    assert set(table["namespace"].unique()) == {NS}


def test_our_ate_agrees_with_evo_ape(short_run: Path) -> None:
    from evo.core import metrics, sync
    from evo.core.trajectory import PoseTrajectory3D
    from scipy.spatial.transform import Rotation

    with RecordingReader(short_run / "recording") as reader:
        truth = ground_truth(reader)
        est = estimates_from_recording(reader, [NS])
        cameras = cameras_in_recording(reader)
    ours = localization_metrics(truth, est, {NS: Visibility(cameras, TRUCK)})

    def trajectory(table: pl.DataFrame) -> PoseTrajectory3D:
        xyz = np.column_stack([table["x"].to_numpy(), table["y"].to_numpy(), np.zeros(table.height)])
        quat = Rotation.from_euler("z", table["yaw"].to_numpy()[:, None]).as_quat(scalar_first=True)
        return PoseTrajectory3D(xyz, quat, table["stamp_ns"].to_numpy() / NS_PER_S)

    estimated = est[NS].filter(pl.col("valid") & pl.col("x").is_not_null())
    ref, traj = sync.associate_trajectories(trajectory(truth[NS]), trajectory(estimated), max_diff=1e-4)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, traj))  # no alignment: the cameras are fixed in the world
    stats = ape.get_all_statistics()
    assert ours[f"localization.{NS}.ate_xy_rmse_m"] == pytest.approx(stats["rmse"], rel=1e-9, abs=1e-12)
    assert ours[f"localization.{NS}.ate_xy_max_m"] == pytest.approx(stats["max"], rel=1e-9, abs=1e-12)
    rot = metrics.APE(metrics.PoseRelation.rotation_angle_deg)
    rot.process_data((ref, traj))
    assert ours[f"localization.{NS}.yaw_rmse_deg"] == pytest.approx(
        rot.get_statistic(metrics.StatisticsType.rmse), rel=1e-6
    )


def test_detector_restricted_to_the_fleets_ids_finds_the_same_corners(frames) -> None:
    """Identifying candidates only against the fleet's codes (the speed-up) changes nothing about
    the markers found: same ids, bit-identical corners, full frames and regions alike."""
    _, data = frames
    everything, fleet, other = (
        MarkerDetector(),
        MarkerDetector(marker_ids=[1, 7]),
        MarkerDetector(marker_ids=[2]),
    )
    found = 0
    for _, cid, gray, _ in data[::4]:
        ref = everything.detect(cid, gray)
        got = fleet.detect(cid, gray)
        assert [d.marker_id for d in got] == [d.marker_id for d in ref if d.marker_id in (1, 7)]
        for a, b in zip(got, [d for d in ref if d.marker_id in (1, 7)]):
            np.testing.assert_array_equal(a.corners_px, b.corners_px)
        assert other.detect(cid, gray) == []
        for d in got:
            u0, v0 = np.floor(d.corners_px.min(axis=0) - 20).astype(int).clip(0)
            roi = (int(u0), int(v0), int(d.corners_px[:, 0].max() + 20), int(d.corners_px[:, 1].max() + 20))
            np.testing.assert_array_equal(
                fleet.detect(cid, gray, roi)[0].corners_px, everything.detect(cid, gray, roi)[0].corners_px
            )
            found += 1
    assert found >= 5
    assert MarkerDetector(marker_ids=[]).detect("160", data[0][2]) == []
    with pytest.raises(ValueError, match=r"marker ids must be in 0\.\.999"):
        MarkerDetector(marker_ids=[1000])


def test_background_reading_hands_over_items_in_order_and_raises_its_errors() -> None:
    import threading

    from simlan_data.errors import RecordingInputError
    from simlan_data.evaluation.localization_replay import in_background

    assert list(in_background(iter(range(50)), depth=3)) == list(range(50))

    def broken():
        yield 1
        raise RecordingInputError("message undecodable", "bag", "corrupt chunk", "recover it")

    items = in_background(broken(), depth=2)
    assert next(items) == 1  # the good item first, then the reader's error, in the consumer's thread
    with pytest.raises(RecordingInputError, match="message undecodable"):
        next(items)
    before = threading.active_count()
    items = in_background(iter(range(10_000)), depth=2)
    assert next(items) == 0
    items.close()  # the consumer stops early: the reading thread ends too
    assert threading.active_count() == before


def _reference_rois(loc: Localizer, t_ns: int, cid: str) -> list[tuple[int, int, int, int]]:
    """The regions one camera is planned to search, computed the plain way: each predicted
    marker's corners through ``CameraModel.project`` (OpenCV's distortion), one at a time."""
    from simlan_data.algorithms.markers import marker_corners_in_marker_frame

    cam = loc.cameras[cid]
    rois = []
    for mount, P, marker in loc._tick_predictions(t_ns).tracks:
        uv, ok = cam.project(marker.apply(marker_corners_in_marker_frame(mount.size_m)))
        if not ok.all():
            continue
        rng = float(np.linalg.norm(marker.translation - cam.position))
        sigma_m = float(np.sqrt(max(P[0, 0], P[1, 1]))) + 0.5 * mount.size_m * float(np.sqrt(P[2, 2]))
        margin = loc.params.roi_margin_px + 3.0 * sigma_m * cam.K[0, 0] / max(rng, 1e-3)
        u0, v0 = np.floor(uv.min(axis=0) - margin).astype(int)
        u1, v1 = np.ceil(uv.max(axis=0) + margin).astype(int)
        u0, v0, u1, v1 = max(0, u0), max(0, v0), min(cam.width, u1), min(cam.height, v1)
        if u1 - u0 >= 8 and v1 - v0 >= 8:
            rois.append((int(u0), int(v0), int(u1), int(v1)))
    return rois


def test_planned_regions_of_a_frame_set_equal_the_per_camera_projection() -> None:
    """All 12 real ceiling cameras and eight tracked robots spread over the warehouse, some at
    image borders, with growing uncertainty: the regions planned for a whole frame set at once
    (one array, the camera model's distortion in numpy) are exactly the ones each camera's own
    projection through OpenCV gives."""
    from simlan_data.algorithms.localization import PoseFix
    from simlan_data.geometry.calibration import available_camera_ids, load_calibration

    ids = [c for c in available_camera_ids() if 160 <= int(c) <= 171]
    assert len(ids) == 12
    cameras = {c: load_calibration(c).camera.scaled(960, 540) for c in ids}
    mounts = [
        MarkerMount(f"robot_agent_{i}", i, MARKER_SIZE_M, TRUCK.marker_xyz[2], TRUCK.marker_xyz[:2])
        for i in range(1, 9)
    ]
    loc = Localizer(cameras, mounts, LocalizerParams())
    rng = np.random.default_rng(4)
    centres = np.stack([cam.position[:2] for cam in cameras.values()])
    lo, hi = centres.min(axis=0) - 3.0, centres.max(axis=0) + 3.0
    compared = regions = 0
    for step in range(6):
        t = (step + 1) * NS_PER_S // 5
        for m in mounts:  # a fix per robot, then the plans for the next instant (extrapolated)
            x, y = rng.uniform(lo, hi)
            fix = PoseFix(
                m.namespace,
                t,
                float(x),
                float(y),
                float(rng.uniform(-np.pi, np.pi)),
                0.01 * (step + 1),
                0.02,
                (),
            )
            loc._pending.append((t, fix))
        loc.estimate(t)
        plans = loc.search_plans(t + NS_PER_S // 10, ids)
        for cid, plan in zip(ids, plans):
            assert plan != "full"  # every robot is tracked
            assert plan == _reference_rois(loc, t + NS_PER_S // 10, cid), (step, cid)
            compared += 1
            regions += len(plan)
    assert compared == 72 and regions >= 20, regions
