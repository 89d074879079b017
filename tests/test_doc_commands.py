"""The commands README.md and docs/ show stay valid: every ``simlan_data.run`` command composes and
passes the config checks, every replay/export/evals/view/recover command parses.

This is the cheap, always-on half of "every documented command runs as written";
``scripts/doc_commands.py`` runs them for real (minutes to hours; results in
docs/benchmarks/doc_commands.md). Sweeps (``-m``) are composed with the first value of each
swept key. Plug-ins the docs use as templates (``my_package``, ``my_pkg``, the entry point
``mine``) come from tests/data/doc_plugins on sys.path; ``mine`` needs an installed entry
point and is checked through its import path instead.
"""

from __future__ import annotations

import importlib
import importlib.util
import re
import shlex
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from simlan_data.config.validation import compose_config
from simlan_data.constants import ASSETS_DIR

ROOT = Path(__file__).resolve().parent.parent
PLUGINS = Path(__file__).resolve().parent / "data" / "doc_plugins"
_spec = importlib.util.spec_from_file_location("doc_commands", ROOT / "scripts" / "doc_commands.py")
assert _spec is not None and _spec.loader is not None
doc_commands = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(doc_commands)

COMMANDS = doc_commands.extract(ROOT)
APPS = {
    "simlan_data.replay": "simlan_data.apps.replay",
    "simlan_data.export": "simlan_data.apps.export",
    "simlan_data.evals": "simlan_data.apps.evals",
    "simlan_data.view": "simlan_data.apps.view",
    "simlan_data.recover": "simlan_data.apps.recover",
}


def _argv(cmd: str, module: str) -> list[str] | None:
    """The arguments after ``python -m MODULE`` of a one-command line, else None."""
    syntax = re.sub(r"\[--[^\]]*\]", " ", cmd.replace("\\\n", " "))  # [--seeds N]: optional, in a usage line
    words = shlex.split(syntax)
    if len(words) < 3 or words[0] != "python" or words[1:3] != ["-m", module]:
        return None
    return words[3:]


def _overrides(argv: list[str]) -> list[str]:
    """Hydra overrides of a run command; a sweep keeps its first value."""
    out = []
    for arg in argv:
        if arg in ("-m", "--multirun") or arg.startswith("--cfg") or arg == "job":
            continue
        key, _, value = arg.partition("=")
        if value.startswith("range("):
            bounds = value[len("range(") : -1].split(",")
            value = bounds[0] if len(bounds) > 1 else "0"
        elif "," in value and value[0] not in "[{'\"":
            value = value.split(",")[0]
        out.append(f"{key}={value}")
    return out


RUNS = [c for c in COMMANDS if _argv(c["cmd"], "simlan_data.run") is not None]
OTHERS = [(c, m) for c in COMMANDS for m in APPS if _argv(c["cmd"], m) is not None]


def test_the_docs_show_commands_of_every_app() -> None:
    assert len(RUNS) >= 40, [c["where"] for c in RUNS]
    assert {m for _, m in OTHERS} == set(APPS)


@pytest.fixture
def doc_plugins(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[Path]:
    """The docs' template plug-ins importable, and the files a reader supplies (tracks.json) there."""
    monkeypatch.syspath_prepend(str(PLUGINS))
    monkeypatch.chdir(tmp_path)
    shutil.copy(ASSETS_DIR / "trajectories" / "example_trajectory.json", tmp_path / "tracks.json")
    yield tmp_path
    for name in [n for n in sys.modules if n.split(".")[0] in ("my_package", "my_pkg")]:
        del sys.modules[name]


@pytest.mark.parametrize("item", RUNS, ids=lambda c: c["where"])
@pytest.mark.usefixtures("doc_plugins")
def test_documented_run_command_composes(item: dict) -> None:
    overrides = _overrides(_argv(item["cmd"], "simlan_data.run") or [])
    # the entry point `mine` (docs/plugins.md registers it in the reader's pyproject.toml)
    overrides = [o.replace("=mine", "=my_package.localizer:MyLocalizer") for o in overrides]
    if (
        any("=centroid" in o for o in overrides)
        and importlib.util.find_spec("simlan_centroid_localizer") is None
    ):
        pytest.skip(
            "the example plug-in is not installed (pip install -e examples/simlan_centroid_localizer)"
        )
    compose_config(overrides)  # raises ConfigError naming the key, value and fix


@pytest.mark.parametrize("item", OTHERS, ids=lambda x: x[0]["where"])
def test_documented_command_parses(item: tuple[dict, str]) -> None:
    cmd, module = item
    parser = importlib.import_module(APPS[module]).build_parser()
    parser.parse_args(_argv(cmd["cmd"], module))  # SystemExit(2) on an unknown flag or a missing argument
