"""A command loads what it uses: the packages' re-exports are imported at their first use."""

from __future__ import annotations

import argparse
import ast
import gc
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO

from nlp_calib.cli.parser import build_parser, named_command
from nlp_calib.core import collector

#: The packages whose ``__init__`` re-exports through :func:`nlp_calib.core.lazy.exports`.
LAZY = (
    "nlp_calib",
    "nlp_calib.fleet",
    "nlp_calib.logs",
    "nlp_calib.pipeline",
    "nlp_calib.problem",
    "nlp_calib.results",
)


def _loaded_after(code: str) -> set[str]:
    """The modules a fresh interpreter holds after running ``code``."""
    script = f"import json, sys\n{code}\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, cwd=REPO)
    return set(json.loads(out.stdout.splitlines()[-1]))


def test_the_parser_loads_no_pipeline_stage_nor_matplotlib() -> None:
    """``--help`` and every command's parsing: the grammar, not the calibration."""
    loaded = _loaded_after("from nlp_calib.cli.parser import build_parser\nbuild_parser()")
    assert "nlp_calib.cli.parser" in loaded
    heavy = {"nlp_calib.pipeline.analyse", "nlp_calib.pipeline.calibration", "nlp_calib.fleet.pool"}
    assert loaded & heavy == set()
    assert not any(m == "matplotlib" or m.startswith("matplotlib.") for m in loaded)


def test_a_package_import_loads_none_of_its_re_exports() -> None:
    loaded = _loaded_after("import nlp_calib.pipeline, nlp_calib.logs, nlp_calib.results, nlp_calib.fleet")
    inside = {m for m in loaded if m.count(".") > 1 and not m.startswith("nlp_calib.core.")}
    assert {m for m in inside if m.startswith("nlp_calib.")} == set()


def _type_checking_names(package: str) -> dict[str, str]:
    """Each name the package's ``if TYPE_CHECKING:`` block imports, with its module."""
    source = importlib.util.find_spec(package).origin  # type: ignore[union-attr]
    with open(source, encoding="utf-8") as file:
        tree = ast.parse(file.read())
    block = next(n for n in tree.body if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.unparse(n.test))
    return {
        alias.asname or alias.name: node.module
        for node in ast.walk(block)
        if isinstance(node, ast.ImportFrom) and node.module
        for alias in node.names
    }


@pytest.mark.parametrize("package", LAZY)
def test_a_lazy_package_exports_what_its_modules_define(package: str) -> None:
    """The table names the statically imported names (what mypy and the layer contracts read), each
    resolves to its module's object, and none is also a module of the package (whose import would
    set the package's attribute to the module)."""
    module = importlib.import_module(package)
    table = module._EXPORTS
    assert table == _type_checking_names(package)
    assert set(module.__all__) - {"__version__"} == set(table)
    for name, source in table.items():
        assert getattr(module, name) is getattr(importlib.import_module(source), name), name
        assert importlib.util.find_spec(f"{package}.{name}") is None, name
    with pytest.raises(AttributeError, match="no attribute 'not_exported'"):
        module.not_exported  # noqa: B018
    assert set(table) <= set(dir(module))


def _simulator(loaded: set[str]) -> set[str]:
    """The modules of ``loaded`` that only simulating or drafting a scenario needs."""
    return {m for m in loaded if m.startswith(("nlp_calib.simulation", "nlp_calib.pipeline.simconfig"))} | (
        loaded & {"nlp_calib.pipeline.draft"}
    )


def test_a_compare_loads_no_simulator(tmp_path: Path) -> None:
    """``compare`` of the demo (a simulated log, its truth beside it: the run reads the truth) from
    the command line's entry: nothing of the simulator, nor the scenario drafter, is loaded."""
    out = tmp_path / "out"
    argv = ["compare", str(REPO / "scenarios" / "demo.yaml"), "--out", str(out)]
    loaded = _loaded_after(f"from nlp_calib.cli.main import main\nmain({argv!r})")
    assert "nlp_calib.pipeline.truth" in loaded and (out / "result.json").is_file()
    assert _simulator(loaded) == set()


