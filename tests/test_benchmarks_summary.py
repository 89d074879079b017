"""BENCHMARKS.md is the summary benchmarks/summary.py generates from benchmarks/results/*.json.

When ``test_committed_summary_is_up_to_date`` fails after a results file was added or changed,
run ``python benchmarks/summary.py`` and commit BENCHMARKS.md with the JSON.
"""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("benchmarks_summary", REPO / "benchmarks" / "summary.py")
assert _spec is not None and _spec.loader is not None
summary = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(summary)

_ROW = re.compile(r"^\| (?!figure \|)(?!---)(.+) \|$")


def _rows(text: str) -> list[list[str]]:
    return [m.group(1).split(" | ") for line in text.splitlines() if (m := _ROW.match(line))]


def test_committed_summary_is_up_to_date() -> None:
    committed = (REPO / "BENCHMARKS.md").read_text(encoding="utf-8")
    assert committed == summary.generate(), (
        "BENCHMARKS.md differs from what benchmarks/results/*.json give; run python benchmarks/summary.py"
    )


def test_summary_is_short_and_every_row_names_command_machine_date() -> None:
    text = (REPO / "BENCHMARKS.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) < 150
    rows = _rows(text)
    assert len(rows) >= 15
    machines = set(re.findall(r"^- (M\d+): .+$", text, flags=re.MULTILINE))
    for cells in rows:
        assert len(cells) == 8, cells
        _, value, _, _, command, machine, date, history = cells
        assert value.startswith("**"), cells
        assert command.startswith(("`python ", "`benchmarks/")), cells
        assert machine in machines, cells
        assert re.match(r"^\[\d{4}-\d\d-\d\d", date), cells
        assert history.startswith("[") and "docs/benchmarks/" in history, cells


def test_summary_links_resolve() -> None:
    text = (REPO / "BENCHMARKS.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    assert targets
    missing = [t for t in targets if not (REPO / t).exists()]
    assert not missing, missing


def _write(path: Path, **fields: object) -> Path:
    path.write_text(json.dumps(fields), encoding="utf-8")
    return path


def _figure(**over: object) -> dict[str, object]:
    return {"id": "f", "figure": "a figure", "value": 1.0, "unit": "s", **over}


def test_the_newest_run_of_a_figure_is_current(tmp_path: Path) -> None:
    run = {"command": "python benchmarks/x.py", "machine": "m", "history": "docs/benchmarks/x.md"}
    _write(tmp_path / "x_2026-01-02.json", **run, date="2026-01-02", figures=[_figure(value=2.0)])
    _write(tmp_path / "x_2026-01-01.json", **run, date="2026-01-01", figures=[_figure(value=1.0)])
    figs = summary.current(tmp_path.glob("*.json"))
    assert [(f["value"], f["file"]) for f in figs] == [(2.0, "x_2026-01-02.json")]
    assert "**2.0** s" in summary.render(figs)


def test_a_figure_without_command_or_date_is_refused(tmp_path: Path) -> None:
    path = _write(tmp_path / "x_2026-01-01.json", machine="m", history="h", figures=[_figure()])
    with pytest.raises(ValueError, match="lacks command"):
        summary.figures_of(path)
    path = _write(tmp_path / "y.json", command="python b.py", machine="m", history="h", figures=[_figure()])
    with pytest.raises(ValueError, match="lacks date"):
        summary.figures_of(path)


def test_a_raw_file_nobody_reads_is_refused(tmp_path: Path) -> None:
    path = _write(tmp_path / "mystery_2026-01-01.json", command="python b.py", rows=[])
    with pytest.raises(ValueError, match="no extractor for 'mystery'"):
        summary.figures_of(path)


def test_a_short_determinism_run_never_overwrites_the_figure_s_file(tmp_path: Path) -> None:
    """`benchmarks/determinism.py --runs 2` wrote determinism_<date>.json over the day's 100-run
    file, and so replaced BENCHMARKS.md's 100 of 100 by 2 of 2."""
    import datetime

    spec = importlib.util.spec_from_file_location(
        "benchmarks_determinism", REPO / "benchmarks" / "determinism.py"
    )
    assert spec is not None and spec.loader is not None
    determinism = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(determinism)
    results, runs_root, day = tmp_path / "results", tmp_path / "runs", datetime.date(2026, 11, 26)
    results.mkdir()
    assert determinism.default_json(2, runs_root, day, results) == runs_root / "determinism.json"
    first = determinism.default_json(100, runs_root, day, results)
    assert first == results / "determinism_2026-11-26.json"
    first.write_text("{}")
    second = determinism.default_json(100, runs_root, day, results)
    assert second == results / "determinism_2026-11-26_2.json"
    assert summary._family(second) == "determinism"  # still read by BENCHMARKS.md's extractor
