"""A full disk is a failed run (exit 1) naming the file and what was kept: never exit 0 with an
output missing, never "invalid configuration" (exit 2).

Each test mounts a small tmpfs (root only; skipped where mounting is not permitted) as the run
directory's disk and fills it to where the run must fail.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from conftest import run_cli
from simlan_data.evaluation.report_figures import ERROR_FILENAME, TIMELINE_FILENAME, TRAJECTORIES_FILENAME

RUN_ARGS = ("duration_s=1", "cameras=single", "world.fidelity=empty", "progress=false")  # a quick run


@pytest.fixture
def tmpfs(tmp_path: Path) -> Iterator[Path]:
    """A 4 MiB tmpfs, unmounted afterwards."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs root and mount(8)")
    proc = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mnt)], capture_output=True, text=True
    )
    if proc.returncode != 0:
        pytest.skip(f"mounting a tmpfs is not permitted here: {proc.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def _free_bytes(mnt: Path) -> int:
    st = os.statvfs(mnt)
    return st.f_bavail * st.f_frsize


def _fill(mnt: Path, leave: int) -> None:
    """Write a filler file so that about ``leave`` bytes stay free."""
    size = max(0, _free_bytes(mnt) - leave)
    with open(mnt / "filler", "wb") as f:
        f.truncate(0)
        block = b"\0" * (1 << 16)
        while size > 0:
            f.write(block[: min(size, len(block))])
            size -= min(size, len(block))
    assert abs(_free_bytes(mnt) - leave) <= 8192, (_free_bytes(mnt), leave)


def _one_error_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip() and "libpng" not in ln]
    assert len(lines) == 1, stderr
    return lines[0]


FIGURES = (TRAJECTORIES_FILENAME, ERROR_FILENAME, TIMELINE_FILENAME)


def test_disk_full_at_start_is_a_failed_run_not_a_bad_config(tmpfs: Path) -> None:
    _fill(tmpfs, 0)
    run_dir = tmpfs / "run"
    proc = run_cli(*RUN_ARGS, f"hydra.run.dir={run_dir}", timeout=60)
    assert proc.returncode == 1, proc.stderr
    line = _one_error_line(proc.stderr)
    assert line.startswith(f"error: no space left on {run_dir}"), line
    assert "errno ENOSPC" in line and "nothing of the run was kept" in line, line
    assert "invalid configuration" not in line


def test_disk_full_while_writing_the_report_names_what_was_kept(tmpfs: Path) -> None:
    """cv2.imwrite returned False on a full disk: 'finished', exit 0, report_cameras.png missing
    but linked from report.md. Sized from a first run on the same disk: room for everything
    the run writes before its report, and half of the camera mosaic."""
    first = tmpfs / "first"
    free0 = _free_bytes(tmpfs)
    proc = run_cli(*RUN_ARGS, f"hydra.run.dir={first}", timeout=60)
    assert proc.returncode == 0, proc.stderr
    mosaic = first / "report_cameras.png"
    report_bytes = sum(  # (the figures come after the mosaic)
        -(-(first / name).stat().st_size // 4096) * 4096
        for name in ("report_cameras.png", "report.md", *FIGURES)
        if (first / name).exists()
    )
    before_report = free0 - _free_bytes(tmpfs) - report_bytes
    half_mosaic = mosaic.stat().st_size // 2
    shutil.rmtree(first)

    _fill(tmpfs, before_report + half_mosaic)
    run_dir = tmpfs / "run"
    proc = run_cli(*RUN_ARGS, f"hydra.run.dir={run_dir}", timeout=60)
    assert proc.returncode == 1, proc.stderr + proc.stdout
    line = _one_error_line(proc.stderr)
    assert line.startswith(f"error: no space left on {run_dir / 'report_cameras.png'}: "), line
    assert f"kept: {run_dir / 'recording'}, {run_dir / 'metrics.json'}" in line, line
    assert "finished" not in proc.stdout
    assert not (run_dir / "report_cameras.png").exists()  # no half-written file
    report = run_dir / "report.md"
    assert not report.exists() or "report_cameras.png" not in report.read_text()
    assert (run_dir / "metrics.json").is_file() and (run_dir / "recording").is_dir()


def test_disk_errors_map_to_one_line_and_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """ENOSPC, EDQUOT, EIO and EROFS anywhere in the chain: exit 1, the file named."""
    from simlan_data.apps.cli import run_cli as cli
    from simlan_data.errors import RunError

    (tmp_path / "recording").mkdir()
    (tmp_path / "metrics.json").write_text("{}\n")
    target = tmp_path / "report.md"
    for code, words in [
        (errno.ENOSPC, "no space left on"),
        (errno.EDQUOT, "disk quota exceeded on"),
        (errno.EIO, "input/output error on"),
        (errno.EROFS, "read-only file system at"),
    ]:

        def main(code: int = code) -> None:
            try:
                raise OSError(code, os.strerror(code), str(target))
            except OSError as err:
                raise RunError("simulation failed", str(tmp_path), str(err)) from err

        with pytest.raises(SystemExit) as exit_info:
            cli(main, started=lambda: False)  # even before the run began: not a bad config
        assert exit_info.value.code == 1, words
        line = _one_error_line(capsys.readouterr().err)
        assert line.startswith(f"error: {words} {target}: "), line
        assert f"kept: {tmp_path / 'recording'}, {tmp_path / 'metrics.json'}" in line, line
