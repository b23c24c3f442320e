"""Adding a model or a solver is one file plus one registry entry: nothing else names them."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
from conftest import REPO, assert_close, parse_lines

from nlp_calib.cli.parser import build_parser
from nlp_calib.models import MODELS, param_names
from nlp_calib.models.clock import LAG_PARAM
from nlp_calib.models.tricycle import Tricycle
from nlp_calib.outputs.handoff import calibration_dict
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.simulation import SimulationOptions, simulate
from nlp_calib.solvers import SOLVERS, GaussNewton, solver_label


def _model_words() -> set[str]:
    words: set[str] = set()
    for m in MODELS.values():
        words |= {m.name, *m.log_names, *m.kinematic_params, *m.encoder_kinds, *m.input_names}
        words |= set(m.header_names.values())
    # result.json's "baseline" is the uncalibrated guess, not the differential drive's parameter.
    return words - {"baseline"}


def test_no_module_outside_the_models_names_a_model_or_its_parameters() -> None:
    words = _model_words()
    found = []
    for path in sorted((REPO / "nlp_calib").rglob("*.py")):
        if "models" in path.relative_to(REPO).parts:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                tokens = set(node.value.replace("'", " ").replace('"', " ").replace("`", " ").split())
                if tokens & words:
                    found.append((path.name, node.lineno, sorted(tokens & words)))
    assert found == []


def _scenario(model: str, log: Path | str, **raw: object) -> dict[str, object]:
    return {"name": f"reg-{model}", "dataset": str(log), "model": model, "residual": {"horizon": 5}, **raw}


def test_a_model_registered_under_a_new_name_works_end_to_end(monkeypatch: pytest.MonkeyPatch) -> None:
    """A new model class plus its registry entry: simulated, read, calibrated, no other change."""

    class Trike(Tricycle):
        name = "trike"
        log_names = ("trike",)

    monkeypatch.setitem(MODELS, "trike", Trike())
    sim = simulate(SimulationOptions.of(model="trike", records=500, seed=5))
    lines = (
        sim.text().replace("#kinematic_model: traction_drive_wheel", "#kinematic_model: trike").splitlines()
    )
    log = parse_lines(lines, model="trike")
    sc = scenario_from_mapping(
        _scenario("trike", "sim.txt", solvers=["gauss_newton"]), "trike.yaml", Path(".")
    )
    run = Calibration(sc, log=log).run()
    res = run.reports["gauss_newton"].result
    assert res.converged
    assert_close(res.params[1], sim.options.truth["k_traction"], rtol=5e-3)


class _CopyOfGaussNewton(GaussNewton):
    name: ClassVar[str] = "gn_copy"
    label: ClassVar[str] = "Gauss-Newton (copy)"


def test_a_registered_solver_reaches_the_command_line_scenarios_and_labels(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(SOLVERS, "gn_copy", _CopyOfGaussNewton)
    run_parser = build_parser()._subparsers._group_actions[0].choices["run"]  # type: ignore[union-attr]
    solver_option = next(a for a in run_parser._actions if a.dest == "solver")
    assert "gn_copy" in solver_option.choices
    assert solver_label("gn_copy") == "Gauss-Newton (copy)"
    raw = _scenario(
        "tricycle",
        REPO / "scenarios" / "data" / "demo_tricycle.txt",
        solvers=["gauss_newton", "gn_copy"],
        samples={"stop": 600},
        gn_copy={"max_iterations": 50},
    )
    sc = scenario_from_mapping(raw, "gn_copy.yaml", Path("."))
    assert sc.options_for("gn_copy").max_iterations == 50
    run = Calibration(sc).run()
    a, b = run.reports["gauss_newton"].result, run.reports["gn_copy"].result
    assert b.converged and b.solver == "gn_copy"  # the same code, reported under its registry name
    assert_close(b.params, a.params, rtol=1e-12)


@pytest.mark.parametrize("model", sorted(MODELS))
def test_calibration_yaml_gives_the_unit_of_every_parameter(model: str) -> None:
    sim = simulate(SimulationOptions.of(model=model, records=400, seed=6))
    log = parse_lines(sim.text().splitlines(), model=model)
    sc = scenario_from_mapping(_scenario(model, "sim.txt", solvers=["gauss_newton"]), "u.yaml", Path("."))
    doc = calibration_dict(Calibration(sc, log=log).run())
    assert doc is not None
    units = doc["units"]
    assert list(units) == [*param_names(MODELS[model]), LAG_PARAM]  # the time offset fitted by default
    assert units[LAG_PARAM] == "s"
    assert all(isinstance(u, str) and u for u in units.values())


def test_every_model_declares_all_its_facts() -> None:
    """The facts the rest of the package reads from a model, present and consistent."""
    for model in MODELS.values():
        names = param_names(model)
        assert set(model.units) == set(model.kinematic_params)
        assert set(model.header_names) == set(model.kinematic_params)
        assert {model.header_aliases[h.lower()] for h in model.header_names.values()} == set(
            model.kinematic_params
        )
        assert set(model.reference) <= set(model.kinematic_params)
        assert set(model.headline) <= set(model.kinematic_params)
        assert set(model.physical_ranges) == set(names)
        assert set(model.drive.default_truth) == set(names) == set(model.drive.default_guess)
        assert set(model.drive.default_ranges) == set(model.encoder_kinds)
        assert all(np.isfinite(list(model.drive.default_truth.values())))
        assert dataclasses.is_dataclass(SimulationOptions)
