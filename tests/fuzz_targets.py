"""Fuzz targets (hypothesis strategies + one check per input), shared by tests and benchmark.

Each ``check_*`` feeds one generated input through the real loading path and returns the outcome
("ok" or the SimlanError subclass name). Any other exception propagates: that is a failure, and
so is a hang (the tests run under hypothesis deadlines).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from hypothesis import strategies as st
from mcap.reader import make_reader

from simlan_data.config.validation import _typed_keys, compose_config
from simlan_data.constants import CALIBRATION_DIR
from simlan_data.errors import EXIT_BAD_INPUT, SimlanError
from simlan_data.geometry.calibration import load_calibration
from simlan_data.recording import schema
from simlan_data.recording.reader import RecordingReader, expected_types
from simlan_data.recording.recover import recover


def clear(err: SimlanError) -> str:
    """The error's class name, after checking it is one line with a where, a why and a fix."""
    line = err.line()
    assert "\n" not in line and err.what and err.why and err.fix, line
    return type(err).__name__


# ---------------------------------------------------------------------------------- calibration
INTRINSIC = (CALIBRATION_DIR / "intrinsic" / "163.yaml").read_bytes()
EXTRINSIC = (CALIBRATION_DIR / "extrinsic" / "163.yaml").read_bytes()
KEYS = ["K", "D", "xi", "image_shape", "rot_mat", "t_vec", "camera_matrix_p", "position", "junk"]
NUMBER_TOKENS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-(10**20), max_value=10**20).map(str),
    st.sampled_from(
        [".NaN", ".Inf", "-.Inf", "1e308", "-1e-308", "0.", "1.", "abc", "", "0x1F", "[", "]", ","]
    ),
)


@st.composite
def filestorage_yaml(draw: st.DrawFn) -> bytes:
    """An OpenCV FileStorage YAML document built from plausible and implausible parts."""
    parts = ["%YAML:1.0\n---\n"] if draw(st.booleans()) or True else []
    for key in draw(st.lists(st.sampled_from(KEYS), max_size=10)):
        rows = draw(st.one_of(st.integers(0, 5), st.sampled_from([-1, 10**9, 2**31, 2**63])))
        cols = draw(st.one_of(st.integers(0, 5), st.sampled_from([-1, 10**9])))
        dt = draw(st.sampled_from(["d", "f", "i", "u", "c", "s", "w", "x", ""]))
        data = draw(st.lists(NUMBER_TOKENS, max_size=14))
        if draw(st.integers(0, 9)) == 0:
            parts.append(f"{key}: {draw(NUMBER_TOKENS)}\n")
        else:
            parts.append(
                f"{key}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: {dt}\n   data: [ {', '.join(data)} ]\n"
            )
    return "".join(parts).encode()


@st.composite
def mutated(draw: st.DrawFn, original: bytes, max_edits: int = 8) -> bytes:
    """``original`` with bit flips, byte overwrites, deletions, insertions and a truncation."""
    data = bytearray(original)
    for _ in range(draw(st.integers(1, max_edits))):
        if not data:
            break
        at = draw(st.integers(0, len(data) - 1))
        op = draw(st.sampled_from(["flip", "byte", "delete", "insert", "truncate"]))
        if op == "flip":
            data[at] ^= 1 << draw(st.integers(0, 7))
        elif op == "byte":
            data[at] = draw(st.integers(0, 255))
        elif op == "delete":
            del data[at : at + draw(st.integers(1, 64))]
        elif op == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=32))
        else:
            del data[at:]
    return bytes(data)


def calibration_inputs() -> st.SearchStrategy[tuple[bytes, bytes]]:
    return st.one_of(
        st.tuples(mutated(INTRINSIC), st.just(EXTRINSIC)),
        st.tuples(st.just(INTRINSIC), mutated(EXTRINSIC)),
        st.tuples(filestorage_yaml(), st.just(EXTRINSIC)),
        st.tuples(st.just(INTRINSIC), filestorage_yaml()),
    )


