"""The C export of a scenario's residual: which Functions, evaluated where (``nlp-calib codegen``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlp_calib.codegen.export import build_for_export, generate
from nlp_calib.pipeline import steps
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.problem import build_residual_data


def write_c_export(sc: Scenario, out_dir: Path) -> list[Path]:
    """Write the residual and its Jacobian as C (H = 1 and the scenario's horizon) into ``out_dir``.

    The example program evaluates the log window with the most motion at the initial guess.
    """
    model, log = steps.load(sc)
    steps.select(sc, log)  # the horizon must fit the log before anything is built
    initial = steps.initial_parameters(sc, model, log)
    with steps.scenario_key(sc, "residual"):
        problems = build_for_export(model, sc.residual.horizon, sc.residual.integration)
    last = problems[-1]
    H = last.spec.horizon
    windows = build_residual_data(last, log, sc.residual)
    # The example evaluates the window with the most motion: a standing robot's Jacobian is 0.
    busiest = int(np.argmax(np.abs(windows.columns[: last.n_inputs * H]).sum(axis=0)))
    params = np.array([initial.get(n, 0.0) for n in last.names])
    origin = f"scenario {sc.name} (model {sc.model}, horizon {H}, {sc.residual.integration})"
    return generate(problems, out_dir, params, windows.columns[:, busiest], origin)
