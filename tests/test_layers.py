"""The packages' layers import downward only (docs/design.md, "Layers"): config -> the parts (envs,
policies, seeding, metrics, statistics, demonstrations) -> the task specs -> core -> the file rater ->
the adapters -> run (and the rating page) -> sweeps -> cli, and above the library the lab, which
nothing in the library imports; no import circle among the modules; reading a config costs no
training stack, and training loads neither the lab nor the statistics' SciPy."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
FOLDERS = {
    "dospcot": ROOT / "dospcot",
    "dospcot.envs": ROOT / "envs",
    "dospcot.policies": ROOT / "policies",
    "dospcot_lab": ROOT / "lab",
}
"""Where each installed package's files lie (pyproject.toml's package-dir)."""
LAYERS: tuple[tuple[str, ...], ...] = (
    ("dospcot.config", "dospcot"),
    (
        "dospcot.envs",
        "dospcot.policies",
        "dospcot.seeding",
        "dospcot.metrics",
        "dospcot.statistics",
        "dospcot.demonstrations",
    ),
    ("dospcot.tasks",),
    ("dospcot.core",),
    ("dospcot.raters",),
    ("dospcot.adapters",),
    ("dospcot.run", "dospcot.rating"),
    ("dospcot.sweeps",),
    ("dospcot.cli", "dospcot.__main__"),
    ("dospcot_lab",),
)
"""Each layer's modules by prefix, bottom first; a module belongs to the longest prefix it starts with."""


def _modules() -> dict[str, Path]:
    found = {}
    for package, folder in FOLDERS.items():
        for path in folder.rglob("*.py"):
            parts = path.relative_to(folder).with_suffix("").parts
            name = ".".join((package, *(parts[:-1] if parts[-1] == "__init__" else parts)))
            if package == "dospcot" and parts[0] in ("envs", "policies", "lab"):
                continue  # never a folder of dospcot/: they install from the top level
            found[name] = path
    return found


MODULES = _modules()


def _owner(name: str) -> str | None:
    """The module a dotted import name lands in (a package's ``__init__`` for a name it defines)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def imports_of(name: str) -> set[str]:
    """Every dospcot module ``name`` imports, at the top, inside a function or for type checking."""
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        targets = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, *([node.module] if node.module else [])])
            targets = [
                f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base for alias in node.names
            ]
        found |= {
            owner for t in targets if t.startswith("dospcot") and (owner := _owner(t)) not in (None, name)
        }
    return found


def layer_of(name: str) -> int:
    matches = [
        (len(prefix), rank)
        for rank, layer in enumerate(LAYERS)
        for prefix in layer
        if name == prefix or name.startswith(prefix + ".")
    ]
    assert matches, f"{name} belongs to no layer: add it to LAYERS and docs/design.md"
    return max(matches)[1]


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = [stack.pop()]
            while component[-1] != v:
                component.append(stack.pop())
            if len(component) > 1:
                circles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return circles


def test_the_checks_find_a_circle_and_an_upward_import():
    assert import_circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_circles({"a": {"b"}, "b": set()}) == []
    assert (
        layer_of("dospcot.config.loading")
        < layer_of("dospcot.core.self_paced")
        < layer_of("dospcot.sweeps.sweep")
    )
    assert layer_of("dospcot.tasks.grid") < layer_of("dospcot.core.sb3_round") < layer_of("dospcot.adapters")
    assert "dospcot.tasks.registry" in imports_of("dospcot.tasks.loading")
    assert "dospcot.sweeps.sweep_spec" in imports_of("dospcot.sweeps.sweep")
    assert layer_of("dospcot.cli.commands") < layer_of("dospcot_lab.studies")


def test_no_import_circle_among_the_modules():
    graph = {name: imports_of(name) for name in MODULES}
    assert import_circles(graph) == []


def test_every_import_runs_down_the_layers():
    upward = [
        f"{name} -> {target}"
        for name in sorted(MODULES)
        for target in sorted(imports_of(name))
        if layer_of(target) > layer_of(name)
    ]
    assert upward == []


@pytest.mark.parametrize(
    "preset", ["grid16-dospcot", "minigrid-lavagap-dospcot", "fasthighway-dospcot", "paper-text", "tiny"]
)
def test_reading_a_config_imports_no_training_stack(preset):
    script = (
        "import json, sys\n"
        "from dospcot.tasks import load_config\n"
        f"assert load_config({preset!r}).name\n"
        "print(json.dumps(sorted(m for m in ('torch', 'stable_baselines3', 'scipy') if m in sys.modules)))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == []


def test_no_library_module_imports_the_lab():
    library = [name for name in MODULES if not name.startswith("dospcot_lab")]
    assert [name for name in library if any(t.startswith("dospcot_lab") for t in imports_of(name))] == []


def test_training_loads_neither_the_lab_nor_the_statistics(tmp_path):
    script = (
        "import json, sys\n"
        "from dospcot.cli import main\n"
        f"status = main(['train', 'tiny', '--set', 'training.rounds=1', '--runs-dir', {str(tmp_path)!r},"
        " '--no-progress'])\n"
        "loaded = sorted(m for m in sys.modules if m.split('.')[0] in ('dospcot_lab', 'scipy'))\n"
        "print(json.dumps([status, loaded]))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout.splitlines()[-1]) == [0, []]


def test_the_training_stack_loads_matplotlib_only_to_write_the_plot():
    """A run imports matplotlib as it writes its plot, at its end, so its peak memory is its fits'."""
    script = (
        "import sys\n"
        "import dospcot.cli.commands, dospcot.run.run_session, dospcot.run.sb3_runs, dospcot.run.train\n"
        "print('matplotlib' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False"]
