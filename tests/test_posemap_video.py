"""Images and video files as the drive's source (issue 26 item 3): ``experiment=posemap_video``.

Real decoding (OpenCV), real MediaPipe Pose 0.10.14 in ``.venv-mediapipe``, a real trained
one-camera model, real runs read back from their bags. Where ``.venv-mediapipe`` is missing (a
fresh checkout, CI, which installs ``.[test]`` only: MediaPipe needs numpy<2, so it cannot be an
extra), the ``mediapipe_python`` fixture creates it with ``scripts/mediapipe_env.sh`` (pip
downloads mediapipe 0.10.14, about a minute); the tests that need it skip, with the script's own
reason, only where it cannot be created (offline without a mirror, a Python without its wheels).
The round trip renders a motion with the twin, writes camera 502's frames to an mp4 and drives
from it.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
from skimage import data as skdata

from conftest import REPO, made_once, run_cli
from simlan_data.algorithms.posemap.source import hold_undetected
from simlan_data.recording import schema
from simlan_data.recording.reader import RecordingReader

MEDIAPIPE_ENV = REPO / ".venv-mediapipe"
MEDIAPIPE = MEDIAPIPE_ENV / "bin" / "python"
SMALL = (
    "world.fidelity=empty",
    "cameras.width=480",
    "cameras.height=270",
    "cameras.ids=[502]",
    "progress=false",
)
JOINTS = schema.agent_topics("robot_agent_1")["joint_states"].name
PERIOD_NS = 200_000_000  # 5 Hz: the camera rate of the posemap experiments


def _mediapipe_works() -> bool:
    if not MEDIAPIPE.exists():
        return False
    probe = [str(MEDIAPIPE), "-c", "import mediapipe as mp; mp.solutions.pose.Pose(model_complexity=1)"]
    return subprocess.run(probe, capture_output=True, timeout=300, check=False).returncode == 0


@pytest.fixture(scope="session")
def mediapipe_python(tmp_path_factory: pytest.TempPathFactory) -> str:
    """The MediaPipe environment's interpreter, made by ``scripts/mediapipe_env.sh`` where missing."""

    def make(root: Path) -> None:
        why = ""
        if not _mediapipe_works():
            script = [str(REPO / "scripts" / "mediapipe_env.sh"), str(MEDIAPIPE_ENV)]
            proc = subprocess.run(
                ["bash", *script], capture_output=True, text=True, timeout=1200, check=False
            )
            lines = (proc.stderr or proc.stdout).strip().splitlines()
            if proc.returncode != 0 or not _mediapipe_works():
                why = lines[-1] if lines else f"exit {proc.returncode}"
        (root / "why_not").write_text(why)

    why = (made_once(tmp_path_factory, "mediapipe_env", make) / "why_not").read_text()
    if why:
        pytest.skip(f"MediaPipe's environment cannot be created here (bash scripts/mediapipe_env.sh: {why})")
    return str(MEDIAPIPE)