def test_simulate_parses_with_its_whole_grammar() -> None:
    """The grammar built for one command is the whole one's for that command; ``simulate``'s is
    built with it (and loads the simulator), for any other command only its help line."""
    loaded = _loaded_after("from nlp_calib.cli.parser import build_parser\nbuild_parser('simulate')")
    assert {"nlp_calib.simulation", "nlp_calib.pipeline.simconfig"} <= _simulator(loaded)

    def commands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
        return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices

    whole = commands(build_parser())
    for name in ("simulate", "compare"):
        alone = commands(build_parser(named_command(["--debug", name, "x"])))
        assert list(alone) == list(whole)
        assert alone[name].format_help() == whole[name].format_help()
    assert commands(build_parser("compare"))["simulate"]._actions[1:] == []
    assert build_parser("compare").format_help() == build_parser().format_help()
    argv = ["simulate", "--out", "x.txt", "--trajectory", "straight", "--records", "500"]
    assert vars(build_parser(named_command(argv)).parse_args(argv)) == vars(build_parser().parse_args(argv))


#: A fresh interpreter runs the command as ``nlp-calib`` does, with ``validate``'s module replaced
#: by ``probe`` (written beside it): what the collector did while the module loaded and after.
_PROBE = """import gc, json, sys
from nlp_calib import __main__ as entry
from nlp_calib.cli import commands
commands.COMMANDS["validate"] = commands._on_demand("probe", "cmd")
sys.argv = ["nlp-calib", *sys.argv[1:]]
try:
    code = entry.run()
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "after": gc.isenabled()}))
"""
_MODULE = """import gc, json
LOADING = gc.isenabled()
def cmd(args):
    print(json.dumps({"loading": LOADING, "running": gc.isenabled(), "frozen": gc.get_freeze_count()}))
    return 0
"""


def _probed(tmp_path: Path, *argv: str) -> list[dict[str, object]]:
    (tmp_path / "probe.py").write_text(_MODULE)
    (tmp_path / "probe_run.py").write_text(_PROBE)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(tmp_path)])}
    out = subprocess.run(
        [sys.executable, str(tmp_path / "probe_run.py"), *argv],
        capture_output=True,
        text=True,
        env=env,
        cwd=REPO,
    )
    return [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]


def test_a_command_loads_its_modules_with_the_collector_paused(tmp_path: Path) -> None:
    """Loading makes objects that live as long as the process: no collector passes while the
    command's module loads; it runs with the collector on, what loading made frozen out of it."""
    command, end = _probed(tmp_path, "validate", "scenarios/demo.yaml")
    assert command["loading"] is False
    assert command["running"] is True
    assert isinstance(command["frozen"], int) and command["frozen"] > 10_000  # numpy, CasADi, the parser
    assert end == {"code": 0, "after": True}


def test_a_command_that_loads_no_module_gives_the_collector_back(tmp_path: Path) -> None:
    """``--help`` (argparse exits) never reaches a command's module: the collector is on again."""
    (end,) = _probed(tmp_path, "--help")
    assert end == {"code": 0, "after": True}


def test_a_command_called_in_a_process_leaves_its_collector_alone() -> None:
    """A program or test calling a command in its own process: nothing paused, nothing frozen."""
    frozen = gc.get_freeze_count()
    collector.resume()
    assert gc.isenabled() and gc.get_freeze_count() == frozen
    gc.disable()
    try:
        collector.pause()  # the program's own choice stands
        collector.resume()
        assert not gc.isenabled() and gc.get_freeze_count() == frozen
    finally:
        gc.enable()


def test_the_compiled_backend_loads_no_process_machinery() -> None:
    """A command whose compiled code is cached starts no compiler: ``subprocess`` (and what it
    loads) comes in only with the first compile."""
    loaded = _loaded_after("import nlp_calib.solvers.backends.compiled")
    assert "nlp_calib.codegen.compiler" in loaded
    assert "subprocess" not in loaded
