"""A recording's own config (``/simlan/config``) is YAML too: an alias bomb there must not hang
``replay`` or ``recover`` (each answers within 5 s; replay refuses with one line, exit 2)."""

from __future__ import annotations

import time
from pathlib import Path

from reliability_cases import run_info_for_tests
from reliability_helpers import mcap_file

from conftest import run_cli
from simlan_data.constants import NS_PER_S
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.writer import RecordingWriter

BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [{', '.join(['*' + p] * 9)}]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=True)
)


def _recording(path: Path) -> Path:
    by_name = {t.name: t for t in schema.GLOBAL_TOPICS}
    with RecordingWriter(path, flush_period_ns=NS_PER_S // 2) as w:
        w.set_metadata("simlan.format_version", "1.0")
        w.write(by_name[schema.CONFIG], 0, M.string(BOMB))
        w.write(by_name[schema.RUN_INFO], 0, run_info_for_tests("bomb"))
        w.write(by_name[schema.TF_STATIC], 0, M.tf_message([]))
        for k in range(121):
            t = k * NS_PER_S // 60
            w.write(by_name[schema.CLOCK], t, M.clock(t))
            pose = Transform.from_pose2d(0.01 * k, 0.0, 0.0)
            w.write(
                by_name[schema.GROUND_TRUTH_POSES],
                t,
                M.tf_message([M.transform_stamped(t, "map", "robot_agent_1/base_link", pose)]),
            )
    return path


def test_replay_refuses_an_alias_bomb_in_the_recorded_config_at_once(tmp_path: Path) -> None:
    bag = _recording(tmp_path / "run" / "recording")
    out = tmp_path / "out"
    t0 = time.monotonic()
    proc = run_cli(str(bag), "--out", str(out), module="simlan_data.replay", timeout=30)
    assert time.monotonic() - t0 < 5.0 + 3.0  # (+ the interpreter's start)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "recorded config unreadable" in lines[0] and "alias" in lines[0], lines[0]
    assert not out.exists()


def test_recover_reads_past_an_alias_bomb_in_the_recorded_config(tmp_path: Path) -> None:
    bag = _recording(tmp_path / "run" / "recording")
    f = mcap_file(bag)
    f.write_bytes(f.read_bytes()[: f.stat().st_size * 2 // 3])  # a crash: no summary, no footer
    (bag / "metadata.yaml").unlink()
    t0 = time.monotonic()
    proc = run_cli(str(tmp_path / "run"), module="simlan_data.recover", timeout=30)
    assert time.monotonic() - t0 < 5.0 + 3.0
    assert proc.returncode == 0, proc.stderr
    assert (bag / "metadata.yaml").is_file()