@pytest.fixture(scope="session")
def one_camera_model(trained: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A model of camera 502 alone (image features, the kinematic fit) on the shared tiny dataset."""
    ds, _ = trained

    def make(root: Path) -> None:
        proc = run_cli(
            "experiment=posemap_train",
            f"posemap.dataset={ds}",
            "posemap.cameras=[502]",
            "posemap.features=image",
            "posemap.epochs=20",
            "posemap.width=64",
            "posemap.layers=2",
            "posemap.lr=0.003",
            "algorithms.posemap.refine_starts=2",
            "progress=false",
            f"hydra.run.dir={root / 'train'}",
        )
        assert proc.returncode == 0, proc.stderr

    return made_once(tmp_path_factory, "posemap_one_camera", make) / "train"


def _one_error_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: "), stderr
    return lines[0]


def _write_png(path: Path, rgb: np.ndarray) -> Path:
    assert cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return path


def _messages(run: Path, topic: str) -> list:
    with RecordingReader(run / "recording") as bag:
        return list(bag.messages([topic]))


def _predicted(model: Path, landmarks: np.ndarray) -> np.ndarray:
    from simlan_data.algorithms.posemap.training import TrainedMapper

    return TrainedMapper(str(model), starts=2).predict(landmarks[:, None])


# ------------------------------------------------------------------------------- the round trip
@pytest.mark.slow
def test_video_rendered_by_the_twin_drives_the_humanoid(
    mediapipe_python: str, one_camera_model: Path, tmp_path: Path
) -> None:
    """Motion -> camera 502's frames as an mp4 -> MediaPipe -> model -> the driven humanoid, whose
    joints are the model's prediction of the recorded landmarks, and near the rendered joints."""
    motion = tmp_path / "motion"
    proc = run_cli("experiment=posemap_motion", "duration_s=2.0", *SMALL, f"hydra.run.dir={motion}")
    assert proc.returncode == 0, proc.stderr
    video = tmp_path / "motion.mp4"
    frames = _messages(motion, "/camera_502/image_raw/compressed")
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"mp4v"), 5.0, (480, 270))
    for m in frames:
        writer.write(cv2.imdecode(np.frombuffer(bytes(m.msg.data), np.uint8), cv2.IMREAD_COLOR))
    writer.release()

    drive = tmp_path / "drive"
    proc = run_cli(
        "experiment=posemap_video",
        f"posemap.source={video}",
        f"posemap.mediapipe_python={mediapipe_python}",
        f"algorithms.posemap.model={one_camera_model}",
        "algorithms.posemap.refine_starts=2",
        "duration_s=2.0",
        *SMALL,
        f"hydra.run.dir={drive}",
    )
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((drive / "metrics.json").read_text())
    assert metrics["posemap.source.frames"] == 10  # 2 s of the 5 Hz video, read at its own rate
    assert metrics["posemap.source.fps"] == 5.0
    assert metrics["posemap.source.detected_fraction"] >= 0.9
    images = _messages(drive, schema.POSEMAP_SOURCE_IMAGE)
    marks = _messages(drive, schema.POSEMAP_SOURCE_LANDMARKS)
    assert [m.stamp_ns for m in images] == [k * PERIOD_NS for k in range(10)]
    assert [m.stamp_ns for m in marks] == [k * PERIOD_NS for k in range(10)]
    first = cv2.imdecode(np.frombuffer(bytes(images[0].msg.data), np.uint8), cv2.IMREAD_COLOR)
    assert first.shape == (270, 480, 3)
    assert all(m.msg.estimator == "mediapipe" and (m.msg.width, m.msg.height) == (480, 270) for m in marks)
    landmarks = np.stack(
        [np.stack([m.msg.x, m.msg.y, m.msg.z, m.msg.visibility], axis=1) for m in marks if m.msg.detected]
    ).astype(np.float32)
    assert len(landmarks) == 10, "the test expects MediaPipe to find the rendered humanoid in every frame"
    driven = {m.stamp_ns: np.asarray(m.msg.position) for m in _messages(drive, JOINTS)}
    got = np.stack([driven[k * PERIOD_NS] for k in range(10)])
    assert np.allclose(got, _predicted(one_camera_model, landmarks), atol=1e-6)
    # the round trip: against the joints the twin rendered (frame k at the motion's k-th stamp)
    truth = {m.stamp_ns: np.asarray(m.msg.position) for m in _messages(motion, JOINTS)}
    rendered = np.stack([truth[m.stamp_ns] for m in frames[:10]])
    mae = float(np.abs(got - rendered).mean())
    assert 0 < mae < 0.5, mae  # a 600-sample model; benchmarks/posemap_video.py measures the figure


