"""The suite file: cases, grids, pending requirements, faults, and one clear line per bad entry."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from conftest import compose_config
from simlan_data.apps import evals
from simlan_data.config.schema import register_configs
from simlan_data.errors import ConfigError
from simlan_data.evaluation.suite import check_jobs, job_name, plan_jobs, write_job_configs
from simlan_data.evaluation.suite_spec import load_suite, select_faults, unmet

CASE = {
    "overrides": ["scenario=single_truck", "duration_s=5"],
    "replay": {"localization": {}},
    "metrics": {
        "run": {"navigation.collisions": {"max": 0}},
        "localization": {"localization.ate_xy_rmse_m": {"max": 0.02, "tolerance": 0.004}},
    },
}


def write(tmp_path: Path, doc: dict) -> Path:
    path = tmp_path / "suite.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def suite_doc(**case_changes: object) -> dict:
    return {
        "faults": {
            "bias": {
                "run": ["algorithms.localizer.bias_m=[0.05,0.0]"],
                "replay": {"localization": {"bias_m": [0.05, 0.0]}},
            }
        },
        "suites": {
            "s": {"baseline": "baselines/s.parquet", "seeds": 2, "cases": {"c": {**CASE, **case_changes}}}
        },
    }


def test_the_shipped_suite_file_loads_with_its_pending_entries() -> None:
    base = load_suite(evals.DEFAULT_FILE, "base")
    names = {c.family for c in base.cases}
    assert {"single_truck", "multi_robot", "default"} <= names
    assert {
        "restricted_zone",
        "blind_spot",
        "humanoid_crossing",
        "collision_slice",
        "posemap_replay",
    } <= names
    ready = {c.name for c in base.cases if not c.pending}
    assert {"single_truck", "multi_robot", "default", "posemap_replay"} <= ready
    assert set(base.faults) >= {"bias", "latency", "drop_camera", "calibration", "safety_condition"}
    assert all(
        len(c.seeds) == 3 for c in base.cases if c.family in ("single_truck", "multi_robot", "default")
    )
    golden = load_suite(evals.DEFAULT_FILE, "golden")
    assert all(c.recording is not None and c.seeds == (0,) for c in golden.cases)


def test_grid_expands_into_one_case_per_cell(tmp_path: Path) -> None:
    suite = load_suite(
        write(tmp_path, suite_doc(grid={"perturbation.spawn_xy_m": [0.0, 0.1], "seed": [1]})), "s"
    )
    assert [c.name for c in suite.cases] == [
        "c[perturbation.spawn_xy_m=0.0,seed=1]",
        "c[perturbation.spawn_xy_m=0.1,seed=1]",
    ]
    assert suite.cases[1].overrides[-2:] == ("perturbation.spawn_xy_m=0.1", "seed=1")
    assert {c.family for c in suite.cases} == {"c"}


def test_unmet_requirements_make_a_case_pending_not_failed(tmp_path: Path) -> None:
    doc = suite_doc(requires=["config:nonexistent.section"], pending_note="a later issue")
    doc["suites"]["s"]["cases"]["c"]["replay"] = {"not_yet_registered": {}}
    doc["suites"]["s"]["cases"]["c"]["metrics"] = {"not_yet_registered": {"x.y": {"max": 1}}}
    case = load_suite(write(tmp_path, doc), "s").cases[0]
    assert case.pending.startswith(
        "needs config key 'nonexistent.section', replay algorithm 'not_yet_registered'"
    )
    assert case.pending.endswith("waiting for the a later issue")
    assert unmet("replay:localization") == ""
    assert unmet("config:algorithms.localizer.bias_m") == ""
    assert unmet("conf:scenario/single_truck") == ""
    assert unmet("conf:scenario/nope") == "config file conf/scenario/nope.yaml"
    assert unmet("module:json") == ""
    assert unmet("module:no_such_module_here=posemap") == (
        "Python module 'no_such_module_here' (pip install -e \".[posemap]\")"
    )


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"colour": 1}, "unknown key 'colour' in .*cases.c: known:"),
        (
            {"metrics": {"birdseye": {"birdseye.coverage": {"min": 0.9}}}},
            "unknown metrics source 'birdseye' in .*cases.c.metrics.birdseye",
        ),
        (
            {"metrics": {"run": {"a.b": {"max": "small"}}}},
            "invalid max='small' in .*metrics.run.a.b: expected a number",
        ),
        ({"metrics": {"run": {"a.b": {}}}}, "empty bound in .*metrics.run.a.b"),
        ({"metrics": {"run": {"a.b": {"max": 1, "better": "more"}}}}, "invalid better='more'"),
        ({"metrics": {"run": {"a.b": {"tolerance": -1}}}}, "invalid tolerance .*must be >= 0"),
        ({"metrics": {}}, "no metrics in .*cases.c.metrics"),
        ({"seeds": 0}, r"invalid seeds=0 in .*cases.c: expected an integer within 1..1000"),
        (
            {"overrides": [], "replay": {}, "metrics": {"run": {"a": {"max": 1}}}},
            "invalid case in .*neither overrides",
        ),
        ({"requires": ["plugin:x"]}, "invalid requirement 'plugin:x' in requires"),
        ({"replay": {"nope": {}}, "metrics": {"nope": {"a": {"max": 1}}}, "requires": []}, None),
    ],
)
def test_bad_case_entries_are_one_clear_error(tmp_path: Path, change: dict, match: str | None) -> None:
    path = write(tmp_path, suite_doc(**change))
    if match is None:  # an unregistered replay algorithm without requires: pending, not an error
        assert load_suite(path, "s").cases[0].pending == "needs replay algorithm 'nope'"
        return
    with pytest.raises(ConfigError, match=match):
        load_suite(path, "s")


def test_bad_files_and_names(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"suite file missing in .*nope.yaml"):
        load_suite(tmp_path / "nope.yaml", "s")
    bad = tmp_path / "bad.yaml"
    bad.write_text("suites: [unclosed\n")
    with pytest.raises(ConfigError, match="suite file unreadable"):
        load_suite(bad, "s")
    path = write(tmp_path, suite_doc())
    with pytest.raises(ConfigError, match=r"unknown suite 'base' in .*suites: s; pick one"):
        load_suite(path, "base")
    suite = load_suite(path, "s")
    with pytest.raises(ConfigError, match="unknown fault 'bais' in --inject: known: bias"):
        select_faults(suite, ["bais"])
    doc = suite_doc()
    doc["faults"]["empty"] = {"description": "nothing"}
    with pytest.raises(ConfigError, match=r"empty fault in .*faults.empty"):
        load_suite(write(tmp_path, doc), "s")


def test_a_case_becomes_a_hydra_config_group_option(tmp_path: Path) -> None:
    """What the suite's multirun composes for a case equals the same overrides on the command line."""
    doc = suite_doc()
    doc["suites"]["s"]["overrides"] = ["perturbation.spawn_xy_m=0.15", "cameras.streams=[rgb,semantic]"]
    doc["suites"]["s"]["cases"]["c"]["overrides"] = [
        "scenario=single_truck",
        "cameras=single",
        "duration_s=5",
        "agents.robot_agent_1.goals=[[-4.0,-0.5],[12.0,1.2]]",
        "agents.robot_agent_2.type=jackal",
        "agents.robot_agent_2.pose=[10.0,-0.6,3.14159]",
    ]
    suite = load_suite(write(tmp_path, doc), "s")
    jobs = plan_jobs(list(suite.cases), tmp_path / "runs")
    assert [j.name for j in jobs] == [job_name("c", 0), job_name("c", 1)] == ["c__s0", "c__s1"]
    write_job_configs(suite, jobs, tmp_path / "conf")
    register_configs()
    cfg = compose_config(f"hydra.searchpath=[file://{tmp_path / 'conf'}]", "+vv_job=c__s1")
    assert cfg.seed == 1
    assert cfg.scenario.name == "single_truck"
    assert list(cfg.cameras.ids) == [163]
    assert cfg.duration_s == 5
    assert cfg.perturbation.spawn_xy_m == 0.15
    assert list(cfg.cameras.streams) == ["rgb", "semantic"]
    assert [list(g) for g in cfg.agents.robot_agent_1.goals] == [[-4.0, -0.5], [12.0, 1.2]]
    # a second robot added by config merge (the command line cannot add a typed entry)
    assert cfg.agents.robot_agent_2.type == "jackal"
    assert list(cfg.agents.robot_agent_1.pose) == [-16.0, 0.4, 0.0]


