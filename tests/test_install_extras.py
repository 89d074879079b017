"""The base install is light: only pose mapping needs torch, an extra (``.[posemap]``); without
it the pose-mapping models that need it say so in one line."""

from __future__ import annotations

import sys

import pytest
import tomllib

from conftest import REPO
from simlan_data.errors import EXIT_BAD_INPUT, ConfigError


def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())


def test_the_base_install_has_no_torch_and_the_extras_do() -> None:
    project = _pyproject()["project"]
    assert not [d for d in project["dependencies"] if d.lower().startswith("torch")]
    extras = project["optional-dependencies"]
    assert extras["posemap"] == ["torch==2.13.0"]
    assert "simlan-data[posemap]" in extras["test"]  # the tests cover pose mapping


def test_without_torch_the_mlp_models_name_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    from simlan_data.algorithms.posemap.models import MLPMapper, TrainParams

    monkeypatch.setitem(sys.modules, "torch", None)  # what Python does when torch is not installed
    mapper = MLPMapper(TrainParams())
    with pytest.raises(ConfigError) as caught:
        mapper._net(4, 2)
    line = caught.value.line()
    assert caught.value.exit_code == EXIT_BAD_INPUT and "\n" not in line
    assert 'pip install -e ".[posemap]"' in line and "torch is not installed" in line