# ------------------------------------------------------------------------------ a photograph
@pytest.mark.slow
def test_photograph_and_image_folder_drive_the_humanoid(
    mediapipe_python: str, one_camera_model: Path, tmp_path: Path
) -> None:
    """scikit-image's astronaut (a real photograph) and a blank image in a folder: MediaPipe finds
    her in the first; through the second the humanoid holds her pose."""
    folder = tmp_path / "images"
    folder.mkdir()
    astronaut = skdata.astronaut()
    _write_png(folder / "a_astronaut.png", astronaut)
    _write_png(folder / "b_blank.png", np.full_like(astronaut, 128))
    run = tmp_path / "run"
    proc = run_cli(
        "experiment=posemap_video",
        f"posemap.source={folder}",
        f"posemap.mediapipe_python={mediapipe_python}",
        "posemap.source_fps=2.5",
        f"algorithms.posemap.model={one_camera_model}",
        "algorithms.posemap.refine_starts=2",
        "duration_s=1.0",
        *SMALL,
        f"hydra.run.dir={run}",
    )
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["posemap.source.frames"] == 2
    assert metrics["posemap.source.detected_fraction"] == 0.5
    marks = _messages(run, schema.POSEMAP_SOURCE_LANDMARKS)
    assert [(m.stamp_ns, m.msg.detected) for m in marks] == [(0, True), (400_000_000, False)]
    image = _messages(run, schema.POSEMAP_SOURCE_IMAGE)[0].msg
    decoded = cv2.cvtColor(
        cv2.imdecode(np.frombuffer(bytes(image.data), np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB
    )
    assert decoded.shape == astronaut.shape
    assert np.abs(decoded.astype(int) - astronaut).mean() < 4  # the photograph, as JPEG
    lm = marks[0].msg
    nose = np.array([lm.x[0], lm.y[0]]) * 512
    assert np.linalg.norm(nose - [225, 130]) < 40  # her face (pixel found by eye in the 512x512 photo)
    states = _messages(run, JOINTS)
    expected = _predicted(
        one_camera_model, np.stack([lm.x, lm.y, lm.z, lm.visibility], axis=1)[None].astype(np.float32)
    )[0]
    assert all(np.allclose(m.msg.position, expected, atol=1e-6) for m in states)  # held through the blank


def test_frames_without_a_person_hold_the_last_pose() -> None:
    predicted = np.array([1.0, 4.0])[:, None] * np.ones((1, 47))  # frames 1 and 4 show a person
    held = hold_undetected(predicted, np.array([False, True, False, False, True]))
    assert held[:, 0].tolist() == [1, 1, 1, 1, 4]


# ------------------------------------------------------------------------------- bad sources
def _broken_video(tmp_path: Path) -> Path:
    path = tmp_path / "broken.mp4"
    path.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    return path


def _video_at(tmp_path: Path, fps: float) -> Path:
    path = tmp_path / f"at_{fps:g}.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), fps, (64, 48))
    for _ in range(3):
        writer.write(np.zeros((48, 64, 3), np.uint8))
    writer.release()
    return path


@pytest.mark.parametrize(
    ("source", "extra", "expected"),
    [
        (_broken_video, (), "source unreadable in posemap.source="),
        (lambda p: p / "none.mp4", (), "source not found in posemap.source="),
        (lambda p: p, (), "no images in the source folder in posemap.source="),
        (lambda p: _video_at(p, 1000.0), (), "invalid posemap.source_fps=1000.0"),
        (lambda p: _video_at(p, 5.0), ("posemap.source_fps=-5",), "invalid posemap.source_fps=-5"),
        (lambda p: _video_at(p, 5.0), ("posemap.drive=/tmp",), "invalid posemap.source="),
        (None, (), "invalid posemap.source='' in config: experiment=posemap_video drives"),
    ],
    ids=["unreadable", "missing", "empty_folder", "header_fps", "given_fps", "with_drive", "no_source"],
)
def test_bad_source_is_one_line_exit_2_and_nothing_written(
    tmp_path: Path, source, extra, expected: str
) -> None:
    src = tmp_path / "src"
    src.mkdir()
    args = [] if source is None else [f"posemap.source={source(src)}"]
    run = tmp_path / "run"
    proc = run_cli("experiment=posemap_video", *args, *extra, "algorithms.posemap.model=/no/model", *SMALL,
                   f"hydra.run.dir={run}")  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    line = _one_error_line(proc.stderr)
    assert expected in line, line
    assert not (run / "recording").exists() and not (run / "metrics.json").exists()


@pytest.mark.slow
def test_source_needs_a_one_camera_model(trained: tuple[Path, Path], tmp_path: Path) -> None:
    _, four_cameras = trained
    photo = _write_png(tmp_path / "astronaut.png", skdata.astronaut())
    proc = run_cli("experiment=posemap_video", f"posemap.source={photo}", f"algorithms.posemap.model={four_cameras}",
                   *SMALL, f"hydra.run.dir={tmp_path / 'run'}")  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    line = _one_error_line(proc.stderr)
    assert "pose mapper reads several cameras" in line and "posemap.cameras=[502]" in line
    assert not (tmp_path / "run" / "recording").exists()


@pytest.mark.slow
def test_source_without_a_person_is_one_line(
    mediapipe_python: str, one_camera_model: Path, tmp_path: Path
) -> None:
    blank = _write_png(tmp_path / "wall.png", np.full((270, 480, 3), 90, np.uint8))
    run = tmp_path / "run"
    proc = run_cli("experiment=posemap_video", f"posemap.source={blank}", f"posemap.mediapipe_python={mediapipe_python}",
                   f"algorithms.posemap.model={one_camera_model}", *SMALL, f"hydra.run.dir={run}")  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    line = _one_error_line(proc.stderr)
    assert (
        "no person in the source in posemap.source=" in line
        and "found no person in any of its 1 frames" in line
    )
    assert not (run / "recording").exists() and not (run / "metrics.json").exists()
