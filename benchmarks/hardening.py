"""The hardening cases of issue 21, for ``benchmarks/reliability.py`` (section ``hardening``).

Two tables, each case with what is expected and what was observed:

1. Hostile input through the public CLI, timed: each must answer within 5 s with one line and
   exit 2 (a YAML alias bomb in a ``--config-dir``, a ``+`` typo, a FIFO named
   ``recording.mcap``, a ``metadata.yaml`` claiming 10**23 messages, ``replay --set hold_s=abc``,
   ``replay --info | head -1``).
2. The issue's behaviour tests (real processes, real signals, real tmpfs for a full disk, real
   damaged bags read back with ``mcap``), run through pytest: one row per test, its outcome and
   wall time.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml
from reliability_helpers import SMALL_RUN

from common import REPO, run_cli

BEHAVIOUR_TESTS = (
    "tests/test_signals.py",
    "tests/test_run_dir.py",
    "tests/test_recovery_losses.py",
    "tests/test_hostile_inputs.py",
    "tests/test_config_bounds.py",
    "tests/test_disk_full.py",
    "tests/test_metrics_json.py",
    "tests/test_determinism.py",
)
ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [{', '.join(['*' + p] * 9)}]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=True)
)


def _timed(args: list[str], *, module: str = "simlan_data.run") -> tuple[int, str, float]:
    t0 = time.perf_counter()
    try:
        proc = run_cli(*args, module=module, timeout=60)
        code, err = proc.returncode, proc.stderr
    except subprocess.TimeoutExpired:
        code, err = -1, "timed out after 60 s"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    return code, " / ".join(lines) if len(lines) != 1 else lines[0], time.perf_counter() - t0


def hostile_inputs(root: Path) -> list[dict[str, object]]:
    bag_run = root / "hostile_base"
    proc = run_cli(*SMALL_RUN, "duration_s=0.5", f"hydra.run.dir={bag_run}")
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    bag = bag_run / "recording"
    rows: list[dict[str, object]] = []

    def case(name: str, code: int, line: str, wall: float, want: int = 2, extra_ok: bool = True) -> None:
        ok = code == want and wall < 5.0 and "\n" not in line and line.startswith("error:") and extra_ok
        rows.append({"case": name, "exit": code, "line": line[:160], "wall_s": round(wall, 2), "ok": ok})
        print(f"  hostile {rows[-1]}", file=sys.stderr)

    cdir = root / "bomb_conf" / "agents"
    cdir.mkdir(parents=True)
    (cdir / "boom.yaml").write_text(ALIAS_BOMB)
    out = root / "bomb_run"
    code, line, wall = _timed(["--config-dir", str(cdir.parent), "agents=boom", f"hydra.run.dir={out}"])
    case(
        f"alias bomb ({len(ALIAS_BOMB)} B) in --config-dir agents/boom.yaml",
        code,
        line,
        wall,
        extra_ok=not out.exists(),
    )
    out = root / "typo_run"
    code, line, wall = _timed(["+recording.fsynk=true", f"hydra.run.dir={out}"])
    case(
        "+recording.fsynk=true (a typo forced with +)",
        code,
        line,
        wall,
        extra_ok=not out.exists() and "fsync" in line,
    )

    fifo_bag = root / "fifo_bag"
    fifo_bag.mkdir()
    shutil.copy(bag / "metadata.yaml", fifo_bag / "metadata.yaml")
    os.mkfifo(fifo_bag / "recording.mcap")
    code, line, wall = _timed([str(fifo_bag), "--info"], module="simlan_data.replay")
    case("FIFO named recording.mcap: replay --info", code, line, wall)

    big = root / "count_bag"
    shutil.copytree(bag, big)
    meta = big / "metadata.yaml"
    doc = yaml.safe_load(meta.read_text())
    doc["rosbag2_bagfile_information"]["message_count"] = 10**23
    meta.write_text(yaml.safe_dump(doc, sort_keys=False))
    code, line, wall = _timed([str(big), "--info"], module="simlan_data.replay")
    case("metadata.yaml message_count: 1e23: replay --info", code, line, wall)

    out = root / "hold_out"
    code, line, wall = _timed(
        [str(bag), "--algorithms", "safety", "--set", "hold_s=abc", "--out", str(out)],
        module="simlan_data.replay",
    )
    case("replay --algorithms safety --set hold_s=abc --out OUT", code, line, wall, extra_ok=not out.exists())

    t0 = time.perf_counter()
    pipe = subprocess.run(
        f"{sys.executable} -m simlan_data.replay {bag} --info | head -1",
        shell=True,
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
        env={k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"},
    )
    quiet = "Traceback" not in pipe.stderr and "BrokenPipeError" not in pipe.stderr
    rows.append(
        {
            "case": "replay --info | head -1",
            "exit": "(pipe)",
            "line": pipe.stderr.strip()[:160] or "(nothing on stderr)",
            "wall_s": round(time.perf_counter() - t0, 2),
            "ok": quiet and len(pipe.stdout.splitlines()) == 1,
        }
    )
    return rows


def behaviour_tests(root: Path) -> list[dict[str, object]]:
    xml = root / "hardening_junit.xml"
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            f"--junitxml={xml}",
            *BEHAVIOUR_TESTS,
        ],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    rows = []
    for tc in ET.parse(xml).getroot().iter("testcase"):
        outcome = "passed"
        for child in tc:
            if child.tag in ("failure", "error"):
                outcome = "FAILED"
            elif child.tag == "skipped":
                outcome = f"skipped ({child.get('message', '')[:60]})"
        module = tc.get("classname", "").rsplit(".", 1)[-1]
        expected = re.sub(r"^test_", "", tc.get("name", "")).replace("_", " ")
        rows.append(
            {
                "module": module,
                "expected": expected,
                "observed": outcome,
                "wall_s": round(float(tc.get("time", 0)), 1),
            }
        )
    return rows
