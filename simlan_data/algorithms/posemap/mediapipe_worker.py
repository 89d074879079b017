"""MediaPipe Pose worker: runs in its own environment (``.venv-mediapipe``), fed RGB images on stdin.

    .venv-mediapipe/bin/python simlan_data/gpss/posemap/mediapipe_worker.py

Imports only the standard library, numpy and mediapipe (0.10.14, whose wheel carries
pose_landmark_full: ``model_complexity=1`` works offline; 0 and 2 try to download and fail).
Protocol: see ``MediaPipeEstimator`` in estimators.py. Each image is processed on its own
(``static_image_mode=True``): dataset samples are unrelated poses, not a video.
"""

from __future__ import annotations

import argparse
import json
import sys


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--min-detection-confidence", type=float, default=0.5)
    args = parser.parse_args()
    out = sys.stdout
    try:
        import mediapipe as mp
        import numpy as np

        pose = mp.solutions.pose.Pose(
            static_image_mode=True,
            model_complexity=1,
            min_detection_confidence=args.min_detection_confidence,
        )
    except Exception as err:  # report why instead of a traceback the parent cannot show
        out.write(json.dumps({"ready": False, "error": f"{type(err).__name__}: {err}"}) + "\n")
        out.flush()
        return 1
    out.write(json.dumps({"ready": True, "mediapipe": mp.__version__}) + "\n")
    out.flush()
    stdin = sys.stdin.buffer
    while True:
        line = stdin.readline()
        if not line:
            return 0
        head = json.loads(line)
        h, w = int(head["h"]), int(head["w"])
        data = stdin.read(h * w * 3)
        rgb = np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)
        result = pose.process(rgb)
        rows = []
        if result.pose_landmarks is not None:
            rows = [[lm.x, lm.y, lm.z, lm.visibility] for lm in result.pose_landmarks.landmark]
        out.write(json.dumps({"landmarks": rows}) + "\n")
        out.flush()


if __name__ == "__main__":
    sys.exit(main())
