"""The fit stage: each solver on one evaluator bound to the fitted windows.

The windows are one log's, or several logs' laid end to end; the evaluator is bound once and every
solver, the uncertainty and the analyses evaluate it. Results are given in the model's canonical
form (the same cost: an exact symmetry of the model).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from nlp_calib.core import interrupts
from nlp_calib.pipeline.build import Problem, evaluated
from nlp_calib.pipeline.keys import refuse_rejected_options, scenario_key
from nlp_calib.problem import ProblemFunctions, ResidualData
from nlp_calib.results import SolverResult
from nlp_calib.solvers import Solver, get_solver


class Fit:
    """The fitted windows ``data`` of ``problem`` bound to one evaluator, ready for any solver."""

    def __init__(self, problem: Problem, data: ResidualData, solvers: Sequence[str]) -> None:
        self.problem = problem
        self.data = data
        self.evaluator = problem.binder.evaluate(data)
        self.evaluator.prepare(evaluated(problem.binder.scenario, solvers))
        self._solvers: dict[str, Solver] = {}

    @property
    def fns(self) -> ProblemFunctions:
        return self.problem.fns

    def solver(self, name: str) -> Solver:
        """The solver ``name`` set up on this fit's evaluator (once)."""
        sc = self.problem.binder.scenario
        if name not in self._solvers:
            with scenario_key(sc, name):
                self._solvers[name] = get_solver(name)(self.evaluator, sc.options_for(name))
        return self._solvers[name]

    def solve(self, name: str) -> SolverResult:
        """Run one solver from the starting point; the result is in the model's canonical form."""
        start = self.problem.start
        result = self.solver(name).solve(start.x0, start.lower, start.upper)
        interrupts.check()  # IPOPT catches the signal that stops it and returns as if it had failed
        refuse_rejected_options(self.problem.binder.scenario, result)
        return self.canonical(dataclasses.replace(result, solver=name))

    def canonical(self, result: SolverResult) -> SolverResult:
        """``result`` mapped onto the model's canonical form (same cost: an exact symmetry)."""
        params = self.canonical_params(result.params)
        if np.array_equal(params, result.params):
            return result
        x = params[[self.fns.names.index(n) for n in self.fns.free]]
        return dataclasses.replace(result, params=params, x=x)

    def canonical_params(self, params: np.ndarray) -> np.ndarray:
        """The full parameter vector ``params`` in the canonical form (the sensor's: a planar mount
        by the model's symmetries, a 3-D one's angles wrapped)."""
        fns = self.fns
        named = dict(zip(fns.names, map(float, params)))
        # A mount per log: each log's view turned round by the same symmetry (the wheels decide it).
        views = [
            fns.sensor.canonical(fns.model, fns.view_dict(named, i), fns.mount_view(fns.fixed, i))
            for i in range(fns.spec.mounts)
        ]
        canon = fns.full_dict(views)
        return np.array([canon[n] for n in fns.names])
