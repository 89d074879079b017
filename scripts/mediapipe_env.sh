#!/usr/bin/env bash
# Create the MediaPipe environment the `mediapipe` pose estimator runs in (README: Pose mapping).
#
#   bash scripts/mediapipe_env.sh [DIR]        (default DIR: .venv-mediapipe)
#
# MediaPipe 0.10.14 is the newest release whose wheel carries the pose models (pose_detection,
# pose_landmark_full): newer releases download them at run time, which fails offline. It needs
# numpy<2 and pulls opencv-contrib-python, which would shadow the main environment's headless
# OpenCV 5 and numpy 2: so it lives in its own environment, and simlan_data talks to it through a
# worker process (simlan_data/gpss/posemap/mediapipe_worker.py).
set -euo pipefail
DIR="${1:-.venv-mediapipe}"
PY="${PYTHON:-python3}"
"$PY" -m venv "$DIR"
"$DIR/bin/pip" install --quiet "mediapipe==0.10.14" "numpy<2"
"$DIR/bin/python" -c "import mediapipe as mp; mp.solutions.pose.Pose(model_complexity=1); print('mediapipe', mp.__version__, 'ready in $DIR')"
