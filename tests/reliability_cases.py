"""Bad inputs at every boundary, with the one-line error each must give (tests and benchmark).

Each table is a list of ``Case(id, ..., match)``; ``match`` is a regex the error line must match.
``benchmarks/reliability.py`` runs every case and counts them per boundary; the tests
parametrize over the same tables.
"""

from __future__ import annotations

import atexit
import os
import shutil
import struct
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import yaml

from simlan_data.config.validation import compose_config
from simlan_data.constants import CALIBRATION_DIR, LAYOUT_DIR, NS_PER_S, URDF_DIR
from simlan_data.errors import SimlanError
from simlan_data.geometry.calibration import load_calibration
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.reader import RecordingReader
from simlan_data.recording.writer import RecordingWriter
from simlan_data.sim.scene import load_cameras, load_inputs
from simlan_data.sim.urdf_check import check_urdf
from simlan_data.world.agent_types import AGENT_TYPES, AgentType
from simlan_data.world.layout import load_layout


@dataclass(frozen=True)
class Case:
    id: str
    arg: object  # overrides, or a function mutating a copy of the input
    match: str


# ------------------------------------------------------------------------------------ config
def _alias_bomb_dir() -> list[str]:
    """Overrides selecting a spawn list of ~400 bytes whose YAML aliases stand for 9**9 values
    (composition hung, killed after 150 s), from a ``hydra.searchpath`` directory."""
    conf = Path(tempfile.mkdtemp(prefix="alias_bomb_"))
    atexit.register(shutil.rmtree, conf, ignore_errors=True)  # (it left a directory in /tmp per run)
    (conf / "agents").mkdir()
    lines = ["# @package agents", "a0: &a0 [" + ",".join("x" * 9) + "]"]
    lines += [f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]
    (conf / "agents" / "boom.yaml").write_text("\n".join(lines) + "\n")
    return [f"hydra.searchpath=[file://{conf}]", "agents=boom"]


