"""The project's layers, checked on the source: every ``import`` and ``from`` statement of every
module under src/ (at any depth of the file: inside functions, under ``TYPE_CHECKING``, in ``try``
blocks), read with ``ast`` without importing anything.

From the bottom: ``tlt_common`` (shared) imports no other ``tlt_`` package; ``tlt_drivers``
imports no agent; an agent (``tlt_crs``, ``tlt_ars``, ``tlt_gsw``, ``tlt_vision``) imports no other
agent (they talk over ROS and the ground link); no runtime package imports the twin (``tlt_sim``,
which hands the drivers its backends) or the offline tools (``tlt_tools``); and no two modules
under src/ import each other, directly or round a longer loop.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
SHARED = "tlt_common"
DRIVERS = "tlt_drivers"
AGENTS = ("tlt_crs", "tlt_ars", "tlt_gsw", "tlt_vision")
RUNTIME = (SHARED, DRIVERS, *AGENTS)
ABOVE_THE_RUNTIME = ("tlt_sim", "tlt_tools")  # the twin and the offline tools


def module_name(path: Path, src: Path) -> str:
    parts = path.relative_to(src).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules(src: Path) -> dict[str, Path]:
    return {module_name(p, src): p for p in sorted(src.rglob("*.py"))}


def imports(path: Path, src: Path) -> Iterator[tuple[int, str]]:
    """(line, imported module) for every import statement in ``path``; a relative import is made
    absolute, and ``from package import name`` yields ``package.name`` too (the name may be a
    module)."""
    module = module_name(path, src)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join([*base, node.module] if node.module else base)
            else:
                target = node.module or ""
            yield node.lineno, target
            for alias in node.names:
                if alias.name != "*":
                    yield node.lineno, f"{target}.{alias.name}"


def top(name: str) -> str:
    return name.split(".", 1)[0]


def layer_violations(src: Path = SRC) -> list[str]:
    """``file:line imports module (why)`` for every import that points the wrong way."""
    out = []
    for module, path in modules(src).items():
        own = top(module)
        seen = set()
        for line, target in imports(path, src):
            to = top(target)
            if to == own or not to.startswith("tlt_") or (line, to) in seen:
                continue
            why = None
            if to in ABOVE_THE_RUNTIME:
                above = "the twin" if to == "tlt_sim" else "an offline tool"
                why = f"the runtime package {own} imports {above}"
            elif own == SHARED and to in RUNTIME:
                why = f"the shared layer imports {to}"
            elif own == DRIVERS and to in AGENTS:
                why = f"the drivers import the agent {to}"
            elif own in AGENTS and to in AGENTS:
                why = f"the agent {own} imports the agent {to}"
            if why:
                seen.add((line, to))
                out.append(f"{path.relative_to(src.parent)}:{line} imports {target} ({why})")
    return out


def import_graph(src: Path = SRC) -> dict[str, set[str]]:
    """Module -> the modules under src/ it imports (a package's ``__init__`` counts as a module)."""
    known = modules(src)
    graph: dict[str, set[str]] = {m: set() for m in known}
    for module, path in known.items():
        for _, target in imports(path, src):
            if target in known and target != module:
                graph[module].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    out.append(sorted(component))
    return out


def test_src_holds_every_runtime_package_and_nothing_above_them():
    packages = {p.name for p in SRC.iterdir() if (p / "__init__.py").exists()}
    assert packages == set(RUNTIME)


def test_every_import_points_down_the_layers():
    violations = layer_violations()
    assert not violations, "imports against the layers:\n" + "\n".join(violations)


def test_no_modules_import_each_other():
    found = cycles(import_graph())
    assert not found, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in found)


def package_graph(src: Path = SRC) -> dict[str, set[str]]:
    """Package -> the packages its modules import, between sibling packages only (neither holds
    the other): a package's own modules and its sub-packages' may use each other, as a package's
    ``__init__`` and configuration are used by its parts."""
    known = modules(src)

    def package(module: str) -> str:
        return module if known[module].name == "__init__.py" else module.rpartition(".")[0]

    graph: dict[str, set[str]] = {package(m): set() for m in known}
    for module, targets in import_graph(src).items():
        a = package(module)
        for target in targets:
            b = package(target)
            if not (a == b or a.startswith(b + ".") or b.startswith(a + ".")):
                graph[a].add(b)
    return graph


def test_no_sibling_packages_import_each_other():
    found = cycles(package_graph())
    assert not found, "package cycles:\n" + "\n".join(" <-> ".join(c) for c in found)


# The checks themselves, on made-up modules: each rule and a cycle are caught, and a clean tree passes.
@pytest.mark.parametrize(
    ("module", "source", "caught"),
    [
        ("tlt_drivers/gpio.py", "def f():\n    from tlt_sim.emulators import chip\n", "imports the twin"),
        ("tlt_vision/train.py", "import tlt_tools.vision_training\n", "imports an offline tool"),
        ("tlt_common/geo.py", "from tlt_ars.planning import kinematics\n", "shared layer imports tlt_ars"),
        ("tlt_drivers/ee.py", "from tlt_crs import context\n", "drivers import the agent tlt_crs"),
        (
            "tlt_ars/tags.py",
            "try:\n    import tlt_vision.apriltag\nexcept ImportError:\n    pass\n",
            "agent tlt_ars imports the agent tlt_vision",
        ),
    ],
)
def test_a_wrong_import_is_named_with_its_file_and_line(tmp_path, module, source, caught):
    src = tmp_path / "src"
    for package in RUNTIME:
        (src / package).mkdir(parents=True)
        (src / package / "__init__.py").write_text("")
    (src / module).write_text("import numpy\n" + source)
    violations = layer_violations(src)
    assert len(violations) == 1
    assert violations[0].startswith(f"src/{module}:") and caught in violations[0]


def test_a_cycle_between_sibling_packages_is_found_and_one_with_the_parent_is_not(tmp_path):
    pkg = tmp_path / "tlt_demo"
    for sub in ("a", "b"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "config.py").write_text("from tlt_demo.a import one\n")
    (pkg / "a" / "one.py").write_text("from tlt_demo import config\n")
    assert cycles(package_graph(tmp_path)) == []
    (pkg / "a" / "two.py").write_text("from tlt_demo.b import three\n")
    (pkg / "b" / "three.py").write_text("x = 1\n")
    assert cycles(package_graph(tmp_path)) == []
    (pkg / "b" / "four.py").write_text("from tlt_demo.a import one\n")
    assert cycles(package_graph(tmp_path)) == [["tlt_demo.a", "tlt_demo.b"]]


def test_a_cycle_is_found_also_through_relative_imports(tmp_path):
    src = tmp_path / "src"
    (src / "tlt_crs" / "behaviours").mkdir(parents=True)
    for init in ("tlt_crs/__init__.py", "tlt_crs/behaviours/__init__.py"):
        (src / init).write_text("")
    (src / "tlt_crs/context.py").write_text("def f():\n    from .behaviours.inspection import Desk\n")
    (src / "tlt_crs/behaviours/inspection.py").write_text("from ..tree import build\n")
    (src / "tlt_crs/tree.py").write_text("from tlt_crs import context\n")
    (src / "tlt_crs/node.py").write_text("from tlt_crs.tree import build\n")
    assert cycles(import_graph(src)) == [["tlt_crs.behaviours.inspection", "tlt_crs.context", "tlt_crs.tree"]]
    (src / "tlt_crs/tree.py").write_text("import numpy\n")
    assert cycles(import_graph(src)) == []