def check_calibration(files: tuple[bytes, bytes]) -> str:
    """Load camera 163 from the given intrinsic and extrinsic file contents."""
    with tempfile.TemporaryDirectory(prefix="fuzz_calib_") as tmp:
        root = Path(tmp)
        for kind, data in zip(("intrinsic", "extrinsic"), files):
            (root / kind).mkdir()
            (root / kind / "163.yaml").write_bytes(data)
        try:
            cal = load_calibration("163", root)
        except SimlanError as err:
            return clear(err)
    cam = cal.camera
    for m in (cam.K, cam.D, cam.world_from_camera.rotation, cam.world_from_camera.translation):
        assert np.all(np.isfinite(m))
    assert cam.width > 0 and cam.height > 0
    return "ok"


# ---------------------------------------------------------------------------------------- config
CONFIG_KEYS = [k for k in _typed_keys() if k not in ("hydra",)] + [
    "agents.robot_agent_1.type",
    "agents.robot_agent_1.pose",
    "agents.robot_agent_1.goals",
    "agents.robot_agent_1.speed_mps",
    "agents.robot_agent_1.marker_id",
    "agents.robot_agent_2.goals",
    "no_such_key",
    "recording.no_such_key",
    "cameras",
    "world",
    "agents",
    "scenario",
]
SCALAR = st.one_of(
    st.integers(min_value=-(10**12), max_value=10**12).map(str),
    st.floats(allow_nan=True, allow_infinity=True, width=64).map(lambda f: repr(f).replace("inf", "inf")),
    st.sampled_from(
        [
            "true",
            "false",
            "null",
            "???",
            "5s",
            "60 s",
            "1e400",
            "-0.0",
            "abc",
            "''",
            "gpss",
            "single",
            "four_robots",
            "multi_robot",
            "160",
            "[",
            "]",
            "{",
            "}",
            "${now:%Y}",
            "${seed}",
            "pallet_truck",
            "jackal",
            "nan",
            "-inf",
        ]
    ),
    st.text(alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=12),
)
VALUE = st.one_of(
    SCALAR,
    st.lists(SCALAR, max_size=4).map(lambda xs: "[" + ",".join(xs) + "]"),
    st.lists(st.lists(SCALAR, max_size=3), max_size=3).map(
        lambda xss: "[" + ",".join("[" + ",".join(x) + "]" for x in xss) + "]"
    ),
)


def config_overrides() -> st.SearchStrategy[list[str]]:
    prefix = st.sampled_from(["", "", "", "+", "~", "++"])
    one = st.builds(
        lambda p, k, v: f"{p}{k}={v}" if p != "~" else f"~{k}", prefix, st.sampled_from(CONFIG_KEYS), VALUE
    )
    return st.lists(one, min_size=1, max_size=4)


def check_config(overrides: list[str]) -> str:
    """Compose and check a config from the overrides (as ``python -m simlan_data.run`` would)."""
    try:
        compose_config(["cameras=single", *overrides])
    except SimlanError as err:
        return clear(err)
    return "ok"


# ------------------------------------------------------------------------------------ recordings
def recording_inputs(bag: dict[str, bytes]) -> st.SearchStrategy[dict[str, bytes]]:
    """A real small bag's files with one of them mutated."""
    mcap_name = next(n for n in bag if n.endswith(".mcap"))

    def with_file(name: str, data: bytes) -> dict[str, bytes]:
        return {**bag, name: data}

    return st.one_of(
        mutated(bag[mcap_name], max_edits=3).map(lambda d: with_file(mcap_name, d)),
        st.integers(0, len(bag[mcap_name])).map(lambda n: with_file(mcap_name, bag[mcap_name][:n])),
        mutated(bag["metadata.yaml"], max_edits=3).map(lambda d: with_file("metadata.yaml", d)),
        st.just({k: v for k, v in bag.items() if k != "metadata.yaml"}),
    )


def read_as_a_replay_does(bag: Path) -> None:
    """Open ``bag``, require the topics, summarize it and read every message."""
    with RecordingReader(bag) as reader:
        reader.require_topics(schema.REQUIRED_TOPICS)
        reader.summary()
        for _ in reader.messages():
            pass