# fmt: off
CONFIG_CASES = [
    Case(*c)
    for c in [
        ("duration unit suffix", ["duration_s=60s"], r"invalid duration_s='60s' in config: expected Float, got str; units are part of the key's name \(duration_s: seconds\): write duration_s=60"),
        ("duration not a number", ["duration_s=abc"], r"invalid duration_s='abc' in config: expected Float"),
        ("duration negative", ["duration_s=-5"], r"invalid duration_s=-5.0 in config: must be within \(0, 86400\]"),
        ("duration nan", ["duration_s=nan"], r"invalid duration_s=nan in config: not a finite number; give a number in seconds"),
        ("duration inf", ["duration_s=inf"], r"invalid duration_s=inf in config: not a finite number"),
        ("seed negative", ["seed=-1"], r"invalid seed=-1 in config: must be within 0..2\^32-1"),
        ("seed not whole", ["seed=1.5"], r"invalid seed='1.5' in config: expected Integer, got float; give a whole number"),
        ("unknown top-level key", ["no_such_key=1"], r"unknown key no_such_key in config: Config has no such key"),
        ("misspelt key", ["recording.flush_period=2"], r"unknown key recording.flush_period in config: RecordingConfig has no such key; did you mean recording.flush_period_s\?"),
        ("misspelt key forced with +", ["+recording.fsynk=true"], r"unknown key recording.fsynk in config: RecordingConfig has no such key; did you mean recording.fsync\?"),
        ("agent key forced with +", ["+agents.robot_agent_1.typ=jackal"], r"unknown key agents.robot_agent_1.typ in config: AgentConfig has no such key; did you mean agents.robot_agent_1.type\?"),
        ("algorithm key forced with +", ["+algorithms.localizer.min_side=1"], r"unknown key algorithms.localizer.min_side in config: LocalizerParams has no such key; did you mean algorithms.localizer.min_side_px\?"),
        ("selected algorithm's key misspelt", ["algorithms/coordinator=fleet", "algorithms.coordinator.horizon_z=120"], r"unknown key algorithms.coordinator.horizon_z in config: FleetConfigSelection has no such key; did you mean algorithms.coordinator.horizon_s\?"),
        ("algorithm section given a value (found by the fuzzer)", ["algorithms.safety=0"], r"invalid algorithms.safety=0 in config: expected the selected algorithm's section \(its keys\), not a value; select an algorithm with algorithms/safety=NAME"),
        ("flush period zero", ["recording.flush_period_s=0"], r"invalid recording.flush_period_s=0.0 in config: must be > 0"),
        ("flush period negative", ["recording.flush_period_s=-1"], r"invalid recording.flush_period_s=-1.0 in config: must be > 0"),
        ("epoch not a date", ["recording.epoch=notadate"], r"invalid recording.epoch='notadate' in config: not an ISO 8601 date and time; give an ISO 8601 UTC time such as recording.epoch=2026-01-01T00:00:00Z"),
        ("epoch past 2037", ["recording.epoch=2040-01-01"], r"invalid recording.epoch='2040-01-01' in config: must lie within 1970-01-01 .. 2037-01-01"),
        ("unknown group option", ["cameras=gpsss"], r"unknown cameras=gpsss in config: no such option in conf/cameras/; did you mean gpss\? options: gpss, gpss_all"),
        ("no cameras", ["cameras.ids=[]"], r"invalid cameras.ids=\[\] in config: no camera selected"),
        ("camera twice", ["cameras.ids=[160,160]"], r"invalid cameras.ids=\[160, 160\] in config: an id appears twice"),
        ("unknown camera", ["cameras.ids=[999]"], r"unknown camera id 999 in cameras.ids in the packaged calibrations"),
        ("camera id not a number", ["cameras.ids=[abc]"], r"invalid cameras.ids\[0\]='abc' in config: expected Integer"),
        ("width not a number", ["cameras.width=abc"], r"invalid cameras.width='abc' in config: expected Integer"),
        ("width too small", ["cameras.width=10"], r"invalid cameras.width x height='10x540' in config: must be within 16x16"),
        ("aspect ratio", ["cameras.width=1000"], r"invalid cameras.width x height=1000x540 in config: camera 160 is 3840x2160"),
        ("camera rate not a divisor", ["cameras.rate_hz=7"], r"invalid cameras.rate_hz=7.0 in config: the simulation steps at world.physics_hz=240"),
        ("camera rate with unit", ["cameras.rate_hz=5Hz"], r"invalid cameras.rate_hz='5Hz' in config: expected Float, got str; units are part of the key's name \(rate_hz: hertz\): write cameras.rate_hz=5"),
        ("near beyond far", ["cameras.near_m=200"], r"invalid cameras.near_m/far_m=\(200.0, 100.0\) in config: need 0 < near_m < far_m"),
        ("unknown stream", ["cameras.streams=[rgb,thermal]"], r"invalid cameras.streams\[\]='thermal' in config: expected one of rgb, depth, semantic"),
        ("no rgb stream", ["cameras.streams=[depth]"], r"invalid cameras.streams=\['depth'\] in config: rgb is required"),
        ("calibration check choice", ["cameras.calibration_check=maybe"], r"invalid cameras.calibration_check='maybe' in config: expected one of warn, error"),
        ("calibration dir missing", ["cameras.calibration_dir=/nonexistent/calib"], r"unknown camera id 160 in cameras.ids in /nonexistent/calib: no intrinsic/extrinsic calibration pair with that id; use one of \(none found\)"),
        ("fidelity", ["world.fidelity=ultra"], r"invalid world.fidelity='ultra' in config: expected one of empty, light, medium, default"),
        ("physics rate not whole", ["world.physics_hz=240.5"], r"invalid world.physics_hz='240.5' in config: expected Integer, got float"),
        ("physics rate range", ["world.physics_hz=10"], r"invalid world.physics_hz=10 in config: must be within 60..2000 Hz"),
        ("gravity negative", ["world.gravity_mps2=-9.81"], r"invalid world.gravity_mps2=-9.81 in config: must be within 0..100 m/s\^2"),
        ("settle range", ["world.settle_s=100"], r"invalid world.settle_s=100.0 in config: must be within 0..60 s"),
        ("layout missing", ["world.layout=missing.csv"], r"layout file missing in .*missing.csv: no such file"),
        ("restitution range", ["world.physics.box.restitution=2"], r"invalid world.physics.\*.restitution=2.0 in config: must be in \[0, 1\]"),
        ("negative mass", ["world.physics.box.mass_kg=-1"], r"invalid world.physics.\*.mass_kg=-1.0 in config: must be >= 0"),
        ("rgb encoding", ["recording.rgb_encoding=webp"], r"invalid recording.rgb_encoding='webp' in config: expected one of jpeg, png, raw"),
        ("jpeg quality", ["recording.jpeg_quality=0"], r"invalid recording.jpeg_quality=0 in config: must be within 1..100"),
        ("jpeg quality list", ["recording.jpeg_quality=[1]"], r"invalid recording.jpeg_quality='\[1\]' in config: expected Integer, got list"),
        ("chunk compression", ["recording.compression=lz4"], r"invalid recording.compression='lz4' in config: expected one of zstd, none"),
        ("zstd level", ["recording.compression_level=50"], r"invalid recording.compression_level=50 in config: zstd levels are -7..22"),
        ("depth rate", ["recording.depth_rate_hz=2"], r"invalid recording.depth_rate_hz=2.0 in config: must divide the camera rate"),
        ("ground truth rate", ["recording.ground_truth_rate_hz=10"], r"invalid recording.ground_truth_rate_hz=10.0 in config: ground truth must be recorded at 50 Hz or more"),
        ("encode threads", ["recording.encode_threads=100"], r"invalid recording.encode_threads=100 in config: must be within 0..16"),
        ("control rate", ["control_rate_hz=7"], r"invalid control_rate_hz=7.0 in config: the simulation steps at world.physics_hz=240"),
        ("control rate zero (found by fuzzing)", ["control_rate_hz=0"], r"invalid control_rate_hz=0.0 in config: must be > 0"),
        ("control rate null (found by fuzzing)", ["~control_rate_hz", "+control_rate_hz=null"], r"invalid control_rate_hz=None in config: must not be null; give control_rate_hz a value"),
        ("live port", ["live.port=70000"], r"invalid live.port=70000 in config: a TCP port is within 0..65535"),
        ("live host empty", ["live.host=''"], r"invalid live.host='' in config: empty; use 127.0.0.1"),
        ("live view without a recording", ["live.foxglove=true", "recording.enabled=false"], r"invalid live.foxglove=True in config: the live view publishes the messages the recording writes, and recording.enabled=false writes none"),
        ("render backend", ["render.backend=vulkan"], r"invalid render.backend='vulkan' in config: expected one of auto, egl, tiny"),
        ("localization method", ["algorithms.localizer.method=magic"], r"invalid algorithms.localizer.method='magic' in config: expected one of ground, pnp"),
        ("localization source", ["localization.source=gps"], r"invalid localization.source='gps' in config: expected one of camera, ground_truth"),
        ("bias nan", ["algorithms.localizer.bias_m=[nan,0]"], r"invalid algorithms.localizer.bias_m\[0\]=nan in config: not a finite number; give a number in metres"),
        ("bias length", ["algorithms.localizer.bias_m=[1,2,3]"], r"invalid algorithms.localizer.bias_m=\[1.0, 2.0, 3.0\] in config: expected \[x_m, y_m\]"),
        ("timeouts order", ["algorithms.localizer.lost_timeout_s=0.1"], r"invalid algorithms.localizer.lost_timeout_s=0.1 in config: must be >= algorithms.localizer.unobserved_timeout_s"),
        ("delay in ms", ["algorithms.localizer.processing_delay_s=100"], r"invalid algorithms.localizer.processing_delay_s=100.0 in config: must be within 0..5 s"),
        ("grid resolution", ["navigation.resolution_m=5"], r"invalid navigation.resolution_m=5.0 in config: must be within 0.02..0.5 m"),
        ("navigation map", ["navigation.map=google"], r"invalid navigation.map='google' in config: expected one of world, simlan"),
        ("clearance negative", ["navigation.clearance_m=-1"], r"invalid navigation.clearance_m=-1.0 in config: must be > 0"),
        ("birdseye rate", ["birdseye.rate_hz=3"], r"invalid birdseye.rate_hz=3.0 in config: must divide the camera rate"),
        ("birdseye region", ["birdseye.x_m=[10,0]"], r"birdseye.x_m.*empty region \(max must exceed min\)"),
        ("birdseye resolution", ["birdseye.px_per_m=0"], r"birdseye.px_per_m"),
        ("agent type", ["agents.robot_agent_1.type=hovercraft"], r"unknown agent type 'hovercraft' in agents.robot_agent_1.type: known types: pallet_truck"),
        ("agent key misspelt", ["agents.robot_agent_1.typ=jackal"], r"unknown key agents.robot_agent_1.typ in config: AgentConfig has no such key; did you mean agents.robot_agent_1.type\?"),
        ("pose length", ["agents.robot_agent_1.pose=[1,2]"], r"invalid agents.robot_agent_1.pose=\[1.0, 2.0\] in config: expected \[x_m, y_m, yaw_rad\]"),
        ("yaw in degrees", ["agents.robot_agent_1.pose=[-16,0.4,90]"], r"invalid agents.robot_agent_1.pose\[2\]=90.0 in config: yaw_rad must be within \[-2 pi, 2 pi\] radians \(this looks like degrees\); give radians, e.g. 1.5708"),
        ("pose nan", ["agents.robot_agent_1.pose=[nan,0.4,0]"], r"invalid agents.robot_agent_1.pose\[0\]=nan in config: not a finite number"),
        ("pose outside", ["agents.robot_agent_1.pose=[100.0,0.0,0.0]"], r"invalid agents.robot_agent_1.pose=\[100.0, 0.0, 0.0\] in config: the robot's footprint leaves the building"),
        ("speed nan", ["agents.robot_agent_1.speed_mps=nan"], r"invalid agents.robot_agent_1.speed_mps=nan in config: not a finite number"),
        ("speed range", ["agents.robot_agent_1.speed_mps=10"], r"invalid agents.robot_agent_1.speed_mps=10.0 in config: must be within \(0, 3\] m/s"),
        ("marker id range", ["agents.robot_agent_1.marker_id=1000"], r"invalid agents.robot_agent_1.marker_id=1000 in config: DICT_5X5_1000 has ids 0..999"),
        ("goal shape", ["agents.robot_agent_1.goals=[[1.0,2.0,3.0]]"], r"invalid agents.robot_agent_1.goals\[0\]=\[1.0, 2.0, 3.0\] in config: expected \[x_m, y_m\]"),
        ("goal integers", ["agents.robot_agent_1.goals=[[1,2]]"], r"invalid agents.robot_agent_1.goals\[0\] in config: 1 is an integer, and numbers in nested lists are not converted; write every number with a decimal point"),
        ("goal in obstacle", ["agents.robot_agent_1.goals=[[0.0,3.5]]"], r"invalid agents.robot_agent_1.goals\[0\]=\[0.0, 3.5\] in config: the goal is inside an obstacle"),
        ("fleet without robots", ["scenario=fleet", "fleet.robots=0"], r"invalid fleet.robots=0 in config: must be within 1..200 for scenario=fleet; use e.g. fleet.robots=4"),
        ("fleet beyond the floor", ["scenario=fleet", "fleet.robots=150"], r"invalid fleet.robots=150 in config: the free floor of fleet.area_m=\[-8.0, 34.0, -10.0, 10.0\] holds only \d+ of these robots apart"),
        ("fleet of people", ["scenario=fleet", "fleet.types=[humanoid]"], r"invalid fleet.types\[\]='humanoid' in config: not a robot type \(pallet_truck, forklift, jackal\)"),
        ("scenario names unspawned agent", ["scenario=multi_robot", "agents=single_truck"], r"unknown agent robot_agent_2 in config: something refers to it \(a scenario's goals, an override\) but the spawn list does not spawn it"),
        ("marker id reused", ["agents=four_robots", "agents.robot_agent_3.marker_id=1"], r"invalid agents.robot_agent_3.marker_id=1 in config: already used by robot_agent_1"),
        ("agents overlap", ["agents=four_robots", "agents.robot_agent_2.pose=[-20.5,1.5,0.0]"], r"invalid agents.robot_agent_2.pose=\[-20.5, 1.5, 0.0\] in config: its footprint overlaps robot_agent_1's"),
        ("new agent on the command line", ["+agents.robot_agent_5={type:jackal,pose:[0.0,0.0,0.0]}"], r"cannot add agent .*robot_agent_5 in command line: new agents go in a spawn list file"),
        ("group given a list (found by fuzzing)", ["agents=[0]"], r"invalid configuration in command line: TypeError: argument of type 'int' is not iterable"),
        ("section given by an interpolation (found by fuzzing)", ["faults=${now:%Y}"], r"invalid faults='\$\{now:%Y\}' in config: Invalid type assigned: str is not a subclass of FaultsConfig\. value: \d+; give a value of the key's type \(an interpolation has to give one too\)"),
        ("list given by an interpolation", ["faults.drop_cameras=${now:%Y}"], r"invalid faults.drop_cameras='\$\{now:%Y\}' in config: Invalid value assigned: str is not a ListConfig, list or tuple"),
        ("override syntax", ["x=[1,2"], r"invalid override in command line: .*; write KEY=VALUE"),
        ("missing mandatory", ["cameras.ids=???"], r"missing value for cameras.ids in config: the key has no default"),
        ("alias bomb in a spawn list (config dir)", _alias_bomb_dir, r"config file too large in .*boom.yaml: YAML aliases expand to more than 100000 nodes \(an alias bomb\?\); write the values out"),
    ]
]
# fmt: on


