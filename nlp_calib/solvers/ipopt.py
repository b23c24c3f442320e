"""IPOPT on the same objective Gauss-Newton minimises, with optional box bounds.

The NLP's cost, gradient and Hessian are answered by the evaluator's Functions
(:mod:`nlp_calib.solvers.nlp`), handed to ``nlpsol`` as ``grad_f`` / ``hess_lag`` so that CasADi
never re-derives them. The Hessian is Gauss-Newton's (``JᵀΩJ`` weighted by the kernel; the
default: it meets the exact Hessian's optimum, without the second-order prefix jets that cost
most of IPOPT's time on long logs), exact (the problem's ``cost_derivatives``) or IPOPT's
limited-memory approximation. For Huber,
``huber_formulation: lifted`` solves the exact smooth Black–Rangarajan form
``min_{w∈(0,1]} w·s + δ²(1/w − 1)`` with one extra variable per residual (its parameter block of
the Hessian is Gauss-Newton's).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from nlp_calib.core import memory
from nlp_calib.core.errors import OptionsError
from nlp_calib.results.solver import IterationRecord, SolverResult, SolverTrace
from nlp_calib.solvers.evaluation import (
    NAN_START_REASON,
    SINGULAR_REASON,
    NormalEquations,
    ProblemEvaluator,
    is_singular,
)
from nlp_calib.solvers.nlp import NlpOracle

HUBER_FORMULATIONS = ("direct", "lifted")
HESSIANS = ("exact", "gauss_newton", "limited_memory")
_SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
#: IPOPT also stops on a step below machine precision, which it takes at an optimum that rounding
#: keeps it from certifying to its own tolerance (a fit exact to rounding). That point is
#: converged when no Gauss-Newton step there could lower the cost by more than this fraction.
_TINY_STEP = "Search_Direction_Becomes_Too_Small"
_TINY_STEP_DECREMENT = 1e-12
#: IPOPT takes a step without a line search when no parameter moves by more than this (relative):
#: √ε. At an optimum such a step changes the cost by about ε of itself, so the line search cannot
#: see its decrease through the cost's rounding and halves a correct Newton step again and again
#: (on the real log: 18 iterations and 166 cost evaluations instead of 8 and 9, depending on how
#: the last digits of the cost happened to round; IPOPT's default is 10 ε).
TINY_STEP_TOL = float(np.sqrt(np.finfo(float).eps))
#: Lower bound of the lifted weights: keeps δ²/w finite; far below any weight at the optimum.
_W_MIN = 1e-8
#: IPOPT options that make it read or write files, or load a library, by name of its own: the
#: run's files are written only through its staged output folder, and nothing but the scenario
#: sets IPOPT's options (no ``ipopt.opt`` from the working folder is read, see ``_ipopt_options``).
FILE_OPTIONS = {
    "output_file": "it writes IPOPT's log into that file, outside the run's output folder",
    "file_print_level": "it only sets the detail of output_file's log",
    "file_append": "it only applies to output_file's log",
    "option_file_name": "it reads options from a file that is not the scenario; put them in ipopt.options",
    "print_options_documentation": "it prints IPOPT's whole option reference into the run's output",
    "hsllib": "it loads a library from a path; install HSL where IPOPT finds it by default",
    "pardisolib": "it loads a library from a path; install Pardiso where IPOPT finds it by default",
}

#: Address space a solve needs free: the 128 MiB work buffer of the OpenBLAS under MUMPS (which
#: retries forever, deaf to signals, when it cannot get it) and room for MUMPS's own workspace.
_ADDRESS_SPACE = 136 << 20


@dataclass(frozen=True)
class IpoptOptions:
    """Options of :class:`Ipopt`; ``options`` passes raw IPOPT options through (e.g. ``mu_init``)."""

    huber_formulation: str = "direct"
    hessian: str = "gauss_newton"
    max_iter: int = 500
    tol: float = 1e-10
    linear_solver: str = "mumps"
    print_level: int = 0
    options: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.huber_formulation not in HUBER_FORMULATIONS:
            raise OptionsError(
                f"huber_formulation must be one of {', '.join(HUBER_FORMULATIONS)}, "
                f"got {self.huber_formulation!r}"
            )
        if self.hessian not in HESSIANS:
            raise OptionsError(f"hessian must be one of {', '.join(HESSIANS)}, got {self.hessian!r}")
        if self.max_iter < 1 or not self.tol > 0:
            raise OptionsError(f"max_iter must be >= 1 and tol > 0, got {self.max_iter} and {self.tol}")
        for key in self.options:
            if key in FILE_OPTIONS:
                raise OptionsError(f"options.{key}: not allowed ({FILE_OPTIONS[key]}); remove it")


#: IPOPT keeps its iterates inside the bounds, within about its tolerance: a parameter this close
#: (relative) to a bound is held there.
_AT_BOUND = 1e-6


def _at_bound(x: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The parameters of ``x`` at a bound (IPOPT's answer: next to it, inside)."""
    with np.errstate(invalid="ignore"):
        low = x - lower <= _AT_BOUND * (1.0 + np.abs(lower))
        return np.asarray(low | (upper - x <= _AT_BOUND * (1.0 + np.abs(upper))))


