"""Paths, file names and format constants: the one place they are spelled out."""

from __future__ import annotations

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent


def _data_dir(packaged: str, in_repo: str) -> Path:
    """Return the directory of packaged data: inside the wheel if installed, else in the checkout."""
    inside = PACKAGE_DIR / packaged
    return inside if inside.is_dir() else PACKAGE_DIR.parent / in_repo


ASSETS_DIR = _data_dir("_assets", "assets")
CONF_DIR = _data_dir("_conf", "conf")
EVALS_DIR = _data_dir("_evals", "evals")  # V&V suites (base.yaml) and accepted baselines
MSG_DIR = PACKAGE_DIR / "recording" / "msg"

CALIBRATION_DIR = ASSETS_DIR / "calibration"
LAYOUT_DIR = ASSETS_DIR / "layout"
URDF_DIR = ASSETS_DIR / "urdf"
MAPS_DIR = ASSETS_DIR / "maps"
MOTIONS_DIR = ASSETS_DIR / "motions"

# Recording format. Bump the minor for additive changes (new topics), the major when a reader of
# the previous major cannot interpret a recording any more.
FORMAT_VERSION = "1.1"  # 1.1: SafetyEvent.robot (was namespace, same bytes), ground_truth/<ns>/base_link frames, bag time = sim time + simlan.epoch_ns
FORMAT_MAJOR = 1

# Run directory layout (hydra.run.dir):
#   <run>/recording/            ROS 2 bag: metadata.yaml + recording.mcap
#   <run>/metrics.json          flat {"dotted.name": number}
#   <run>/report.md             human summary (+ report_*.png)
#   <run>/.hydra/               Hydra's resolved config, overrides
#   <run>/RUNNING               present while the run is in progress (absent once finished)
#   <run>/INCOMPLETE            the run crashed and its recording was recovered (replaces RUNNING)
#   <run>/INTERRUPTED           a signal (SIGTERM, SIGINT) stopped the run early; what ran is finalized
RECORDING_DIRNAME = "recording"
METRICS_FILENAME = "metrics.json"
REPORT_FILENAME = "report.md"
RUNNING_MARKER = "RUNNING"
INCOMPLETE_MARKER = "INCOMPLETE"
INTERRUPTED_MARKER = "INTERRUPTED"
DAMAGED_SUFFIX = ".damaged"  # a recovered file's original is kept beside it with this suffix
DEFAULT_OUTPUT_ROOT = "recordings"
EVALS_OUTPUT_ROOT = "recordings/evals"  # python -m simlan_data.evals SUITE writes <root>/<suite>_<time>/

NS_PER_S = 1_000_000_000
