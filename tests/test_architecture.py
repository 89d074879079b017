"""The import contract (docs/layout.md): layers, forbidden imports, no cycles, a small top level.

`lint-imports` checks the contracts written in pyproject.toml ([tool.importlinter]); the tests
below add what import-linter does not say: no cycle among any modules, the top level's modules,
no package module shadowing the standard library, and every subpackage's ``__all__``.
"""

from __future__ import annotations

import importlib
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import simlan_data

# import-linter 2.17 (acyclic_siblings, grimp's exclude_type_checking_imports) and tomllib need 3.11;
# the test extra installs import-linter only there
pytestmark = pytest.mark.skipif(sys.version_info < (3, 11), reason="import-linter needs Python 3.11")

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "simlan_data"

# the top level: the package, the shared leaves every layer may import, the `python -m` names
TOP_LEVEL_MODULES = {
    "__init__",
    "__main__",
    "errors",
    "constants",
    "seeding",
    "metrics_io",
    "run",
    "replay",
    "evals",
    "recover",
    "view",
    "export",
}


def _subpackages() -> list[str]:
    return sorted(i.name for i in pkgutil.walk_packages(simlan_data.__path__, "simlan_data.") if i.ispkg)


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's algorithm (iterative): the components of more than one module, i.e. the cycles."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            node, pos = work.pop()
            if pos == 0:
                index[node] = low[node] = counter
                counter += 1
                stack.append(node)
                on_stack.add(node)
            targets = sorted(graph[node])
            for k in range(pos, len(targets)):
                target = targets[k]
                if target not in index:
                    work.append((node, k + 1))
                    work.append((target, 0))
                    break
                if target in on_stack:
                    low[node] = min(low[node], index[target])
            else:
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
    return found


def test_strongly_connected_finds_a_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e"}}
    assert _strongly_connected(graph) == [["a", "b", "c"]]
    assert _strongly_connected({"a": {"b"}, "b": set()}) == []


def test_import_contracts_hold() -> None:
    """`lint-imports` (pyproject.toml [tool.importlinter]) exits 0; its report is shown otherwise."""
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            "from importlinter.cli import lint_imports_command; lint_imports_command()",
            "--no-cache",
            "--no-logo",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "0 broken" in proc.stdout, proc.stdout


def test_every_subpackage_has_a_layer() -> None:
    """A new subpackage is placed in the layers contract, or the contract says nothing about it."""
    import tomllib

    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"]
    (layers,) = [c for c in config["contracts"] if c["type"] == "layers"]
    layered = {name.strip() for layer in layers["layers"] for name in layer.split("|")}
    top = {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    assert top == layered, (
        f"not in the layers contract: {sorted(top - layered)}; gone: {sorted(layered - top)}"
    )


def test_no_import_cycles_between_modules() -> None:
    """No cycle among all of simlan_data's modules (imports under `if TYPE_CHECKING:` excepted)."""
    import grimp

    graph = grimp.build_graph("simlan_data", exclude_type_checking_imports=True, cache_dir=None)
    edges = {m: set(graph.find_modules_directly_imported_by(m)) for m in graph.modules}
    cycles = _strongly_connected(edges)
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_top_level_holds_only_the_shared_leaves_and_the_entry_names() -> None:
    modules = {p.stem for p in PACKAGE.glob("*.py")}
    assert modules == TOP_LEVEL_MODULES, (
        f"unexpected: {sorted(modules - TOP_LEVEL_MODULES)}; missing: {sorted(TOP_LEVEL_MODULES - modules)}"
    )


def test_no_top_level_name_shadows_the_standard_library() -> None:
    names = {p.stem for p in PACKAGE.glob("*.py")} | {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    shadowing = sorted(n for n in names if n in sys.stdlib_module_names)
    assert not shadowing, f"named like standard-library modules: {shadowing}"


@pytest.mark.parametrize("name", _subpackages())
def test_subpackage_all_resolves(name: str) -> None:
    """Every subpackage declares ``__all__``; each name resolves and is not a submodule's name."""
    package = importlib.import_module(name)
    assert "__all__" in vars(package), f"{name}/__init__.py has no __all__"
    exported = list(package.__all__)
    assert exported, f"{name}.__all__ is empty"
    assert len(exported) == len(set(exported)), f"{name}.__all__ repeats a name"
    submodules = {i.name for i in pkgutil.iter_modules(package.__path__)}
    clashes = sorted(set(exported) & submodules)
    assert not clashes, (
        f"{name}.__all__ names submodules (what they resolve to depends on import order): {clashes}"
    )
    missing = [n for n in exported if not hasattr(package, n)]
    assert not missing, f"{name}.__all__ names what does not resolve: {missing}"


@pytest.mark.parametrize("name", ["simlan_data.algorithms", "simlan_data.world"])
def test_importing_a_subpackage_loads_nothing_heavy(name: str) -> None:
    """`import simlan_data.algorithms` (or world) loads no pybullet or torch: the re-exports are lazy."""
    code = (
        f"import sys, {name}; "
        "heavy = sorted({'pybullet', 'torch'} & set(sys.modules)); "
        "assert not heavy, heavy"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert proc.returncode == 0, proc.stderr
