"""The package's architecture: layers read one way, no import cycles, and the house rules on imports."""

from __future__ import annotations

import ast
import functools
import sys
from collections.abc import Iterator
from pathlib import Path

import grimp
import numpy as np
import pytest
from conftest import REPO
from importlinter import configuration
from importlinter.application.use_cases import lint_imports

PACKAGE = REPO / "nlp_calib"


@pytest.fixture(scope="module")
def graph() -> grimp.ImportGraph:
    return grimp.build_graph("nlp_calib", cache_dir=None)


@functools.cache
def _parsed() -> tuple[tuple[str, Path, ast.Module], ...]:
    """Every module of the package parsed once per test process (the trees are only read)."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(REPO).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        out.append((name, path, ast.parse(path.read_text(encoding="utf-8"))))
    return tuple(out)


def _modules() -> Iterator[tuple[str, Path, ast.Module]]:
    yield from _parsed()


def _strongly_connected(nodes: set[str], edges: dict[str, set[str]]) -> list[set[str]]:
    """Tarjan's components of the directed graph (iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    components = []
    for root in sorted(nodes):
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, ()))))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    comp = set()
                    while True:
                        top = stack.pop()
                        on_stack.discard(top)
                        comp.add(top)
                        if top == node:
                            break
                    components.append(comp)
            elif child not in index:
                index[child] = low[child] = len(index)
                stack.append(child)
                on_stack.add(child)
                work.append((child, iter(sorted(edges.get(child, ())))))
            elif child in on_stack:
                low[node] = min(low[node], index[child])
    return components


def test_import_linter_contracts_are_kept() -> None:
    """The layers contract and the acyclic-siblings contract of pyproject.toml."""
    configuration.configure()
    assert lint_imports(config_filename=str(REPO / "pyproject.toml"), cache_dir=None, no_logo=True)


def test_no_import_cycle_between_files(graph: grimp.ImportGraph) -> None:
    modules = set(graph.modules)
    edges = {m: set(graph.find_modules_directly_imported_by(m)) & modules for m in modules}
    cycles = [c for c in _strongly_connected(modules, edges) if len(c) > 1]
    assert cycles == []


def test_no_import_cycle_between_packages(graph: grimp.ImportGraph) -> None:
    def package(m: str) -> str:
        return m if graph.find_children(m) else m.rpartition(".")[0]

    packages = {package(m) for m in graph.modules}
    edges: dict[str, set[str]] = {p: set() for p in packages}
    for m in graph.modules:
        for imported in graph.find_modules_directly_imported_by(m):
            a, b = package(m), package(imported)
            # A package may import its own children (re-exports); that is not a loop between packages.
            if a != b and not b.startswith(a + ".") and not a.startswith(b + "."):
                edges[a].add(b)
    cycles = [c for c in _strongly_connected(packages, edges) if len(c) > 1]
    assert cycles == []


def test_no_module_imports_the_package_root(graph: grimp.ImportGraph) -> None:
    """The root re-exports the public API; a module importing it would import every layer."""
    assert graph.find_modules_that_directly_import("nlp_calib") == set()


def test_matplotlib_is_imported_only_by_the_plotting_package() -> None:
    users = set()
    for name, _, tree in _modules():
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            if any(n.split(".")[0] == "matplotlib" for n in names):
                users.add(name)
    assert users and all(u.startswith("nlp_calib.outputs.plots") for u in users), users


#: The run-time dependencies' import names (pyproject.toml's ``dependencies``: pyyaml is ``yaml``).
RUNTIME = {"casadi", "numpy", "matplotlib", "yaml"}
#: What the run-time dependencies install themselves (matplotlib writes its PNGs with Pillow).
WITH_RUNTIME = {"PIL"}


def _top_level_imports(tree: ast.Module) -> Iterator[str]:
    """The modules a file imports when it is imported (not inside a function, nor for type checking
    alone)."""
    for node in tree.body:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            continue
        for sub in ast.walk(node):
            if isinstance(sub, (ast.FunctionDef, ast.AsyncFunctionDef)):
                break
            if isinstance(sub, ast.Import):
                yield from (a.name for a in sub.names)
            elif isinstance(sub, ast.ImportFrom) and sub.module and sub.level == 0:
                yield sub.module


