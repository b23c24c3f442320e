"""The C export of a scenario's residual: which Functions, evaluated where (``nlp-calib codegen``)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from nlp_calib.codegen.export import Example, build_for_export, generate
from nlp_calib.core.errors import NlpCalibWarning, ProblemError
from nlp_calib.pipeline.build import lag_count
from nlp_calib.pipeline.calibration import Calibration
from nlp_calib.pipeline.keys import scenario_key
from nlp_calib.pipeline.prepare import read, resolved, select
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.problem import build_residual_data


def write_c_export(sc: Scenario, out_dir: Path) -> tuple[list[Path], Example]:
    """Write the residual and its Jacobian as C (H = 1 and the scenario's horizon) into ``out_dir``.

    The example program evaluates the log window with the most motion at the scenario's calibrated
    parameters (its first solver's; the initial guess if that does not converge) and compares the
    result with Python's. Returns the files and what the example evaluates.
    """
    model, log = read(sc)
    sc = resolved(sc, log)
    select(sc, log)  # the horizon must fit the log before anything is built
    residual, sensor = sc.objective.residual, sc.objective.sensor
    with scenario_key(sc, "residual"):
        problems = build_for_export(
            model, residual.horizon, residual.integration, sensor.kind, sensor.scale, lag_count(sc, 1)
        )
    last = problems[-1]
    H = last.spec.horizon
    windows = build_residual_data(last, log, sc.objective.residual)
    # The example evaluates the window with the most motion: a standing robot's Jacobian is 0. Of
    # a reference's own increments (windows of several lengths) those of the C residual's H alone.
    fits = np.flatnonzero(windows.stops - windows.starts == H)
    if not fits.size:
        raise ProblemError(f"no window of {H} intervals to evaluate example.c on")
    columns = windows.columns_of(fits)
    busiest = int(np.argmax(np.abs(columns[: last.n_inputs * H]).sum(axis=0)))
    first = int(windows.starts[fits[busiest]])
    lines = log.line_numbers[[first, first + H]]
    window = (
        f"records {first}-{first + H} ({log.where(lines[0], lines[1])}) of {sc.log.source.numbered.name}, "
        "the busiest window"
    )
    calib = Calibration(sc, log)
    solver = sc.solvers[0]
    result = calib.solve(solver)
    if result.converged:
        values, params_from = result.param_dict(), f"calibrated by {solver}"
    else:
        warnings.warn(
            f"{solver} did not converge ({result.reason}): example.c evaluates the initial guess",
            NlpCalibWarning,
            stacklevel=2,
        )
        values, params_from = dict(calib.initial), "the initial guess"
    params = np.array([values[n] for n in last.names])
    origin = f"scenario {sc.name} (model {sc.model}, horizon {H}, {sc.objective.residual.integration})"
    example = Example(params, params_from, columns[:, busiest], window)
    return generate(problems, out_dir, example, origin), example