def _last_line(exc: BaseException) -> str:
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return lines[-1].split(": ", 1)[-1] if lines else type(exc).__name__


class Ipopt:
    """An ``nlpsol`` instance set up once for one evaluator; :meth:`solve` may be called often."""

    name: ClassVar[str] = "ipopt"
    label: ClassVar[str] = "IPOPT"
    options_type: ClassVar[type] = IpoptOptions
    supports_bounds: ClassVar[bool] = True
    _buffer_held: ClassVar[bool] = False

    @staticmethod
    def functions(options: IpoptOptions) -> tuple[str, ...]:
        if options.huber_formulation == "lifted":
            return ("cost", "normal_equations", "robust_terms")
        return ("cost", "cost_derivatives" if options.hessian == "exact" else "normal_equations")

    def __init__(self, evaluator: ProblemEvaluator, options: IpoptOptions | None = None) -> None:
        self.evaluator = evaluator
        self.options = options or IpoptOptions()
        self.lifted = self.options.huber_formulation == "lifted" and evaluator.fns.spec.kernel == "huber"
        t0 = time.perf_counter()
        try:
            self._solver = self._build()
        except RuntimeError as exc:  # CasADi checks the options when the solver is built
            raise OptionsError(
                f"IPOPT cannot be set up with these options ({_last_line(exc)}); "
                "check options and linear_solver"
            ) from None
        self.build_time_s = time.perf_counter() - t0

    def _ipopt_options(self) -> dict[str, Any]:
        o = self.options
        opts: dict[str, Any] = {
            "ipopt.max_iter": o.max_iter,
            "ipopt.tol": o.tol,
            "ipopt.print_level": o.print_level,
            "ipopt.sb": "yes",
            "ipopt.linear_solver": o.linear_solver,
            "ipopt.tiny_step_tol": TINY_STEP_TOL,
            "print_time": False,
            # An empty name: IPOPT reads no ipopt.opt from the working folder.
            "ipopt.option_file_name": "",
        }
        if o.hessian == "limited_memory":
            opts["ipopt.hessian_approximation"] = "limited-memory"
        opts.update({f"ipopt.{k}": v for k, v in o.options.items()})
        return opts

    def _build(self) -> ca.Function:
        opts = self._ipopt_options()
        exact = self.options.hessian == "exact" and not self.lifted
        self._oracle = oracle = NlpOracle(self.evaluator, self.lifted, exact)
        x = ca.MX.sym("x", oracle.n_x)
        p = ca.MX.sym("p", 0)
        nlp = {"x": x, "p": p, "f": oracle.f(x, p)}
        opts.update({"grad_f": oracle.grad_f, "no_nlp_grad": True, "calc_lam_p": False})
        if self.options.hessian != "limited_memory":
            opts["hess_lag"] = oracle.hess_lag
        return ca.nlpsol("ipopt_lifted" if self.lifted else "ipopt_direct", "ipopt", nlp, opts)

    def solve(
        self,
        x0: np.ndarray,
        lower: np.ndarray | Sequence[float] | None = None,
        upper: np.ndarray | Sequence[float] | None = None,
    ) -> SolverResult:
        """Solve from ``x0`` (free parameters) within optional bounds on them."""
        ev = self.evaluator
        t0 = time.perf_counter()
        if not np.isfinite(ev.cost(x0)):
            # Reported like Gauss-Newton does, so that the other solver's result is not lost.
            return self._not_started(np.asarray(x0, dtype=float), time.perf_counter() - t0)
        x_init, lbx, ubx = self._start(np.asarray(x0, dtype=float), lower, upper)
        if not Ipopt._buffer_held:
            fix = "solve with gauss_newton alone (solvers: [gauss_newton])"
            memory.require_address_space(_ADDRESS_SPACE, "IPOPT's linear algebra", fix)
        try:
            sol = self._solver(x0=x_init, lbx=lbx, ubx=ubx)
            Ipopt._buffer_held = True  # OpenBLAS keeps its buffer: later solves need no more room
        except RuntimeError as exc:  # CasADi reports a failed evaluation by raising
            self._oracle.guard.reraise()
            return self._not_started(np.asarray(x0, dtype=float), time.perf_counter() - t0, _last_line(exc))
        self._oracle.guard.reraise()
        elapsed = time.perf_counter() - t0
        n = ev.fns.n_free
        at_bound = _at_bound(np.asarray(sol["x"]).ravel()[:n], lbx[:n], ubx[:n])
        return self._result(np.asarray(sol["x"]).ravel()[:n], self._solver.stats(), elapsed, at_bound)

    def _start(
        self,
        x0: np.ndarray,
        lower: np.ndarray | Sequence[float] | None,
        upper: np.ndarray | Sequence[float] | None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """IPOPT's start point and bounds: the free parameters' and, lifted, each residual's weight
        (started at its IRLS value at ``x0``)."""
        ev = self.evaluator
        n = ev.fns.n_free
        lbx = np.full(n, -np.inf) if lower is None else np.asarray(lower, dtype=float)
        ubx = np.full(n, np.inf) if upper is None else np.asarray(upper, dtype=float)
        if not self.lifted:
            return x0, lbx, ubx
        _, s, _ = ev.robust_terms(x0)
        w0 = np.clip(ev.delta / np.sqrt(np.maximum(s, 1e-300)), _W_MIN, 1.0)
        return (
            np.concatenate([x0, w0]),
            np.concatenate([lbx, np.full(ev.n_residuals, _W_MIN)]),
            np.concatenate([ubx, np.ones(ev.n_residuals)]),
        )

    def _result(
        self, x: np.ndarray, stats: dict[str, Any], elapsed: float, at_bound: np.ndarray | None = None
    ) -> SolverResult:
        """The result at IPOPT's answer ``x`` (free parameters), judged on the normal equations there
        (of the parameters not held at a bound, ``at_bound``)."""
        ev = self.evaluator
        ne = ev.normal_equations(x)
        status = str(stats.get("return_status", "unknown"))
        converged = bool(stats.get("success", False)) or status in _SUCCESS
        if status == _TINY_STEP:
            free = np.ones(x.size, dtype=bool) if at_bound is None else ~at_bound
            inner = NormalEquations(ne.H[np.ix_(free, free)], ne.g[free], ne.cost, ne.chi2, ne.inliers)
            converged = inner.decrement() <= _TINY_STEP_DECREMENT * ne.cost
        reason = status if converged else f"IPOPT stopped: {status}"
        if converged and is_singular(ne.H):
            converged, reason = False, SINGULAR_REASON
        history = _history(stats.get("iterations", {}))
        return SolverResult(
            solver=Ipopt.name,
            names=ev.fns.names,
            params=ev.params(x),
            x=x,
            cost=ne.cost,
            chi2=ne.chi2,
            inliers=ne.inliers,
            n_residuals=ev.n_residuals,
            converged=converged,
            reason=reason,
            trace=SolverTrace(
                iterations=int(stats.get("iter_count", len(history))),
                time_s=elapsed,
                history=history,
                stats={
                    "return_status": status,
                    "build_time_s": self.build_time_s,
                    "formulation": "lifted" if self.lifted else "direct",
                },
            ),
        )

    def _not_started(self, x0: np.ndarray, elapsed: float, error: str | None = None) -> SolverResult:
        """The result of a solve that could not run: the cost is not finite at ``x0``, or IPOPT
        failed with ``error``; the parameters are the initial guess and flagged as not converged."""
        ne = self.evaluator.normal_equations(x0)
        return SolverResult(
            solver=Ipopt.name,
            names=self.evaluator.fns.names,
            params=self.evaluator.params(x0),
            x=x0,
            cost=ne.cost,
            chi2=ne.chi2,
            inliers=ne.inliers,
            n_residuals=self.evaluator.n_residuals,
            converged=False,
            reason=NAN_START_REASON if error is None else f"IPOPT failed: {error}",
            trace=SolverTrace(
                iterations=0,
                time_s=elapsed,
                stats={
                    "return_status": "not run" if error is None else "error",
                    "build_time_s": self.build_time_s,
                },
            ),
        )


def _history(its: dict[str, list[float]]) -> tuple[IterationRecord, ...]:
    """IPOPT's per-iteration statistics as records."""
    columns = ("obj", "inf_pr", "inf_du", "d_norm", "regularization_size")
    return tuple(
        IterationRecord(
            iteration=i,
            cost=float(obj),
            constraint_violation=float(pr),
            dual_infeasibility=float(du),
            step_norm=float(dn),
            damping=float(reg),
        )
        for i, (obj, pr, du, dn, reg) in enumerate(zip(*(its.get(c, []) for c in columns)))
    )
