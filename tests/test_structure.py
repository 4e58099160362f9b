"""The packages' layering: the core of ``common`` imports no simulator, plotting or learning library,
nothing imports the application from below it, and no module imports itself through others."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("common", "flatland", "physics3d")
APPLICATION = "common.curriculum"
# What the core leaves to the tiers (simulators), the application (learning, plots, clusters) and the renderers.
NOT_IN_THE_CORE = ("pymunk", "pybullet", "matplotlib", "PIL", "torch", "stable_baselines3", "tensorboard", "ray",
                   "optuna", "flatland", "physics3d", APPLICATION)


def _modules() -> dict[str, Path]:
    modules = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            modules[name.removesuffix(".__init__")] = path
    return modules


MODULES = _modules()


def _imports(name: str) -> set[str]:
    """Every module ``name`` imports, at its top, inside functions or under TYPE_CHECKING alike."""
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([node.module] if node.module else []))
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names if f"{base}.{alias.name}" in MODULES)
    return found


def _project_module(imported: str) -> str | None:
    while imported and imported not in MODULES:
        imported = imported.rpartition(".")[0]
    return imported or None


def _is_core(name: str) -> bool:
    return name.split(".")[0] == "common" and not (name == APPLICATION or name.startswith(APPLICATION + "."))


# A grid map's image is part of a world file, as YAML is: read (when a map needs it, never at
# import) with the reader IR-SIM reads it with, matplotlib's imread over Pillow, for the same cells.
READS_MAP_IMAGES = {("common.grid_maps", "PIL"), ("common.grid_maps", "matplotlib.image")}


def test_the_core_imports_no_simulator_plotting_or_learning_library():
    offending = {
        f"{name} imports {imported}"
        for name in MODULES if _is_core(name)
        for imported in _imports(name)
        if any(imported == banned or imported.startswith(banned + ".") for banned in NOT_IN_THE_CORE)
        and (name, imported) not in READS_MAP_IMAGES
    }
    assert not offending


def test_importing_the_whole_core_loads_none_of_them():
    core = sorted(name for name in MODULES if _is_core(name))
    program = f"import sys; import {', '.join(core)}; print(' '.join(sorted(sys.modules)))"
    loaded = set(subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, check=True,
                                cwd=ROOT).stdout.split())
    assert not {m for m in loaded if m.split(".")[0] in NOT_IN_THE_CORE or m.startswith(APPLICATION)}


def test_no_module_imports_itself_through_others():
    graph = {name: {m for m in map(_project_module, _imports(name)) if m and m != name} for name in MODULES}
    # Tarjan's strongly connected components: any with two or more modules is a cycle.
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in graph[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for name in graph:
        if name not in index:
            visit(name)
    assert not cycles