def test_the_package_imports_only_its_run_time_dependencies() -> None:
    """What a fresh install (the README's first command) has: the standard library, the package and
    its run-time dependencies; an extra (rosbags, small_gicp, dask) or a test-only library (scipy)
    only inside the function that needs it."""
    text = (REPO / "pyproject.toml").read_text()
    block = text.split("\ndependencies = [", 1)[1].split("]", 1)[0]
    declared = {
        line.strip().strip('",').split(">")[0].split("=")[0] for line in block.splitlines() if line.strip()
    }
    assert {d.replace("pyyaml", "yaml") for d in declared} == RUNTIME
    outside = {
        (name, top)
        for name, _, tree in _modules()
        for top in {m.split(".")[0] for m in _top_level_imports(tree)}
        if top not in sys.stdlib_module_names and top != "nlp_calib" and top not in RUNTIME | WITH_RUNTIME
    }
    assert outside == set(), sorted(outside)


def test_only_the_command_line_prints() -> None:
    printing = set()
    for name, _, tree in _modules():
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                printing.add(name)
    assert printing and all(p.startswith("nlp_calib.cli") for p in printing), printing


def test_derivatives_are_taken_only_where_the_problem_is_written() -> None:
    """Jacobians, gradients and Hessians come from the problem and symbolic layers, once (and from
    each sensor plug-in, which writes its own error term: the noise map of its measured motion)."""
    derivative = {"jacobian", "gradient", "hessian", "jtimes", "forward", "reverse"}
    takers = set()
    for name, _, tree in _modules():
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)):
                continue
            if node.value.id == "ca" and node.attr in derivative:
                takers.add(name)
    where = ("nlp_calib.problem", "nlp_calib.symbolic", "nlp_calib.sensors")
    assert takers and all(t.startswith(where) for t in takers), takers


def test_solvers_build_no_symbolic_expressions() -> None:
    """Solvers call named Functions; at most thin MX wrappers around them (no SX expressions)."""
    for name, _, tree in _modules():
        if not name.startswith("nlp_calib.solvers"):
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr == "SX":
                pytest.fail(f"{name} builds SX expressions")


#: The house rules on size: a function fits on a screen, a class holds few enough attributes to
#: be understood at once.
MAX_FUNCTION_LINES = 60
MAX_CLASS_ATTRIBUTES = 12


def _class_attributes(cls: ast.ClassDef) -> set[str]:
    """The data a class holds: annotated or assigned class attributes (not constants in capitals,
    not ``ClassVar`` registry facts) and every ``self.<name>`` its methods assign."""
    names: set[str] = set()
    for node in cls.body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            if "ClassVar" not in ast.unparse(node.annotation):
                names.add(node.target.id)
        elif isinstance(node, ast.Assign):
            names |= {t.id for t in node.targets if isinstance(t, ast.Name) and not t.id.isupper()}
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for sub in ast.walk(node):
                targets = sub.targets if isinstance(sub, ast.Assign) else []
                if isinstance(sub, (ast.AnnAssign, ast.AugAssign)):
                    targets = [sub.target]
                names |= {
                    t.attr
                    for t in targets
                    if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) and t.value.id == "self"
                }
    return {n for n in names if not n.startswith("__")}


def test_functions_fit_on_a_screen() -> None:
    long = [
        f"{name}:{node.lineno} {node.name} ({node.end_lineno - node.lineno + 1} lines)"  # type: ignore[operator]
        for name, _, tree in _modules()
        for node in ast.walk(tree)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES  # type: ignore[operator]
    ]
    assert long == [], long


def test_classes_hold_few_attributes() -> None:
    large = [
        f"{name}:{node.lineno} {node.name} ({len(attrs)}: {', '.join(sorted(attrs))})"
        for name, _, tree in _modules()
        for node in ast.walk(tree)
        if isinstance(node, ast.ClassDef) and len(attrs := _class_attributes(node)) > MAX_CLASS_ATTRIBUTES
    ]
    assert large == [], large


