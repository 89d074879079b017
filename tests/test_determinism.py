"""Same config and seed, same bytes; replay reproduces the live metrics exactly.

The two runs differ in everything that must not matter: the process's string hash salt
(PYTHONHASHSEED: set iteration order), the number of encoder threads (thread completion order)
and Mesa's llvmpipe thread count (software rendering).
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from reliability_helpers import SMALL_RUN, messages_in_file_order, payload_digest

from conftest import run_cli
from simlan_data.constants import PACKAGE_DIR
from simlan_data.recording import schema
from simlan_data.seeding import run_rng, stream_key

DURATION = "duration_s=3"
# measured on the wall or CPU clock, not the simulated one
WALL_CLOCK_METRICS = (
    "sim.rtf",
    "sim.wall_s",
    "sim.render_wall_s",
    "sim.localize_wall_s",
    "sim.cpu_s",
    "sim.main_thread_cpu_s",
)
# the two runs' /simlan/config texts differ (thread counts), so their zstd chunks may differ in size
CONFIG_DEPENDENT_METRICS = ("recording.bytes", "job.encode_threads", "job.gl_threads")  # the knobs themselves


@pytest.fixture(scope="module")
def twin_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("determinism")
    a, b = root / "a", root / "b"
    proc = run_cli(*SMALL_RUN, DURATION, f"hydra.run.dir={a}", env={"PYTHONHASHSEED": "1"})
    assert proc.returncode == 0, proc.stderr
    proc = run_cli(
        *SMALL_RUN,
        DURATION,
        "recording.encode_threads=0",
        "render.software_gl_threads=2",
        f"hydra.run.dir={b}",
        env={"PYTHONHASHSEED": "2"},
    )
    assert proc.returncode == 0, proc.stderr
    return a, b


def test_same_config_and_seed_give_the_same_messages(twin_runs: tuple[Path, Path]) -> None:
    """Every message payload is identical; the recorded config differs only in the execution knobs."""
    a, b = (messages_in_file_order(run / "recording") for run in twin_runs)
    assert len(a) > 500 and len({m.topic for m in a}) > 20
    config = [[m for m in msgs if m.topic == schema.CONFIG] for msgs in (a, b)]
    a, b = ([m for m in msgs if m.topic != schema.CONFIG] for msgs in (a, b))
    if payload_digest(a) != payload_digest(b):
        differing = sorted(
            {x.topic for x, y in zip(a, b) if x != y} | {m.topic for m in a[len(b) :] + b[len(a) :]}
        )
        pytest.fail(f"payloads differ on {differing}")
    store = schema.typestore()
    ca, cb = (yaml.safe_load(store.deserialize_cdr(c[0].data, schema.STRING_TYPE).data) for c in config)
    assert (ca["recording"].pop("encode_threads"), cb["recording"].pop("encode_threads")) == (2, 0)
    assert (ca["render"].pop("software_gl_threads"), cb["render"].pop("software_gl_threads")) == (1, 2)
    assert ca == cb
    ma, mb = (json.loads((run / "metrics.json").read_text()) for run in twin_runs)
    for key in WALL_CLOCK_METRICS + CONFIG_DEPENDENT_METRICS:
        ma.pop(key), mb.pop(key)
    assert ma == mb


def test_replay_reproduces_the_live_metrics_exactly(twin_runs: tuple[Path, Path], tmp_path: Path) -> None:
    run = twin_runs[0]
    proc = run_cli(str(run / "recording"), "--out", str(tmp_path / "replay"), module="simlan_data.replay")
    assert proc.returncode == 0, proc.stderr
    live = json.loads((run / "metrics.json").read_text())
    replay = json.loads((tmp_path / "replay" / "metrics.json").read_text())
    compared = [k for k in live if k.startswith(("localization.", "navigation."))]
    assert (
        len(compared) >= 15
        and live["localization.ticks_valid" if False else "localization.ate_xy_rmse_m"] > 0
    )
    assert {k: replay.get(k) for k in compared} == {k: live[k] for k in compared}
    assert replay["replay.localization.max_diff_to_live_m"] == 0.0


# ------------------------------------------------------------------------------ static audit
FORBIDDEN_CALLS = {
    ("time", "time"): "the wall clock",
    ("time", "time_ns"): "the wall clock",
    ("datetime", "now"): "the wall clock",
    ("datetime", "today"): "the wall clock",
    ("datetime", "utcnow"): "the wall clock",
    ("os", "urandom"): "OS randomness",
    ("uuid", "uuid4"): "OS randomness",
    ("uuid", "uuid1"): "the wall clock",
}
ALLOWED_NP_RANDOM = {"default_rng", "Generator", "SeedSequence", "PCG64", "BitGenerator"}


def _problems(path: Path) -> list[str]:
    """Calls and imports that would make a run depend on more than (config, seed). A line marked
    ``# audit-ok: <why>`` is exempt (e.g. naming an output directory by the date, as Hydra does)."""
    text = path.read_text()
    exempt = {i + 1 for i, line in enumerate(text.splitlines()) if "# audit-ok:" in line}
    tree = ast.parse(text, filename=str(path))
    out = []
    for node in ast.walk(tree):
        if getattr(node, "lineno", 0) in exempt:
            continue
        where = f"{path.relative_to(PACKAGE_DIR.parent)}:{getattr(node, 'lineno', 0)}"
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            for name in names:
                if name.split(".")[0] in ("random", "secrets"):
                    out.append(
                        f"{where}: imports {name} (unseeded randomness; use simlan_data.seeding.run_rng)"
                    )
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if isinstance(func, ast.Name) and func.id == "hash":
            out.append(f"{where}: hash() of strings changes per process (use seeding.stream_key)")
        if isinstance(func, ast.Attribute):
            owner = func.value
            owner_name = owner.attr if isinstance(owner, ast.Attribute) else getattr(owner, "id", "")
            if (owner_name, func.attr) in FORBIDDEN_CALLS:
                out.append(
                    f"{where}: {owner_name}.{func.attr}() reads {FORBIDDEN_CALLS[owner_name, func.attr]}"
                )
            if owner_name == "random" and isinstance(owner, ast.Attribute):  # np.random.<fn>
                if func.attr not in ALLOWED_NP_RANDOM:
                    out.append(f"{where}: np.random.{func.attr}() uses numpy's global random state")
                elif func.attr == "default_rng" and not node.args and not node.keywords:
                    out.append(f"{where}: np.random.default_rng() without a seed")
    return out


