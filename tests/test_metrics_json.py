"""metrics.json is strict JSON (JavaScript's JSON.parse, jq): null where a metric is not a number."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from conftest import run_cli


def strict_loads(text: str) -> object:
    """``json.loads`` that refuses NaN, Infinity and -Infinity, as strict parsers do."""

    def refuse(constant: str) -> object:
        raise ValueError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def test_dumps_metrics_is_strict_and_reads_back_as_nan() -> None:
    from simlan_data.metrics_io import dumps_metrics, loads_metrics

    metrics = {"a": math.nan, "b": math.inf, "c": -math.inf, "d": 1.5, "e": np.float64("nan"), "f": 3}
    text = dumps_metrics(metrics)
    assert strict_loads(text) == {"a": None, "b": None, "c": None, "d": 1.5, "e": None, "f": 3}
    back = loads_metrics(text)
    assert math.isnan(back["a"]) and math.isnan(back["b"]) and back["d"] == 1.5 and back["f"] == 3
    assert math.isnan(loads_metrics('{"old": NaN}')["old"])  # files written before


def test_sweep_reads_null_as_nan(tmp_path: Path) -> None:
    from simlan_data.evaluation.sweep import collect_sweep

    job = tmp_path / "0"
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "overrides.yaml").write_text("- seed=1\n")
    (job / "metrics.json").write_text('{"sim.rtf": 2.0, "localization.ate_m": null}\n')
    table = collect_sweep(tmp_path)
    assert table["sim.rtf"].to_list() == [2.0]
    assert math.isnan(table["localization.ate_m"][0])


def test_run_metrics_json_is_strict_json(tmp_path: Path) -> None:
    """A real run's metrics.json (its localization metrics are NaN: 1 s is too short for an
    estimate) parses with a strict parser."""
    run_dir = tmp_path / "run"
    proc = run_cli("duration_s=1", "cameras=single", "progress=false", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr
    doc = strict_loads((run_dir / "metrics.json").read_text())
    assert isinstance(doc, dict) and doc["sim.duration_s"] > 0
    assert any(v is None for v in doc.values())  # (the run has metrics without a value)