#: What only a 3-D mount speaks of: its parameters, its pose layout, and the choice of it.
MOUNT_3D_WORDS = {
    "sensor_roll", "sensor_pitch", "sensor_yaw", "sensor_z", "MOUNT_PARAMS", "MOUNT_ANGLES", "HELD_PARAMS",
    "SCALE_PARAM", "is_3d", "sensor_3d", "T_world_sensor_3d", "Mount3D", "CameraPose", "3d",
}  # fmt: skip
#: Where they may appear: the sensor plug-ins, the readers of 3-D poses and the camera's simulator.
MOUNT_3D_PLACES = ("nlp_calib.sensors", "nlp_calib.logs", "nlp_calib.simulation.camera")


def _words(tree: ast.Module) -> set[str]:
    """Names, attributes and string constants of a module's code (docstrings left out)."""
    docstrings = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            out.add(node.id)
        elif isinstance(node, ast.Attribute):
            out.add(node.attr)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            out |= set(node.value.replace(".", " ").replace(":", " ").split()) | {node.value}
        elif isinstance(node, ast.Compare) and "pose_rows" in ast.unparse(node):
            out.add("pose_rows comparison")
    return out


def test_the_words_of_a_3d_mount_appear_only_in_its_sensor_plug_in() -> None:
    """No module outside the sensor plug-ins (and the readers and the simulator of 3-D poses) decides
    anything by the sensor being 3-D: it asks the sensor."""
    found = {
        name: sorted(words)
        for name, _, tree in _modules()
        if not name.startswith(MOUNT_3D_PLACES)
        and (words := _words(tree) & (MOUNT_3D_WORDS | {"pose_rows comparison"}))
    }
    assert found == {}, found


def test_the_stages_ask_the_references_kind_never_whether_a_log_holds_motions() -> None:
    """Poses or own motions is the reference kind's to say (``nlp_calib/logs/reference.py``): no
    module outside the logs and the sources that fill them tests ``….motions is (not) None``."""
    found = []
    for _, path, tree in _modules():
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith(("logs/", "sources/")):
            continue
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Compare)
                and isinstance(node.left, ast.Attribute)
                and node.left.attr == "motions"
                and any(isinstance(op, (ast.Is, ast.IsNot)) for op in node.ops)
            ):
                found.append(f"{rel}:{node.lineno}")
    assert found == [], found


def test_each_source_gives_its_reference_kind() -> None:
    """A tracker's log holds poses; a motions file's, its own increments (one-interval ones set the
    horizon to 1 and cover their intervals only)."""
    from nlp_calib.logs.reference import Motions, Poses
    from nlp_calib.logs.relative import RelativeMotions

    # Two one-interval increments, then one over two intervals.
    motions = RelativeMotions(np.array([0, 1, 2]), np.array([1, 2, 4]), np.zeros((3, 3)), np.arange(3))
    kind = Motions(motions)
    assert (
        kind.horizon(1) == 2 and kind.window_count((0, 5), 1, 1) == 3 and kind.window_count((0, 4), 1, 2) == 1
    )
    assert kind.uncovered(5).tolist() == [False, False, True, True]
    assert Motions(motions.take(motions.single())).horizon(7) == 1
    assert Poses().window_count((0, 10), 3, 2) == 4 and Poses().horizon(3) is None


def test_a_references_kind_is_the_one_its_reader_names() -> None:
    """The reader that fills a reference names its kind (``ReferenceData.measures``); the kind is
    not inferred from which fields it holds, keeps through a selection of records, and a name the
    registry does not know, or own motions without any, are refused with the reason."""
    from nlp_calib.logs.log import ReferenceData
    from nlp_calib.logs.reference import Motions, Poses
    from nlp_calib.logs.relative import RelativeMotions

    motions = RelativeMotions(np.array([0, 1, 2]), np.array([1, 2, 4]), np.zeros((3, 3)), np.arange(3))
    own = ReferenceData(motions=motions, measures=Motions.name)
    assert isinstance(own.kind, Motions) and own.kind.uncovered(5).tolist() == [False, False, True, True]
    part = own.select(0, 3)
    assert isinstance(part.kind, Motions) and part.motions is not None and part.motions.n == 2
    assert isinstance(ReferenceData(poses_3d=np.zeros((4, 7))).kind, Poses)
    with pytest.raises(ValueError, match="unknown reference kind 'lidar'"):
        ReferenceData(measures="lidar")
    with pytest.raises(ValueError, match="measure its own motions holds none"):
        _ = ReferenceData(measures=Motions.name).kind