def run_config_case(case: Case) -> None:
    """Compose, check and load the inputs as a run does before writing anything."""
    cfg = compose_config(case.arg() if callable(case.arg) else case.arg)  # type: ignore[arg-type]
    load_inputs(cfg)


# ------------------------------------------------------------------------------- calibration
def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, (path, old)
    path.write_text(text.replace(old, new, 1))


def _matrix(path: Path, key: str, data: str, rows: int | None = None, cols: int | None = None) -> None:
    """Replace the data (and optionally the shape) of one !!opencv-matrix in a FileStorage file."""
    lines = path.read_text().splitlines()
    out, i = [], 0
    while i < len(lines):
        line = lines[i]
        if line.startswith(f"{key}:"):
            out.append(line)
            i += 1
            while i < len(lines) and lines[i].startswith("   "):
                field = lines[i].strip().split(":")[0]
                if field == "rows" and rows is not None:
                    out.append(f"   rows: {rows}")
                elif field == "cols" and cols is not None:
                    out.append(f"   cols: {cols}")
                elif field == "data":
                    out.append(f"   data: [ {data} ]")
                    i += 1
                    while i < len(lines) and lines[i].startswith("      "):
                        i += 1
                    continue
                else:
                    out.append(lines[i])
                i += 1
            continue
        out.append(line)
        i += 1
    path.write_text("\n".join(out) + "\n")


