"""The camera recorder's reuse of encodings (sim/camera_recording.py): a frame the render reports
unchanged reuses the last encoding, but not after a lost frame, whose change it never saw. Real
RecordingWriter, JPEG encoding and bag read back."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simlan_data.config.schema import RecordingConfig
from simlan_data.geometry.calibration import load_calibration
from simlan_data.recording.codecs import decode_compressed
from simlan_data.recording.reader import RecordingReader
from simlan_data.recording.writer import RecordingWriter
from simlan_data.sim.camera_recording import CameraRecorder
from simlan_data.sim.rendering import CameraImages

W, H = 320, 180


def _recorded_images(path: Path, frames: list[tuple[int, np.ndarray, bool]]) -> list[np.ndarray]:
    """Record (frame index, image, changed) colour frames of one camera; the images read back."""
    camera = load_calibration(160).camera.scaled(W, H)
    with RecordingWriter(path, encode_threads=2) as writer:
        recorder = CameraRecorder(writer, RecordingConfig(), ["rgb"], depth_every=1, semantic_every=1)
        for index, rgb, changed in frames:
            recorder.record(index * 200_000_000, index, camera, CameraImages(rgb, None, None, changed))
        topic = recorder.topics(camera.camera_id)["rgb"].name
    with RecordingReader(path, check_format=False) as reader:
        return [decode_compressed(m.msg.format, m.msg.data) for m in reader.messages([topic])]


def test_an_unchanged_frame_after_a_lost_one_is_encoded_again(tmp_path: Path) -> None:
    grey, white = np.full((H, W, 3), 60, np.uint8), np.full((H, W, 3), 230, np.uint8)
    # frame 1 was lost: its render (white) changed, and frame 2 shows that render again
    images = _recorded_images(tmp_path / "lost", [(0, grey, True), (2, white, False), (3, white, False)])
    assert [round(float(im.mean())) for im in images] == [60, 230, 230]
    # without a lost frame, changed=False reuses the encoding (the render's word is trusted)
    images = _recorded_images(tmp_path / "kept", [(0, grey, True), (1, white, False)])
    assert [round(float(im.mean())) for im in images] == [60, 60]