def check_recording(files: dict[str, bytes]) -> str:
    """Open, validate and read every message; then recover a copy and read the result back."""
    with tempfile.TemporaryDirectory(prefix="fuzz_bag_") as tmp:
        bag = Path(tmp) / "recording"
        bag.mkdir()
        for name, data in files.items():
            (bag / name).write_bytes(data)
        copy = Path(tmp) / "copy" / "recording"
        shutil.copytree(bag, copy)
        outcome = "ok"
        try:
            read_as_a_replay_does(bag)
        except SimlanError as err:
            outcome = clear(err)
        try:
            report = recover(copy)
        except SimlanError as err:
            return f"{outcome}/recover:{clear(err)}"
        if report.written:  # what recovery writes, the independent reader reads, CRCs and all
            with next(copy.glob("*.mcap")).open("rb") as f:
                n = sum(1 for _ in make_reader(f, validate_crcs=True).iter_messages())
            assert n == report.salvage.messages
        return f"{outcome}/recover:{'written' if report.written else 'intact'}"


# ---------------------------------------------------------------------------- hostile inputs
# issue 21: shapes that hung a reader or crashed it; each must answer within 5 s with one line
# and exit 2 (RecordingInputError or ConfigError), and leave no replay output behind
HOSTILE_KINDS = (
    "fifo",
    "not a regular file",
    "alias bomb",
    "metadata too large",
    "count inflated",
    "wrong type",
    "set of the wrong type",
    "config alias bomb",
)
TRUE_COUNTS = {
    "message_count": 245,
    "topics:/clock": 121,
    "topics:/ground_truth/poses": 121,
    "duration": 2 * 10**9,
}
WRONG_VALUES = st.one_of(
    st.text(alphabet="abcxyz:/ ", min_size=1, max_size=6).filter(lambda t: t.strip() != ""),
    st.sampled_from(["true", "false", "null", "[1]", "[1,2,3]", '{"a":1}', '"1.0"', "[]", "{}"]),
)
SET_KEYS = {"hold_s": "float", "ttc.enabled": "bool", "enabled": "bool", "collision.enabled": "bool"}


def _fits_json(raw: str, kind: str) -> bool:
    import json

    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        return False
    if kind == "bool":
        return isinstance(value, bool)
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@st.composite
def hostile_inputs(draw: st.DrawFn) -> tuple[str, tuple]:
    """(kind, parameters) of one hostile input for :func:`check_hostile`."""
    kind = draw(st.sampled_from(HOSTILE_KINDS))
    if kind in ("fifo", "not a regular file"):
        return kind, (draw(st.sampled_from(["recording.mcap", "metadata.yaml", "RUNNING", "."])),)
    if kind == "alias bomb":
        width, depth = draw(st.integers(2, 12)), draw(st.integers(1, 12))
        return kind, (width, depth, draw(st.booleans()))
    if kind == "config alias bomb":  # one that expands past the config loader's 100k values
        width = draw(st.integers(2, 12))
        shallowest = next(d for d in range(1, 40) if width ** (d + 1) > 100_000)
        return kind, (width, draw(st.integers(shallowest, shallowest + 8)), draw(st.booleans()))
    if kind == "metadata too large":
        return kind, (draw(st.integers((256 << 10) + 1, 8 << 20)),)
    if kind == "count inflated":
        key = draw(st.sampled_from(sorted(TRUE_COUNTS)))
        value = draw(st.one_of(st.integers(0, 10**30), st.sampled_from([2**63, 2**64, 10**23])))
        return kind, (key, value if value != TRUE_COUNTS[key] else value + 1)
    if kind == "wrong type":
        topic = draw(st.sampled_from(schema.REQUIRED_TOPICS))
        types = (schema.STRING_TYPE, schema.CLOCK_TYPE, schema.TF_TYPE, schema.IMAGE_TYPE)
        wrong = [t for t in types if t not in expected_types(topic)]
        return kind, (topic, draw(st.sampled_from(wrong)))
    key = draw(st.sampled_from(sorted(SET_KEYS)))
    raw = draw(WRONG_VALUES.filter(lambda r: not _fits_json(r, SET_KEYS[key])))
    return kind, (key, raw)


def _bomb(width: int, depth: int) -> str:
    names = [f"n{i}" for i in range(depth + 1)]
    lines = [f"{names[0]}: &{names[0]} [{', '.join(['x'] * width)}]"]
    lines += [
        f"{names[i]}: &{names[i]} [{', '.join([f'*{names[i - 1]}'] * width)}]" for i in range(1, depth + 1)
    ]
    return "\n".join(lines) + "\n"


