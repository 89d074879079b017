"""A sweep's runs exported as shards: ``python -m simlan_data.export SWEEP --format F --out DIR``.

SWEEP is a Hydra multirun directory (``multirun/DATE/TIME``, or any directory whose
subdirectories are run directories with a recording). Each run is exported, with the same
arguments, into ``DIR/<run name>/`` (one shard per run: per seed of a ``-m ... 'seed=range(N)'``
sweep), in run order, and ``DIR/shards.json`` lists them::

    {"format": "coco", "shards": [{"name": "0", "run": "/abs/multirun/.../0", "path": "0"}, ...]}

The shards are independent datasets in the format's own layout (a COCO file per shard, a MOT
sequence set per shard, a LeRobot dataset per shard), as sharded training sets are read: each
loader takes a list of shard paths. Nothing is merged, so a large sweep streams one run at a time.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path

from simlan_data.errors import ConfigError

__all__ = ["SHARDS_FILE", "check_out", "export_shards", "sweep_runs"]

SHARDS_FILE = "shards.json"


def check_out(out: Path) -> None:
    """Refuse an ``--out`` that exists and is not an empty directory (export never overwrites)."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ConfigError(
            "invalid --out",
            str(out),
            "it exists and is not an empty directory (export never overwrites)",
            "choose a new --out or remove it",
        )


def _run_key(path: Path) -> tuple[int, int | str]:
    return (0, int(path.name)) if path.name.isdigit() else (1, path.name)


def sweep_runs(path: Path) -> list[Path] | None:
    """The run directories of a sweep directory in run order, or None when ``path`` is not one (a run
    directory, a recording, a metadata file, or a directory without runs)."""
    if not path.is_dir() or (path / "recording").exists() or (path / "metadata.yaml").exists():
        return None
    runs = [d for d in path.iterdir() if d.is_dir() and (d / "recording" / "metadata.yaml").is_file()]
    return sorted(runs, key=_run_key) or None


def export_shards(
    runs: Sequence[Path], out: Path, fmt: str, options: Sequence[str], export_one: Callable[[list[str]], int]
) -> int:
    """Export every run with ``export_one`` (the export command's ``main``) into ``out/<run name>``
    and write the shard list; returns the exit code."""
    check_out(out)
    shards: list[dict[str, str]] = []
    for run in runs:
        try:
            export_one([str(run), "--format", fmt, "--out", str(out / run.name), *options])
        except ConfigError:
            if not shards and out.is_dir() and not any(out.iterdir()):
                out.rmdir()  # refused before anything was written: leave nothing behind
            raise
        shards.append({"name": run.name, "run": str(run.resolve()), "path": run.name})
    (out / SHARDS_FILE).write_text(json.dumps({"format": fmt, "shards": shards}, indent=1) + "\n")
    print(f"exported {len(shards)} shards ({fmt}) -> {out} ({SHARDS_FILE} lists them)")
    return 0
