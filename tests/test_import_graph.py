"""The layout's rules, read from the source with `ast` (every import, also those inside
functions): no import cycle between files; no upward import (ibrnav -> robot -> explore ->
localization -> ibr: a package imports only itself and the packages to its right); the
library packages import no argparse; only `viz.py` modules and `ibrnav` import rerun; and no
module imports another module's `_private` name."""

from __future__ import annotations

import ast
from graphlib import CycleError, TopologicalSorter
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ORDER = ("ibrnav", "robot", "explore", "localization", "ibr")  # each may import those to its right
LIBRARY = ORDER[1:]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for pkg in ORDER for p in sorted((REPO / pkg).rglob("*.py"))}


def _imports(path: Path) -> list[tuple[str, list[str]]]:
    """(module, names imported from it) of every import statement in the file."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.module, [a.name for a in node.names]))
    return out


def _targets(module: str, names: list[str]) -> list[str]:
    """The project files an import loads: `from pkg import sub` names the module `pkg.sub`."""
    found = [f"{module}.{n}" for n in names if f"{module}.{n}" in MODULES]
    if module in MODULES and (not found or len(found) < len(names)):
        found.append(module)
    return found


def _graph() -> dict[str, set[str]]:
    """module -> the project modules it imports."""
    return {name: {t for module, names in _imports(path) for t in _targets(module, names) if t != name}
            for name, path in MODULES.items()}


def test_the_modules_were_found():
    assert {"ibr.camera", "ibrnav.cli", "robot.mission.mission", "explore.vueplan.phase1",
            "explore.scenic.planner", "localization.particle_filter"} <= set(MODULES)


def test_no_import_cycle_between_files():
    try:
        TopologicalSorter(_graph()).prepare()
    except CycleError as e:
        pytest.fail(f"import cycle: {' -> '.join(e.args[1])}")


def test_no_upward_import():
    bad = [(a, b) for a, targets in _graph().items() for b in targets
           if ORDER.index(b.split(".")[0]) < ORDER.index(a.split(".")[0])]
    assert not bad, bad


@pytest.mark.parametrize("banned", ["argparse"])
def test_library_packages_import_no_argparse(banned):
    bad = [name for name, path in MODULES.items() if name.split(".")[0] in LIBRARY
           and any(m.split(".")[0] == banned for m, _ in _imports(path))]
    assert not bad, bad


def test_only_viz_modules_and_ibrnav_import_rerun():
    bad = [name for name, path in MODULES.items()
           if name.split(".")[0] != "ibrnav" and not name.endswith(".viz")
           and any(m.split(".")[0] == "rerun" for m, _ in _imports(path))]
    assert not bad, bad


def test_no_module_imports_a_private_name_of_another():
    bad = [(name, m, n) for name, path in MODULES.items() for m, names in _imports(path)
           if m.split(".")[0] in ORDER for n in names if n.startswith("_")]
    assert not bad, bad


def test_every_subpackage_states_its_public_names():
    for init in REPO.glob("*/*/__init__.py"):
        if init.parts[-3] in ORDER:
            tree = ast.parse(init.read_text())
            assert any(isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in n.targets)
                       for n in tree.body), init