def check_hostile(case: tuple[str, tuple]) -> str:
    """Build a small recording, make it hostile, then open and read it as a replay does (or run
    the replay CLI's option checks); the answer must be a one-line exit-2 error within 5 s."""
    from reliability_cases import _inflate, small_recording, wrong_type

    from simlan_data.apps.replay import main as replay

    kind, params = case
    with tempfile.TemporaryDirectory(prefix="fuzz_hostile_") as tmp:
        bag = small_recording(Path(tmp) / "run" / "recording")
        out = Path(tmp) / "out"
        if kind in ("fifo", "not a regular file"):
            target = bag / params[0] if params[0] != "RUNNING" else bag.parent / "RUNNING"
            if params[0] == ".":
                target = bag
            if params[0] == "RUNNING":
                (bag / "metadata.yaml").unlink()  # an unfinished run: the reader looks at RUNNING
            if target.is_dir():
                shutil.rmtree(target)
            else:
                target.unlink(missing_ok=True)
            os.mkfifo(target) if kind == "fifo" else target.mkdir()
        elif kind == "alias bomb":
            width, depth, ahead = params
            meta = (bag / "metadata.yaml").read_text()
            bomb = _bomb(width, depth)
            (bag / "metadata.yaml").write_text(bomb + meta if ahead else meta + bomb)
        elif kind == "metadata too large":
            with (bag / "metadata.yaml").open("a") as f:
                f.write("# " + "x" * params[0] + "\n")
        elif kind == "count inflated":
            _inflate(bag, *params)
        elif kind == "wrong type":
            wrong_type(bag, *params)
        elif kind == "config alias bomb":  # a --config-dir file (agents/NAME.yaml) the run would compose
            width, depth, nested = params
            agents = Path(tmp) / "conf" / "agents"
            agents.mkdir(parents=True)
            (agents / "bomb.yaml").write_text(
                ("deep:\n  " if nested else "")
                + _bomb(width, depth).replace("\n", "\n  " if nested else "\n")
            )
        t0 = time.perf_counter()
        try:
            if kind == "config alias bomb":
                from simlan_data.config.safe_yaml import check_config_dirs

                check_config_dirs(["--config-dir", str(Path(tmp) / "conf"), "agents=bomb"])
            elif kind == "set of the wrong type":
                key, raw = params
                replay([str(bag), "--out", str(out), "--algorithms", "safety", "--set", f"{key}={raw}"])
            else:
                read_as_a_replay_does(bag)
        except SimlanError as err:
            error: SimlanError | None = err
        else:
            error = None
        assert error is None or error.exit_code == EXIT_BAD_INPUT, error.line()
        outcome = "ok" if error is None else clear(error)
        assert time.perf_counter() - t0 < 5.0, (kind, params, time.perf_counter() - t0)
        assert not out.exists(), "rejected input left --out behind"
        return outcome


TARGETS = {
    "calibration": lambda: (calibration_inputs(), check_calibration),
    "config": lambda: (config_overrides(), check_config),
}


def main(argv: list[str]) -> int:
    """``python tests/fuzz_targets.py TARGET EXAMPLES``: fuzz one target in this process.

    Run by the slow tests with ``MALLOC_CHECK_=3``, so that native code corrupting the heap
    (OpenCV's FileStorage did) aborts at once instead of crashing some later, unrelated test.
    """
    from collections import Counter

    from hypothesis import HealthCheck, given, settings

    target, examples = argv[0], int(argv[1])
    if target == "hostile":
        strategy, check = hostile_inputs(), check_hostile
    elif target == "recording":
        from reliability_cases import small_recording

        with tempfile.TemporaryDirectory() as tmp:
            bag = small_recording(Path(tmp) / "recording")
            files = {p.name: p.read_bytes() for p in bag.iterdir()}
        strategy, check = recording_inputs(files), check_recording
    else:
        strategy, check = TARGETS[target]()
    outcomes: Counter = Counter()

    @settings(max_examples=examples, deadline=10_000, database=None, suppress_health_check=list(HealthCheck))
    @given(strategy)
    def run(value: object) -> None:
        outcomes[check(value)] += 1  # type: ignore[operator]

    run()
    print(dict(outcomes))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