INTR, EXTR = Path("intrinsic/163.yaml"), Path("extrinsic/163.yaml")
R_163 = "-0.9967456571498724, 0.06788988310855833, -0.04346330319217853, 0.06855035591376359, 0.9975509770059878, -0.013888735669448902, 0.042413955922140596, -0.016822961864837373, -0.9989584797663659"

# fmt: off
CALIBRATION_CASES = [
    Case(*c)
    for c in [
        ("intrinsic missing", lambda r: (r / INTR).unlink(), r"unknown camera id 163 in cameras.ids"),
        ("extrinsic missing", lambda r: (r / EXTR).unlink(), r"unknown camera id 163 in cameras.ids"),
        ("not UTF-8", lambda r: (r / INTR).write_bytes(b"\xff\xfe\x00garbage"), r"calibration file unreadable in .*163.yaml: not UTF-8 text"),
        ("no YAML header", lambda r: (r / INTR).write_text("K: [1, 2, 3]\n"), r"calibration file unreadable in .*163.yaml: not an OpenCV FileStorage YAML file"),
        ("empty file", lambda r: (r / EXTR).write_text(""), r"calibration file unreadable in .*extrinsic/163.yaml"),
        ("truncated", lambda r: (r / INTR).write_text((r / INTR).read_text()[:150]), r"calibration (file unreadable|key 'K' has the wrong shape|key '\w+' missing) in .*intrinsic/163.yaml"),
        ("YAML syntax", lambda r: (r / INTR).write_text("%YAML:1.0\n---\nK: !!opencv-matrix\n  rows: [3\n"), r"calibration file unreadable in .*163.yaml: OpenCV cannot parse it"),
        ("too large", lambda r: (r / INTR).write_text("%YAML:1.0\n" + "#" * (2 << 20)), r"calibration file too large in .*163.yaml: over 1048576 bytes"),
        ("flow nesting bomb (crashes OpenCV's parser)", lambda r: (r / INTR).write_text("%YAML:1.0\n---\nK: " + "[" * 100_000), r"calibration file unreadable in .*163.yaml: brackets nested 100000 deep \(more than 32; OpenCV's parser would crash\)"),
        ("K missing", lambda r: _edit(r / INTR, "K: !!opencv-matrix", "Kx: !!opencv-matrix"), r"calibration key 'K' missing in .*intrinsic/163.yaml"),
        ("D missing", lambda r: _edit(r / INTR, "D: !!opencv-matrix", "E: !!opencv-matrix"), r"calibration key 'D' missing in .*intrinsic/163.yaml"),
        ("image_shape missing", lambda r: _edit(r / INTR, "image_shape:", "shape:"), r"calibration key 'image_shape' missing"),
        ("rot_mat missing", lambda r: _edit(r / EXTR, "rot_mat:", "rotation:"), r"calibration key 'rot_mat' missing in .*extrinsic/163.yaml"),
        ("t_vec missing", lambda r: _edit(r / EXTR, "t_vec:", "t:"), r"calibration key 't_vec' missing"),
        ("P missing", lambda r: _edit(r / EXTR, "camera_matrix_p:", "p:"), r"calibration key 'camera_matrix_p' missing"),
        ("position missing", lambda r: _edit(r / EXTR, "position:", "pos:"), r"calibration key 'position' missing"),
        ("K not a matrix", lambda r: _edit(r / INTR, "K: !!opencv-matrix", "K: 3\nK_old: !!opencv-matrix"), r"calibration key 'K' missing in .*intrinsic/163.yaml"),
        ("K 2x2", lambda r: _matrix(r / INTR, "K", "1., 0., 0., 1.", 2, 2), r"calibration key 'K' has the wrong shape in .*: rows x cols is 2 x 2, expected 9 values"),
        ("negative cols (corrupted OpenCV's heap; found by fuzzing)", lambda r: _matrix(r / EXTR, "rot_mat", ", ".join(["1."] * 12), 4, -1), r"calibration key 'rot_mat' has the wrong shape in .*extrinsic/163.yaml: rows x cols is 4 x -1, expected 9 values"),
        ("data longer than rows x cols", lambda r: _matrix(r / INTR, "D", ", ".join(["0.1"] * 9), 5, 1), r"calibration key 'D' has the wrong shape in .*: data has 9 values, expected 5"),
        ("unknown element type", lambda r: _edit(r / INTR, "dt: d", "dt: q"), r"calibration key 'K' has the wrong shape in .*: dt 'q' is not one of d, f, i, u, c, s, w"),
        ("D 4 values", lambda r: _matrix(r / INTR, "D", "0.1, 0.1, 0., 0.", 4, 1), r"calibration key 'D' has the wrong shape"),
        ("K NaN", lambda r: _matrix(r / INTR, "K", "2149., 0., .NaN, 0., 2145., 1097., 0., 0., 1."), r"calibration key 'K' is not finite in .*: NaN or inf inside"),
        ("t_vec inf", lambda r: _matrix(r / EXTR, "t_vec", "6.6, .Inf, 7.0"), r"calibration key 't_vec' is not finite"),
        ("D NaN", lambda r: _matrix(r / INTR, "D", ".NaN, 0.2, 0., 0., -0.07"), r"calibration key 'D' is not finite"),
        ("R scaled", lambda r: _matrix(r / EXTR, "rot_mat", ", ".join(str(1.01 * float(v)) for v in R_163.split(", "))), r"calibration rot_mat is not a rotation in .*extrinsic/163.yaml: R\^T R deviates from I"),
        ("R reflection", lambda r: _matrix(r / EXTR, "rot_mat", ", ".join(str(-float(v)) for v in R_163.split(", "))), r"calibration rot_mat is not a rotation in .*: R\^T R deviates from I by .* \(det 1.0000\)|det -1.0000"),
        ("R zero", lambda r: _matrix(r / EXTR, "rot_mat", ", ".join(["0."] * 9)), r"calibration rot_mat is not a rotation"),
        ("fx negative", lambda r: _matrix(r / INTR, "K", "-2149., 0., 1927., 0., 2145., 1097., 0., 0., 1."), r"calibration K invalid in .*intrinsic/163.yaml: not an upper-triangular camera matrix with fx, fy > 0"),
        ("K lower triangle", lambda r: _matrix(r / INTR, "K", "2149., 0., 1927., 5., 2145., 1097., 0., 0., 1."), r"calibration K invalid"),
        ("fx implausible", lambda r: _matrix(r / INTR, "K", "2.1e9, 0., 1927., 0., 2145., 1097., 0., 0., 1."), r"calibration K implausible in .*: focal lengths must be within"),
        ("principal point far off", lambda r: _matrix(r / INTR, "K", "2149., 0., 1e7, 0., 2145., 1097., 0., 0., 1."), r"calibration K implausible"),
        ("D implausible", lambda r: _matrix(r / INTR, "D", "5e3, 0.2, 0., 0., -0.07"), r"calibration D implausible in .*: distortion coefficients beyond"),
        ("t_vec implausible", lambda r: _matrix(r / EXTR, "t_vec", "6.6, 1e9, 7.0"), r"calibration t_vec implausible in .*extrinsic/163.yaml"),
        ("image_shape fractional", lambda r: _matrix(r / INTR, "image_shape", "2160.5, 3840., 3."), r"calibration image_shape invalid in .*: got \[2160.5, 3840.0, 3.0\]"),
        ("image_shape zero", lambda r: _matrix(r / INTR, "image_shape", "0., 0., 3."), r"calibration image_shape invalid"),
        ("data not numbers", lambda r: _matrix(r / INTR, "K", "a, b, c, d, e, f, g, h, i"), r"calibration (file unreadable|key 'K' (missing|has the wrong shape))"),
        ("P disagrees with K[R|t] (check=error)", "error", r"calibration files disagree in camera 163: 163.yaml: camera_matrix_p disagrees with K\[R\|t\].*; fix the files or set cameras.calibration_check=warn"),
        ("position disagrees with -R^T t (check=error)", lambda r: _matrix(r / EXTR, "position", "1., 2., 3."), r"calibration files disagree in camera 163: .*position disagrees with -R\^T t by"),
    ]
]
# fmt: on


