"""The fit stage: each solver on one evaluator bound to the fitted windows.

The windows are one log's, or several logs' laid end to end; the evaluator is bound once and every
solver, the uncertainty and the analyses evaluate it. Results are given in the model's canonical
form (the same cost: an exact symmetry of the model).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from nlp_calib.analysis.inputs_bias import BiasStep, bias_step
from nlp_calib.core import interrupts
from nlp_calib.pipeline.build import Problem, evaluated
from nlp_calib.pipeline.keys import refuse_rejected_options, scenario_key
from nlp_calib.problem import ProblemFunctions, ResidualData
from nlp_calib.results import SolverResult
from nlp_calib.solvers import Solver, get_solver


class Fit:
    """The fitted windows ``data`` of ``problem`` bound to one evaluator, ready for any solver;
    ``noise``, the inputs' 1σ and which are counters (see :func:`bias_step`), when each estimate
    is to be freed of the bias the inputs' noise gives it; ``given_lag``, where every log's tracker
    lag is given as a number (no parameter of the problem), the windows' interval inputs with each
    log's encoders read ``d`` s later than at it (``given_lag(d)``); ``speeds_read``, where a log's
    joints were integrated from speeds, the windows' inputs with each speed read as held over the
    interval after its stamp (``speeds_read(1)``) or the mean over the one before (``(-1)``);
    ``steering_read``, where the model reads a steer angle, the windows' inputs with each
    interval's steer angle read as the given ``steering_sample`` (``steering_read("travel")``);
    ``kinked_read``, where encoder readings were re-sampled between records, the windows' inputs
    with each such reading less its interpolation's expected error (``kinked_read()``)."""

    def __init__(
        self,
        problem: Problem,
        data: ResidualData,
        solvers: Sequence[str],
        noise: tuple[np.ndarray, np.ndarray] | None = None,
        given_lag: Callable[[float], np.ndarray] | None = None,
        speeds_read: Callable[[float], np.ndarray] | None = None,
        steering_read: Callable[[str], np.ndarray] | None = None,
        kinked_read: Callable[[], np.ndarray] | None = None,
    ) -> None:
        self.problem = problem
        self.data = data
        self.noise = noise
        self.given_lag = given_lag
        self.speeds_read = speeds_read
        self.steering_read = steering_read
        self.kinked_read = kinked_read
        self._bias: list[BiasStep] = []
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

    def solve(self, name: str, from_estimate: bool = False) -> SolverResult:
        """Run one solver from the starting point; the result is in the model's canonical form.
        ``from_estimate``: the start is an estimate that took the bias step (a stored calibration
        checked again), so the solver starts where that step began (:meth:`before_step`)."""
        start = self.problem.start
        x0 = self.before_step(start.x0) if from_estimate else start.x0
        result = self.solver(name).solve(x0, start.lower, start.upper)
        interrupts.check()  # IPOPT catches the signal that stops it and returns as if it had failed
        refuse_rejected_options(self.problem.binder.scenario, result)
        result = dataclasses.replace(result, solver=name)
        moved = self.unbiased(result)
        return self.canonical(result) if moved is result else moved

    def unbiased(self, result: SolverResult) -> SolverResult:
        """A converged ``result`` moved by the step that removes the inputs' noise bias, within
        the bounds (errors in variables: :mod:`nlp_calib.analysis.inputs_bias`), in the canonical
        form; ``result`` itself where no step is taken."""
        if self.noise is None or not result.converged:
            return result
        ev, start = self.evaluator, self.problem.start
        # Both solvers at one optimum: one step (it costs a pass over the windows per parameter).
        known = [b for b in self._bias if b.holds_at(result.x)]
        if not known:
            known = [bias_step(ev, result.x, self.noise)]
            self._bias.append(known[0])
        if not np.any(known[0].step):
            return result
        x = ev.boxplus(result.x, known[0].step)
        if start.lower is not None and start.upper is not None:
            x = np.clip(x, start.lower, start.upper)
        moved = self.canonical(dataclasses.replace(result, x=x, params=ev.params(x)))
        # Evaluated at the estimate as reported (its canonical form, where wrapping an angle moves
        # its last bits), where the analyses evaluate the normal equations again: one pass, not two.
        ne = ev.normal_equations(moved.x)
        return dataclasses.replace(moved, cost=ne.cost, chi2=ne.chi2, inliers=ne.inliers)

    def bias_taken(self) -> dict[str, float]:
        """The inputs' bias step this fit took, per free coordinate (empty: none)."""
        taken = next((b for b in self._bias if np.any(b.step)), None)
        return {} if taken is None else dict(zip(self.fns.free, map(float, taken.step)))

    def before_step(self, x: np.ndarray) -> np.ndarray:
        """The point whose bias step lands on the estimate ``x``: ``x`` less the step there (the
        step changes over its own size by a share of itself too small to count), so that a refit
        from a stored estimate starts at the optimum its run's solver stopped at, and ends, step
        taken again, where that run did (not wherever a solver's tolerance lets it stop)."""
        if self.noise is None:
            return x
        known = bias_step(self.evaluator, x, self.noise)
        if not np.any(known.step):
            return x
        back = self.evaluator.boxplus(x, -known.step)
        start = self.problem.start
        if start.lower is not None and start.upper is not None:
            back = np.clip(back, start.lower, start.upper)
        return np.asarray(back)

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