def test_faults_act_only_on_the_cases_subject_to_them(tmp_path: Path) -> None:
    doc = suite_doc()
    doc["suites"]["s"]["cases"]["d"] = {**CASE, "faults": []}  # e.g. a case without the fault's camera
    suite = load_suite(write(tmp_path, doc), "s")
    jobs = plan_jobs(list(suite.cases), tmp_path / "runs")
    write_job_configs(suite, jobs, tmp_path / "conf", select_faults(suite, ["bias"]))
    register_configs()
    search = f"hydra.searchpath=[file://{tmp_path / 'conf'}]"
    assert list(compose_config(search, "+vv_job=c__s0").algorithms.localizer.bias_m) == [0.05, 0.0]
    assert list(compose_config(search, "+vv_job=d__s0").algorithms.localizer.bias_m) == [0.0, 0.0]
    doc["suites"]["s"]["cases"]["d"]["faults"] = ["bais"]
    with pytest.raises(ConfigError, match=r"unknown fault 'bais' in .*cases.d.faults: faults: bias"):
        load_suite(write(tmp_path, doc), "s")


def test_every_fault_can_be_injected_into_the_whole_base_suite(tmp_path: Path) -> None:
    """Every case's run config, with every fault that acts on it, composes and validates
    (e.g. a camera fault never reaches the pose-mapping case, whose cameras are 500-503)."""
    suite = load_suite(evals.DEFAULT_FILE, "base", seeds=1)
    faults = select_faults(suite, list(suite.faults))
    jobs = plan_jobs([c for c in suite.cases if not c.pending], tmp_path / "runs")
    write_job_configs(suite, jobs, tmp_path / "conf", faults)
    check_jobs(jobs, tmp_path / "conf", [])
    assert {j.case.family for j in jobs} >= {"single_truck", "posemap_replay"}