def run_calibration_case(case: Case, tmp: Path) -> None:
    """Copy camera 163's files, apply the case, load the camera as a run does."""
    root = tmp / "calibration"
    for kind in ("intrinsic", "extrinsic"):
        (root / kind).mkdir(parents=True, exist_ok=True)
        shutil.copy(CALIBRATION_DIR / kind / "163.yaml", root / kind / "163.yaml")
    check = "error" if "check=error" in case.id else "warn"
    if callable(case.arg):
        case.arg(root)
    cfg = compose_config(
        ["cameras.ids=[163]", f"cameras.calibration_dir={root}", f"cameras.calibration_check={check}"]
    )
    load_cameras(cfg)


def load_calibration_direct(root: Path) -> None:
    load_calibration("163", root)


# -------------------------------------------------------------------------------------- URDF
def _urdf(r: Path, name: str, old: str, new: str) -> None:
    _edit(r / name, old, new)


TRUCK = AGENT_TYPES["pallet_truck"]
# fmt: off
URDF_CASES = [
    Case(*c)
    for c in [
        ("file missing", lambda r: (r / "pallet_truck.urdf").unlink(), r"URDF file missing in .*pallet_truck.urdf \(agent type pallet_truck\): no such file"),
        ("empty file", lambda r: (r / "pallet_truck.urdf").write_text(""), r"URDF file is not valid XML in .*: no element found at line 1"),
        ("truncated XML", lambda r: (r / "pallet_truck.urdf").write_text((r / "pallet_truck.urdf").read_text()[:500]), r"URDF file is not valid XML in .*pallet_truck.urdf .*at line \d+, column \d+"),
        ("not UTF-8", lambda r: (r / "pallet_truck.urdf").write_bytes(b"<robot>\xff\xfe</robot>"), r"URDF file unreadable in .*: not UTF-8 text"),
        ("root not robot", lambda r: (r / "pallet_truck.urdf").write_text("<model name='x'><link name='a'/></model>"), r"URDF file has no <robot> root in .*: the root element is <model>"),
        ("no links", lambda r: (r / "pallet_truck.urdf").write_text("<robot name='x'></robot>"), r"URDF file has no links"),
        ("joint to unknown link", lambda r: _urdf(r, "pallet_truck.urdf", '<child link="left_wheel"/>', '<child link="left_wheeel"/>'), r"URDF joint 'left_wheel_joint' names an unknown child link in .*: child link 'left_wheeel' is not defined"),
        ("marker placeholder missing", lambda r: _urdf(r, "pallet_truck.urdf", "<!-- ARUCO_MARKER -->", ""), r"URDF lacks the marker placeholder in .*pallet_truck.urdf .*: no <!-- ARUCO_MARKER --> line"),
        ("wheel joint missing", lambda r: _urdf(r, "pallet_truck.urdf", 'name="right_wheel_joint"', 'name="right_joint"'), r"URDF lacks wheel joint 'right_wheel_joint' in .*: a diff-drive robot is driven through left_wheel_joint and right_wheel_joint"),
        ("wheel joint fixed", lambda r: _urdf(r, "pallet_truck.urdf", 'name="left_wheel_joint" type="continuous"', 'name="left_wheel_joint" type="fixed"',), r"URDF wheel joint 'left_wheel_joint' cannot turn in .*: its type is 'fixed'"),
        ("caster link missing", lambda r: _urdf(r, "pallet_truck.urdf", 'link name="rear_caster"', 'link name="rear_wheel"'), r"URDF (lacks caster links in .*: rear_caster|joint '\w+' names an unknown child link)"),
        ("XML entity bomb", lambda r: (r / "pallet_truck.urdf").write_text('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;"><!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;"><!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;"><!ENTITY e "&d;&d;&d;&d;&d;&d;&d;&d;&d;&d;"><!ENTITY f "&e;&e;&e;&e;&e;&e;&e;&e;&e;&e;"><!ENTITY g "&f;&f;&f;&f;&f;&f;&f;&f;&f;&f;"><!ENTITY h "&g;&g;&g;&g;&g;&g;&g;&g;&g;&g;">]><robot name="&h;"></robot>'), r"URDF file (is not valid XML|has no links)"),
    ]
]
# fmt: on