def test_no_unseeded_randomness_or_wall_clock_in_the_package() -> None:
    files = sorted(PACKAGE_DIR.rglob("*.py"))
    assert len(files) > 50
    problems = [p for f in files for p in _problems(f)]
    assert problems == []


def test_the_audit_finds_what_it_looks_for() -> None:
    bad = PACKAGE_DIR / "_audit_probe_tmp.py"
    bad.write_text(
        "import random\nimport time\nimport numpy as np\n"
        "a = time.time()\nb = np.random.rand(3)\nc = np.random.default_rng()\nd = hash('x')\n"
        "e = np.random.default_rng(3)\n"
    )
    try:
        found = _problems(bad)
    finally:
        bad.unlink()
    assert len(found) == 5, found


def test_named_streams_are_reproducible_and_independent() -> None:
    a = run_rng(7, "camera_noise", "160").normal(size=1000)
    assert np.array_equal(a, run_rng(7, "camera_noise", "160").normal(size=1000))
    b = run_rng(7, "camera_noise", "161").normal(size=1000)
    c = run_rng(8, "camera_noise", "160").normal(size=1000)
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.1 and abs(np.corrcoef(a, c)[0, 1]) < 0.1
    assert stream_key("x") == (int.from_bytes(bytes.fromhex("2d711642"), "little"),)
    with pytest.raises(ValueError, match="name the stream"):
        run_rng(1)