def run_urdf_case(case: Case, tmp: Path, kind: AgentType = TRUCK) -> None:
    root = tmp / "urdf"
    shutil.copytree(URDF_DIR, root, dirs_exist_ok=True)
    assert callable(case.arg)
    case.arg(root)
    check_urdf(kind, root)


# ------------------------------------------------------------------------------------ layout
HEADER = "model,name,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad,static,world_setups\n"
# fmt: off
LAYOUT_CASES = [
    Case(*c)
    for c in [
        ("file missing", None, r"layout file missing in .*layout.csv: no such file"),
        ("empty file", "", r"layout file (unreadable|lacks columns) in .*layout.csv"),
        ("missing columns", "model,x_m,y_m\nshelf,1,2\n", r"layout file lacks columns in .*: name, z_m, roll_rad, pitch_rad, yaw_rad, static, world_setups"),
        ("binary garbage", b"\x00\xff\xfe\x01" * 100, r"layout file (unreadable|lacks columns) in .*layout.csv"),
        ("unknown model", HEADER + "eur_palet,s1,1,2,0,0,0,0,1,default\n", r"layout names an unknown model 'eur_palet' in .*: this twin has no geometry for it .*; did you mean"),
        ("NaN pose", HEADER + "concrete_ground,g,nan,2,0,0,0,0,1,default\n", r"layout row invalid in .* \(model 'concrete_ground', name 'g'\): a pose value or the model is empty or not finite"),
        ("inf pose", HEADER + "concrete_ground,g,1,inf,0,0,0,0,1,default\n", r"layout row invalid"),
        ("empty pose value", HEADER + "concrete_ground,g,1,,0,0,0,0,1,default\n", r"layout row invalid"),
        ("empty model", HEADER + ",g,1,2,0,0,0,0,1,default\n", r"layout row invalid"),
        ("pose not a number", HEADER + "concrete_ground,g,one,2,0,0,0,0,1,default\n", r"layout file unreadable in .*layout.csv"),
        ("unknown fidelity level", HEADER + "concrete_ground,g,1,2,0,0,0,0,1,default ultra\n", r"layout row has an unknown fidelity level in .*: ultra"),
    ]
]
# fmt: on


def run_layout_case(case: Case, tmp: Path) -> None:
    path = tmp / "layout.csv"
    if isinstance(case.arg, bytes):
        path.write_bytes(case.arg)
    elif isinstance(case.arg, str):
        path.write_text(case.arg)
    load_layout(path, "default")


def real_layout_loads() -> int:
    return len(load_layout(LAYOUT_DIR / "warehouse_layout.csv", "default"))


# -------------------------------------------------------------------------------- recordings
def run_info_for_tests(scenario: str, format_version: str = "1.0") -> object:
    """A ``/simlan/run_info`` message for recordings written by tests."""
    return M.run_info(
        format_version=format_version,
        version="test",
        scenario=scenario,
        seed=0,
        renderer="none",
        renderer_info="",
        dependencies={},
    )


def small_recording(
    path: Path, *, format_version: str = "1.0", topics: tuple[str, ...] | None = None
) -> Path:
    """A 2 s recording with the required topics, written by the real writer (2 chunks per second)."""
    by_name = {t.name: t for t in schema.GLOBAL_TOPICS}
    wanted = set(topics) if topics is not None else set(schema.REQUIRED_TOPICS)
    with RecordingWriter(path, flush_period_ns=NS_PER_S // 2) as w:
        w.set_metadata("simlan.format_version", format_version)
        if schema.CONFIG in wanted:
            w.write(by_name[schema.CONFIG], 0, M.string(yaml.safe_dump({"duration_s": 2.0})))
        if schema.RUN_INFO in wanted:
            w.write(by_name[schema.RUN_INFO], 0, run_info_for_tests("small", format_version))
        if schema.TF_STATIC in wanted:
            w.write(by_name[schema.TF_STATIC], 0, M.tf_message([]))
        for k in range(121):
            t = k * NS_PER_S // 60
            if schema.CLOCK in wanted:
                w.write(by_name[schema.CLOCK], t, M.clock(t))
            if schema.GROUND_TRUTH_POSES in wanted:
                pose = Transform.from_pose2d(0.01 * k, 0.0, 0.0)
                w.write(
                    by_name[schema.GROUND_TRUTH_POSES],
                    t,
                    M.tf_message([M.transform_stamped(t, "map", "robot_agent_1/base_link", pose)]),
                )
    return path


def _meta(bag: Path, edit: Callable[[dict], None]) -> None:
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    edit(meta["rosbag2_bagfile_information"])
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))


def _flip_in_chunk(bag: Path) -> None:
    mcap = next(bag.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    at = data.index(b"\x06", 8)  # the first chunk record
    length = struct.unpack_from("<Q", data, at + 1)[0]
    data[at + 9 + length // 2] ^= 0x10
    mcap.write_bytes(bytes(data))


def _set_custom(bag: Path, key: str, value: str | None) -> None:
    def edit(info: dict) -> None:
        custom = info.get("custom_data") or {}
        if value is None:
            custom.pop(key, None)
        else:
            custom[key] = value
        info["custom_data"] = custom

    _meta(bag, edit)


def _fifo(path: Path) -> None:
    """Replace ``path`` by a FIFO (named pipe): opening it for reading blocks until a writer comes."""
    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)
    os.mkfifo(path)


def _not_a_file(path: Path) -> None:
    """Replace ``path`` by a directory of the same name."""
    path.unlink()
    path.mkdir()


ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join([f'*{chr(97 + i)}'] * 10)}]\n" for i in range(8)
)  # 10**9 values once expanded, 400 bytes


def _alias_bomb(bag: Path) -> None:
    """metadata.yaml with a billion-laughs alias bomb ahead of its real content."""
    (bag / "metadata.yaml").write_text(ALIAS_BOMB + (bag / "metadata.yaml").read_text())


def _inflate(bag: Path, key: str, value: int) -> None:
    """Set a count or time of metadata.yaml (``message_count``, ``topics:/clock``, ``duration``)."""

    def edit(info: dict) -> None:
        if key.startswith("topics:"):
            for t in info["topics_with_message_count"]:
                if t["topic_metadata"]["name"] == key[len("topics:") :]:
                    t["message_count"] = value
        elif key == "duration":
            info["duration"]["nanoseconds"] = value
        elif key == "starting_time":
            info["starting_time"]["nanoseconds_since_epoch"] = value
        else:
            info[key] = value

    _meta(bag, edit)


def wrong_type(bag: Path, topic: str = schema.GROUND_TRUTH_POSES, msgtype: str = schema.STRING_TYPE) -> None:
    """Rewrite the recording with ``topic`` declared as ``msgtype``, its messages std_msgs/String "x"."""
    payload = bytes(schema.typestore().serialize_cdr(M.string("x"), schema.STRING_TYPE))
    orig = bag.with_name(bag.name + ".orig")
    bag.rename(orig)
    with RecordingReader(orig) as r, RecordingWriter(bag, flush_period_ns=NS_PER_S // 2) as w:
        for k, v in r.custom_data.items():
            w.set_metadata(k, v)
        topics = {t.name: schema.Topic(t.name, t.msgtype, "") for t in r.topics.values()}
        topics[topic] = schema.Topic(topic, msgtype, "")
        for m in r.messages(raw=True):
            if m.topic == topic:
                w.write_serialized(topics[topic], m.stamp_ns, payload)
            else:
                w.write_serialized(topics[m.topic], m.stamp_ns, bytes(m.msg))
    shutil.rmtree(orig)


# fmt: off
RECORDING_CASES = [
    Case(*c)
    for c in [
        ("path missing", lambda b: shutil.rmtree(b), r"not a readable recording in .*: no such file or directory; check the path"),
        ("directory without a bag", lambda b: [p.unlink() for p in list(b.iterdir())], r"not a readable recording in .*: no metadata.yaml \(not a ROS 2 bag\)"),
        ("crashed: MCAP without metadata", lambda b: (b / "metadata.yaml").unlink(), r"recording is unfinished in .*: an MCAP file without metadata.yaml \(the run crashed or was killed\); run `python -m simlan_data.recover .*` to keep everything up to its last flushed chunk"),
        ("metadata not YAML", lambda b: (b / "metadata.yaml").write_text("{[: oops"), r"not a readable recording in .*: .*; run `python -m simlan_data.recover"),
        ("metadata nested too deeply", lambda b: (b / "metadata.yaml").write_text("[" * 100_000), r"not a readable recording in .*: metadata.yaml is nested too deeply"),
        ("metadata count not an integer (found by fuzzing)", lambda b: (b / "metadata.yaml").write_text((b / "metadata.yaml").read_text().replace("message_count: 121", "message_count: 1:1", 1)), r"not a readable recording in .*: metadata.yaml holds a message count or time that is not an integer"),
        ("metadata without bag info", lambda b: (b / "metadata.yaml").write_text("hello: world\n"), r"not a readable recording in .*"),
        ("metadata huge", lambda b: (b / "metadata.yaml").write_text("# " + "x" * (17 << 20)), r"not a readable recording in .*"),
        ("MCAP truncated", lambda b: (b / f"{b.name}.mcap").write_bytes((b / f"{b.name}.mcap").read_bytes()[:-300]), r"not a readable recording in .*; run `python -m simlan_data.recover"),
        ("MCAP cut in half", lambda b: (b / f"{b.name}.mcap").write_bytes((b / f"{b.name}.mcap").read_bytes()[:2000]), r"not a readable recording in .*; run `python -m simlan_data.recover"),
        ("MCAP is garbage", lambda b: (b / f"{b.name}.mcap").write_bytes(b"garbage" * 500), r"not a readable recording in .*"),
        ("MCAP file missing", lambda b: (b / f"{b.name}.mcap").unlink(), r"not a readable recording in .*"),
        ("corrupted chunk (CRC)", _flip_in_chunk, r"not a readable recording in .*: ReaderError while reading messages: Chunk checksum mismatch|zstd|ZstdError"),
        ("custom_data not a mapping (found by fuzzing)", lambda b: (b / "metadata.yaml").write_text((b / "metadata.yaml") .read_text() .replace("    simlan.epoch_ns: '0'\n", "") .replace("simlan.format_version: '1.0'", "simlan.format_version; '1.0'")), r"not a readable recording in .*: metadata.yaml custom_data is not a mapping of strings"),
        ("epoch not a number", lambda b: _set_custom(b, "simlan.epoch_ns", "soon"), r"not a readable recording in .*: metadata.yaml custom_data: simlan.epoch_ns is 'soon', not a whole number of ns before 2037"),
        ("no format version", lambda b: _set_custom(b, "simlan.format_version", None), r"recording has no simlan_data format version in .*: metadata.yaml custom_data lacks simlan.format_version"),
        ("newer major version", lambda b: _set_custom(b, "simlan.format_version", "7.0"), r"recording format 7.0 is newer than this simlan_data \(1.x\) in .*; upgrade simlan_data"),
        ("older major version", lambda b: _set_custom(b, "simlan.format_version", "0.9"), r"recording format 0.9 is older than this simlan_data \(1.x\)"),
        ("unreadable version", lambda b: _set_custom(b, "simlan.format_version", "one.two"), r"recording format version unreadable in .*: 'one.two'"),
        ("missing required topics", "topics", r"recording lacks required topics in .*: /tf_static, /ground_truth/poses, /simlan/config, /simlan/run_info"),
        # issue 21: hostile inputs answer within 5 s with one line (a FIFO hung every reader)
        ("MCAP file is a FIFO", lambda b: _fifo(b / f"{b.name}.mcap"), r"recording file is not a regular file in .*recording.mcap: it is a FIFO \(named pipe\), which is never read; replace it by the real file"),
        ("MCAP file is a directory", lambda b: _not_a_file(b / f"{b.name}.mcap"), r"recording file is not a regular file in .*recording.mcap: it is a directory"),
        ("metadata is a FIFO", lambda b: _fifo(b / "metadata.yaml"), r"recording metadata is not a regular file in .*metadata.yaml: it is a FIFO \(named pipe\)"),
        ("metadata is a directory", lambda b: _not_a_file(b / "metadata.yaml"), r"recording metadata is not a regular file in .*metadata.yaml: it is a directory"),
        ("recording path is a FIFO", lambda b: (shutil.rmtree(b), os.mkfifo(b)), r"recording path is not a regular file in .*recording: it is a FIFO \(named pipe\)"),
        ("crashed, RUNNING marker is a FIFO", lambda b: ((b / "metadata.yaml").unlink(), os.mkfifo(b.parent / "RUNNING")), r"recording is unfinished in .*: an MCAP file without metadata.yaml"),
        ("metadata alias bomb", _alias_bomb, r"not a readable recording in .*: metadata.yaml unreadable: YAML alias at line 2, column \d+ \(simlan_data writes none"),
        ("metadata over 256 KiB", lambda b: (b / "metadata.yaml").write_text((b / "metadata.yaml").read_text() + "# " + "x" * (256 << 10)), r"not a readable recording in .*: metadata.yaml is \d+ bytes, more than the 262144"),
        ("metadata message count inflated", lambda b: _inflate(b, "message_count", 10**23), r"not a readable recording in .*: metadata.yaml message_count is 100000000000000000000000, but its MCAP file's summary says 245; run `python -m simlan_data.recover .*` to rebuild metadata.yaml"),
        ("metadata message count 1e23", lambda b: (b / "metadata.yaml").write_text((b / "metadata.yaml").read_text().replace("\n  message_count: 245\n", "\n  message_count: 1e23\n", 1)), r"not a readable recording in .*: metadata.yaml message_count is not a non-negative integer"),
        ("metadata topic count inflated", lambda b: _inflate(b, "topics:/clock", 10**12), r"metadata.yaml topics_with_message_count /clock is 1000000000000, but its MCAP file's summary says 121"),
        ("metadata duration inflated", lambda b: _inflate(b, "duration", 10**18), r"metadata.yaml duration is 1000000000000000000, but its MCAP file's summary says 2000000000"),
        ("ground truth of the wrong type", wrong_type, r"recording topic /ground_truth/poses has the wrong message type in .*: found std_msgs/msg/String, expected tf2_msgs/msg/TFMessage \(simlan_data.recording.schema\); record it with simlan_data"),
        ("clock of the wrong type", lambda b: wrong_type(b, schema.CLOCK), r"recording topic /clock has the wrong message type in .*: found std_msgs/msg/String, expected rosgraph_msgs/msg/Clock"),
        ("replay --set of the wrong type", ("replay", ["--algorithms", "safety", "--set", "hold_s=abc"]), r"invalid hold_s='abc' in replay --set: expected float \(TreesConfig.hold_s\), got str; e.g. --set hold_s=1.0"),
        ("replay --set bool for a float", ("replay", ["--algorithms", "safety", "--set", "hold_s=true"]), r"invalid hold_s=True in replay --set: expected float"),
        ("replay --set of a nested key", ("replay", ["--algorithms", "safety", "--set", "ttc.enabled=3"]), r"invalid ttc.enabled=3 in replay --set: expected bool \(TreesConfig.ttc.enabled\), got int"),
    ]
]
# fmt: on


def run_recording_case(case: Case, tmp: Path) -> None:
    """Open the recording, check it has what a replay needs, read every message."""
    bag = tmp / "recording"
    if case.arg == "topics":
        small_recording(bag, topics=(schema.CLOCK,))
    elif isinstance(case.arg, tuple):  # ("replay", extra arguments): the replay CLI's checks
        from simlan_data.apps.replay import main as replay

        small_recording(bag)
        out = tmp / "replay_out"
        try:
            replay([str(bag), "--out", str(out), *case.arg[1]])
        finally:
            assert not out.exists(), "rejected input left --out behind"
        return
    else:
        small_recording(bag)
        assert callable(case.arg)
        case.arg(bag)
    with RecordingReader(bag) as reader:
        reader.require_topics(schema.REQUIRED_TOPICS)
        for _ in reader.messages():
            pass


BOUNDARIES: dict[str, tuple[list[Case], Callable[..., None], bool]] = {
    # name: (cases, runner, runner takes a tmp dir)
    "config": (CONFIG_CASES, run_config_case, False),
    "calibration": (CALIBRATION_CASES, run_calibration_case, True),
    "urdf": (URDF_CASES, run_urdf_case, True),
    "layout": (LAYOUT_CASES, run_layout_case, True),
    "recording": (RECORDING_CASES, run_recording_case, True),
}


def one_line(err: SimlanError) -> str:
    line = f"error: {err.line()}"
    assert "\n" not in line, line
    return line
