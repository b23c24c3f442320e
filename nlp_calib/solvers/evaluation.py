"""Numeric access to a built problem over one set of windows: what the solvers call.

:class:`ProblemEvaluator` binds the mapped Functions of :mod:`nlp_calib.problem.functions` to the
windows once; each call then integrates the intervals if the problem needs it
(:mod:`nlp_calib.solvers.motion`), copies the parameter vector in and the sums out. The normal
equations and costs of the last points evaluated are kept, and the last point's residual terms
while their buffers are: a solver's accepted trial point, both solvers' start, the uncertainty and
the observability analysis at the same estimate cost one evaluation. A Gauss-Newton run recalls
the normal equations a recent run evaluated on the same contents (:meth:`ProblemEvaluator.recalling`):
the screen's judging fit, the pre-flight's and the fit stage's from the same start are one run's
passes over the windows, not three.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np

from nlp_calib.problem import ORDER, SUMMED, WINDOW_INPUTS, ProblemFunctions, ResidualData, unpack_upper
from nlp_calib.solvers.backends import INTERPRETED, Backend, Buffered, Request, pad_in_place
from nlp_calib.solvers.blocks import BlockMap, stream
from nlp_calib.solvers.motion import WindowMotion

#: H is called singular when its Jacobi-scaled condition number exceeds this.
SINGULAR_CONDITION = 1e12
#: Why a solver did not start: the objective is not a number at the initial guess.
NAN_START_REASON = (
    "the residual is NaN or infinite at the initial guess (e.g. a length of 0); check the data and "
    "the initial guess"
)
SINGULAR_REASON = (
    "singular normal matrix: some parameters are not determined by the data (see the observability warnings)"
)


def _unit_scaled(H: np.ndarray) -> np.ndarray | None:
    """``D^-1/2 H D^-1/2`` (``D = diag H``), insensitive to parameter units; None where ``H`` is
    not finite or a diagonal entry is not positive."""
    d = np.diag(H)
    if np.any(~np.isfinite(H)) or np.any(d <= 0):
        return None
    s = 1.0 / np.sqrt(d)
    return H * s[:, None] * s[None, :]


def scaled_condition(H: np.ndarray) -> float:
    """Condition number of ``D^-1/2 H D^-1/2`` (``D = diag H``): insensitive to parameter units."""
    scaled = _unit_scaled(H)
    if scaled is None:
        return float("inf")
    eig = np.linalg.eigvalsh(scaled)
    return float(eig[-1] / eig[0]) if eig[0] > 0 else float("inf")


def singular_share(H: np.ndarray) -> np.ndarray:
    """Each parameter's share ``(n,)`` of the directions :func:`is_singular` finds (the scaled
    eigenvalues under the largest over :data:`SINGULAR_CONDITION`); 1 everywhere where ``H`` is not
    finite or a diagonal entry is not positive."""
    scaled = _unit_scaled(H)
    if scaled is None:
        return np.ones(H.shape[0])
    lam, V = np.linalg.eigh(scaled)
    return np.asarray((V[:, lam < lam[-1] / SINGULAR_CONDITION] ** 2).sum(axis=1))


def is_singular(H: np.ndarray) -> bool:
    """True when the normal matrix does not determine every free parameter."""
    return scaled_condition(H) > SINGULAR_CONDITION


@dataclass(frozen=True)
class NormalEquations:
    """Robust-weighted normal equations at one point: ``H = Σ w ρ' JᵀΩJ``, ``g = Σ w ρ' JᵀΩe``.

    ``cost`` is the objective ``Σ ρ(s) + prior``; ``chi2`` is ``Σ s``; ``inliers`` counts
    residuals with ``s <= delta²``. ``H`` and ``g`` include the priors.
    """

    H: np.ndarray
    g: np.ndarray
    cost: float
    chi2: float
    inliers: int

    def less(self, other: NormalEquations) -> NormalEquations:
        """These normal equations without ``other``'s terms (a subset's, without priors)."""
        return NormalEquations(
            self.H - other.H,
            self.g - other.g,
            self.cost - other.cost,
            self.chi2 - other.chi2,
            self.inliers - other.inliers,
        )

    def decrement(self) -> float:
        """``gᵀH⁻¹g``: the cost decrease the undamped Gauss-Newton step predicts (×½ convention);
        inf when ``H`` is singular."""
        try:
            return float(self.g @ np.linalg.solve(self.H, self.g))
        except np.linalg.LinAlgError:
            return float("inf")

    def step(self) -> np.ndarray | None:
        """The undamped Gauss-Newton step ``-H⁻¹g`` (manifold); None when ``H`` is singular."""
        try:
            return np.linalg.solve(self.H, -self.g)
        except np.linalg.LinAlgError:
            return None


@dataclass(frozen=True)
class Priors:
    """Gaussian priors on free parameters: ``mean`` and ``sqrt_info = 1/std`` (0 = no prior)."""

    mean: np.ndarray
    sqrt_info: np.ndarray

    @property
    def active(self) -> bool:
        return bool(np.any(self.sqrt_info != 0.0))


@dataclass(frozen=True)
class Sensitivities:
    """Per residual ``w``: ``J`` ``(N, r, n_free)``, ``de_dz`` ``(N, r, z)``, ``de_dend`` ``(N, r, m)``
    (see :class:`~nlp_calib.problem.ProblemFunctions`; ``r`` error rows, ``z`` rows of a tracker
    motion: 3 and 3 for a planar sensor, 6 and 7 for a 3-D one) and the tracker motion's
    Jacobians with respect to its first and last pose's noise, ``dz_da`` and ``dz_db`` ``(N, z, p)``
    (``p`` = 3 or 6); per interval ``j``
    the map ``D`` ``(n_intervals, m, n_inputs)`` from its inputs to the end perturbation
    (``None``: identity)."""

    J: np.ndarray
    de_dz: np.ndarray
    de_dend: np.ndarray
    dz_da: np.ndarray
    dz_db: np.ndarray
    D: np.ndarray | None


#: Functions evaluated once or twice per run (the analyses'): compiling them pays from about this
#: many windows on; below, the interpreter evaluates them in less time than a compiler takes.
COMPILE_ANALYSES_FROM = 50_000
_ANALYSES = ("robust_terms", "sensitivities", "end_sensitivity")


def requests(fns: ProblemFunctions, names: Iterable[str], n_windows: int) -> list[Request]:
    """What a backend compiles so that an evaluator over about ``n_windows`` windows can evaluate
    the per-residual Functions ``names`` (the scans and the intervals' sensitivity of prefix
    problems included)."""
    out: list[Request] = []
    # In the order a run needs them: the internal fits, then the solvers, then the analyses.
    for name in sorted(set(names), key=_PRIORITY.index):
        if name in _ANALYSES and n_windows < COMPILE_ANALYSES_FROM:
            continue
        if fns.prefix:
            out.append(Request(fns.step(ORDER[name]), scan=True))
            if name == "sensitivities":
                out += [
                    Request(fns.step(0), scan=True),
                    Request(fns.interval_sensitivity, ("state", "u"), False),
                ]
        out.append(Request(fns.function(name), WINDOW_INPUTS, name in SUMMED))
    return list({(r.function.name(), r.scan): r for r in out}.values())


_PRIORITY = ("normal_equations", "cost", "cost_derivatives", "robust_terms", "sensitivities")


@dataclass
class _Windows:
    """The buffers an evaluator binds to its windows: built on first use after
    :meth:`ProblemEvaluator.bind` or :meth:`ProblemEvaluator.release`."""

    n_padded: int
    window_data: np.ndarray
    motion: WindowMotion
    bound: dict[str, BlockMap] = field(default_factory=dict)


class _PickedRows:
    """Rows ``index`` of ``values`` ``(N, rows)`` as the columns of a mapped input, gathered a
    block at a time (:class:`~nlp_calib.solvers.blocks.Columns`)."""

    def __init__(self, values: np.ndarray, index: np.ndarray) -> None:
        self.values, self.index = values, index

    @property
    def shape(self) -> tuple[int, int]:
        return self.values.shape[1], self.index.size

    def fill(self, lo: int, hi: int, out: np.ndarray) -> None:
        out[:] = self.values[self.index[lo:hi]].T


#: Points whose normal equations and cost an evaluator keeps: the stages evaluate the same few
#: points again (both solvers' start, the estimate), a solver's iterations lie between them.
KEPT_POINTS = 32

V = TypeVar("V")

#: The normal equations the last few Gauss-Newton runs evaluated, per evaluator contents
#: (:meth:`ProblemEvaluator.contents`), keyed by the point's bytes; most recent last.
_RECALLED: OrderedDict[tuple[object, ...], dict[bytes, NormalEquations]] = OrderedDict()
_RECALLED_KEPT = 4
_RECALLED_LOCK = threading.Lock()


class _Kept(Generic[V]):
    """Values at the last :data:`KEPT_POINTS` points used, keyed by the point's bytes."""

    def __init__(self) -> None:
        self._values: OrderedDict[bytes, V] = OrderedDict()

    def get(self, key: bytes) -> V | None:
        value = self._values.get(key)
        if value is not None:
            self._values.move_to_end(key)
        return value

    def put(self, key: bytes, value: V) -> None:
        self._values[key] = value
        self._values.move_to_end(key)
        if len(self._values) > KEPT_POINTS:
            self._values.popitem(last=False)


@dataclass
class _Last:
    """What was evaluated at recent points, keyed by the point's bytes (an evaluation is a function
    of the point and the bound data alone: the same bits again): normal equations, costs and the
    residual terms' weighted χ², kept when the buffers are released; the last point's exact
    derivatives; the last point's residual terms, views of the bound buffers, dropped with them.
    All dropped when the windows or their inputs change. ``told``: normal equations known
    otherwise (:meth:`ProblemEvaluator.remember`), until the next evaluation, as an evaluated
    point's are kept."""

    normal_equations: _Kept[NormalEquations] = field(default_factory=_Kept)
    told: tuple[bytes, NormalEquations] | None = None
    costs: _Kept[float] = field(default_factory=_Kept)
    weighted_chi2: _Kept[float] = field(default_factory=_Kept)
    derivatives: tuple[bytes, tuple[float, np.ndarray, np.ndarray]] | None = None
    residuals: tuple[bytes, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] | None = None


def _fill(window_data: np.ndarray, data: ResidualData, clock_only: bool = False) -> None:
    """``data``'s per-window data written into ``window_data``, padded as :func:`pad_columns` pads
    it (``clock_only``: :meth:`ResidualData.write_data`'s)."""
    data.write_data(window_data, clock_only=clock_only)
    pad_in_place(window_data, data.n_residuals)


def _same_windows(a: ResidualData, b: ResidualData) -> bool:
    """Whether ``b`` has ``a``'s windows (their records and tracker motions) and layout, its
    inputs and clock data aside."""
    return (
        a.n_residuals == b.n_residuals
        and a.inputs.shape == b.inputs.shape
        and len(a.logs) == len(b.logs)
        and (a.clock is None) == (b.clock is None)
        and np.array_equal(a.starts, b.starts)
        and np.array_equal(a.stops, b.stops)
        and np.array_equal(a.z, b.z)
    )


class ProblemEvaluator:
    """The problem's Functions mapped over the windows of ``data``, ready to call with a free vector."""

    _data: ResidualData

    def __init__(
        self,
        fns: ProblemFunctions,
        data: ResidualData,
        *,
        x_fixed: np.ndarray,
        omega: np.ndarray,
        delta: float,
        priors: Priors | None = None,
        backend: Backend | None = None,
    ) -> None:
        self.fns = fns
        self.backend = backend or INTERPRETED
        self.x_fixed = np.asarray(x_fixed, dtype=float)
        self.omega = np.asarray(omega, dtype=float)
        self.delta = float(delta)
        n = fns.n_free
        self.priors = priors or Priors(np.zeros(n), np.zeros(n))
        self._prior = Buffered(fns.prior, {"mean": self.priors.mean, "sqrt_info": self.priors.sqrt_info})
        # The parameters' own Functions (no windows), called with buffers bound once: a Function
        # called on numpy arrays costs twenty times as much.
        self._of_x = {
            "boxplus": Buffered(fns.boxplus),
            "tangent_map": Buffered(fns.tangent_map),
            "assemble": Buffered(fns.assemble),
        }
        self._known: dict[bytes, NormalEquations] | None = None
        self.bind(data)

    def bind(self, data: ResidualData) -> None:
        """Evaluate on the windows of ``data`` from now on."""
        kept: _Windows | None = getattr(self, "_windows", None)
        same = kept is not None and _same_windows(self._data, data)
        self._data = data
        self._last = _Last()
        if kept is not None and same:
            # The same windows on other inputs (the lag's re-samplings): the buffers and mapped
            # Functions bound to them stay, their contents are written in place.
            self._write_inputs(kept)
            return
        self._windows: _Windows | None = None

    def contents(self) -> tuple[object, ...]:
        """What an evaluation here is a function of, besides the point: the Functions and backend
        (the objects themselves), the robust kernel's width, and a hash of the bound windows' data
        as padded, the intervals' inputs, the windows' first and last records, the held values,
        the weights and the priors."""
        h = hashlib.blake2b(digest_size=16)
        data = self._data
        arrays = (self._on.window_data.T, data.inputs, data.starts, data.stops, self.x_fixed, self.omega)
        for v in (*arrays, self.priors.mean, self.priors.sqrt_info):
            a = np.ascontiguousarray(v)  # the buffer's transpose: a view, no copy
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.data)
        return (self.fns, self.backend, self.delta, h.digest())

    @contextmanager
    def recalling(self) -> Iterator[None]:
        """Within: the normal equations at a point a recent run evaluated on the same
        :meth:`contents` are taken from it (the same bits: an evaluation is a function of the point
        and those alone), and those evaluated here kept for the next such run."""
        key = self.contents()
        with _RECALLED_LOCK:
            known = _RECALLED.pop(key, {})
            _RECALLED[key] = known
            while len(_RECALLED) > _RECALLED_KEPT:
                del _RECALLED[next(iter(_RECALLED))]
        self._known = known
        try:
            yield
        finally:
            self._known = None

    def _write_inputs(self, windows: _Windows) -> None:
        """The bound data's inputs and per-window data written into ``windows``' buffers."""
        windows.motion.set_inputs(self._data.inputs)
        # The same windows: their ``z`` and weights are in the buffer already.
        _fill(windows.window_data, self._data, clock_only=True)

    def unbind(self, name: str) -> None:
        """Let go of the Function ``name``'s bound buffers (its outputs over every window) until its
        next evaluation binds them again; what is bound to the windows themselves stays."""
        if self._windows is not None:
            self._windows.bound.pop(name, None)
        if name == "robust_terms":
            self._last.residuals = None

    def release(self) -> None:
        """Let go of what is bound to the windows (their padded data, the prefix scans' and the
        mapped Functions' buffers: hundreds of MB on 10^6 windows) until the next evaluation, which
        binds them again (with the same results)."""
        self._windows = None
        self._last.residuals = None

    @property
    def _on(self) -> _Windows:
        if self._windows is None:
            data = self._data
            n_padded = self.backend.padded(data.n_residuals)
            window_data = np.empty((data.data_rows, n_padded), order="F")
            _fill(window_data, data)
            self._windows = _Windows(
                n_padded=n_padded,
                window_data=window_data,
                motion=WindowMotion(self.fns, self.backend, data, n_padded),
            )
        return self._windows

    @property
    def data(self) -> ResidualData:
        return self._data

    @property
    def n_residuals(self) -> int:
        return self.data.n_residuals

    @property
    def motion(self) -> WindowMotion:
        return self._on.motion

    def prepare(self, names: Iterable[str]) -> None:
        """Bind the per-residual Functions ``names`` now rather than at their first evaluation."""
        for name in names:
            if name != "sensitivities":
                self._bind(name)

    def _backend(self, name: str) -> Backend:
        """Where ``name`` is evaluated: see :data:`COMPILE_ANALYSES_FROM`."""
        small = self.n_residuals < COMPILE_ANALYSES_FROM
        return INTERPRETED if name in _ANALYSES and small else self.backend

    def _bind(self, name: str) -> BlockMap:
        bound = self._on.bound
        if name not in bound:
            static: dict[str, np.ndarray | float] = {"x_fixed": self.x_fixed}
            if name != "sensitivities":
                static.update(omega=self.omega, delta=self.delta)
            mapped = {"motion": self.motion.buffer(ORDER[name]), "data": self._on.window_data}
            f = self.fns.function(name)
            bound[name] = BlockMap(self._backend(name), f, mapped, static, name in SUMMED)
        return bound[name]

    def _call(self, name: str, x: np.ndarray) -> Sequence[np.ndarray]:
        """The per-residual Function ``name`` over the windows at ``x`` (bound on first use)."""
        bound = self._bind(name)
        self.motion.update(ORDER[name], x, self.x_fixed)
        return bound(x=x)

    def set_inputs(
        self, inputs: np.ndarray, lags: Sequence[float] | None = None, rates: np.ndarray | None = None
    ) -> None:
        """Re-evaluate the same windows on other interval inputs (re-sampled at the time offsets
        ``lags``, one per log, with their ``rates``, when the problem has them); nothing is rebuilt."""
        self._data = self._data.with_inputs(inputs, lags, rates)
        if self._windows is not None:
            # The windows' clock data follow the inputs; written in place (buffers hold it).
            self._write_inputs(self._windows)
        self._last = _Last()

    def normal_equations(self, x: np.ndarray) -> NormalEquations:
        key = np.asarray(x, dtype=float).tobytes()
        told = self._last.told
        if told is not None and told[0] == key:
            return told[1]
        kept = self._last.normal_equations.get(key)
        if kept is not None:
            return kept
        known = self._known
        ne = None if known is None else known.get(key)
        if ne is None:
            ne = self._evaluate_normal_equations(x)
            if known is not None:
                known[key] = ne
        self._last.normal_equations.put(key, ne)
        self._last.told = None
        return ne

    def _evaluate_normal_equations(self, x: np.ndarray) -> NormalEquations:
        h_upper, g, cost, chi2, inliers = self._call("normal_equations", x)
        H, cost_f = unpack_upper(h_upper, self.fns.n_free), float(cost[0])
        if self.priors.active:
            Hp, gp, cp, _, _ = self._prior(x=x)
            H, g, cost_f = H + Hp, g + gp, cost_f + float(cp[0])
        return NormalEquations(H=H, g=g, cost=cost_f, chi2=float(chi2[0]), inliers=round(float(inliers[0])))

    def remember(self, x: np.ndarray, ne: NormalEquations) -> None:
        """Take ``ne`` as the normal equations at ``x`` without evaluating them (known otherwise:
        e.g. a larger set of windows' less those of the windows left out) until the next
        evaluation."""
        self._last.told = (np.asarray(x, dtype=float).tobytes(), ne)

    def cost(self, x: np.ndarray) -> float:
        key = np.asarray(x, dtype=float).tobytes()
        kept = self._last.costs.get(key)
        if kept is not None:
            return kept
        (cost,) = self._call("cost", x)
        c = float(cost[0])
        if self.priors.active:
            c += float(self._prior(x=x)[2][0])
        self._last.costs.put(key, c)
        return c

    def cost_derivatives(self, x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """The objective, its gradient and its exact Hessian ``(n, n)`` in plain coordinates."""
        key = np.asarray(x, dtype=float).tobytes()
        last = self._last.derivatives
        if last is not None and last[0] == key:
            return last[1]
        cost, grad, h_upper = self._call("cost_derivatives", x)
        out = (float(cost[0]), grad.ravel(), unpack_upper(h_upper, self.fns.n_free))
        if self.priors.active:
            c, g, H = self.prior_terms(x)
            out = (out[0] + c, out[1] + g, out[2] + H)
        self._last.derivatives = (key, out)
        return out

    def robust_terms(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per residual: error ``(error rows, n)``, ``s = eᵀΩe`` and the IRLS weight ρ'(s). Views of
        the evaluator's buffers: the next evaluation overwrites them (copy what is kept)."""
        e, s, w, _ = self.residual_terms(x)
        return e, s, w

    def residual_terms(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`robust_terms` plus each residual's ``JᵀΩe`` ``(n_free, n)`` (manifold)."""
        key = np.asarray(x, dtype=float).tobytes()
        last = self._last.residuals
        if last is not None and last[0] == key:
            return last[1]
        e, s, w, g = (np.asarray(v) for v in self._call("robust_terms", x))
        n = self.n_residuals
        nf = self.fns.n_free
        out = (
            e.reshape(self.fns.error_rows, -1, order="F")[:, :n],
            s.ravel()[:n],
            w.ravel()[:n],
            g.reshape(nf, -1, order="F")[:, :n],
        )
        self._last.residuals = (key, out)
        return out

    def weighted_chi2(self, x: np.ndarray) -> float:
        """``Σ ρ'(s)·s`` over the windows at ``x`` (of :meth:`robust_terms`): the residuals' variance
        times their degrees of freedom, as the observability and the plan take it. Kept per point,
        where the residual terms' buffers are let go of after the uncertainty's use."""
        key = np.asarray(x, dtype=float).tobytes()
        kept = self._last.weighted_chi2.get(key)
        if kept is not None:
            return kept
        _, s, weight = self.robust_terms(x)
        value = float(np.sum(weight * s))
        self._last.weighted_chi2.put(key, value)
        return value

    def sensitivities(
        self, x: np.ndarray, windows: np.ndarray | None = None
    ) -> Iterator[tuple[slice, Sensitivities]]:
        """What the noise propagation needs at ``x``, a block of windows at a time (see
        :class:`Sensitivities`; ``D`` covers every interval and is the same in each block); only
        the windows of the indices ``windows`` when given (the blocks' slices then index them, and
        ``D`` covers their intervals alone, in order: :meth:`ResidualData.intervals_of`)."""
        fns = self.fns
        N = self.n_residuals if windows is None else int(windows.size)
        D = self.interval_sensitivity(x, windows) if fns.prefix else None
        poses_wt = self.data.T_world_sensor
        starts, stops = (
            i if windows is None else i[windows] for i in (self.motion.starts, self.motion.stops)
        )
        # Gathered a block at a time: whole, the two ends' poses were 48 MB at 10^6 windows.
        ends = {k: _PickedRows(poses_wt, i) for k, i in (("a", starts), ("b", stops))}
        # Cheap: the interpreter, a block at a time.
        tracker = stream(INTERPRETED, fns.between_jacobians, ends, {}, N)
        p = fns.between_jacobians.size2_out(0)
        for (w, (J, de_dz, de_dend)), (_, jac) in zip(self._per_window("sensitivities", x, windows), tracker):
            dz_da, dz_db = (_per_column(v, v.shape[1] // p, w.stop - w.start) for v in jac)
            yield w, Sensitivities(J=J, de_dz=de_dz, de_dend=de_dend, dz_da=dz_da, dz_db=dz_db, D=D)

    def end_sensitivities(
        self, x: np.ndarray, windows: np.ndarray | None = None
    ) -> Iterator[tuple[slice, np.ndarray]]:
        """:meth:`sensitivities`' ``de_dend`` alone, a block of windows at a time (the same
        values, without the parameters' and the tracker's Jacobians or ``D``)."""
        name = "end_sensitivity"
        if windows is None and self._backend(name) is not INTERPRETED:
            # Compiled (many windows): the full Function, which the backend has built.
            name = "sensitivities"
        for w, outs in self._per_window(name, x, windows):
            yield w, outs[-1]

    def jacobians(self, x: np.ndarray) -> Iterator[tuple[slice, np.ndarray, np.ndarray]]:
        """Every window's ``J`` and ``de_dend`` at ``x``, a block of windows at a time: those of
        :meth:`sensitivities`, without ``D`` or the tracker's Jacobians."""
        for w, (J, _, de_dend) in self._per_window("sensitivities", x, None):
            yield w, J, de_dend

    def _per_window(
        self, name: str, x: np.ndarray, windows: np.ndarray | None
    ) -> Iterator[tuple[slice, list[np.ndarray]]]:
        """The unsummed per-window Function ``name``'s outputs ``(block, rows, cols)`` at ``x``, a
        block of windows at a time (those of ``windows`` alone when given)."""
        N = self.n_residuals if windows is None else int(windows.size)
        # A few windows of many: the interpreter (their compiled map is sized for all of them).
        backend = self._backend(name) if windows is None else INTERPRETED
        motion = self.motion.update(ORDER[name], x, self.x_fixed, windows)
        data = (
            self._on.window_data if windows is None else np.asfortranarray(self._on.window_data[:, windows])
        )
        f = getattr(self.fns, name)
        own = stream(backend, f, {"motion": motion, "data": data}, {"x": x, "x_fixed": self.x_fixed}, N)
        for w, outs in own:
            size = outs[0].shape[1] // f.size2_out(0)
            yield w, [_per_column(v, size, w.stop - w.start) for v in outs]

    def interval_sensitivity(
        self, x: np.ndarray, windows: np.ndarray | None = None, shift: np.ndarray | None = None
    ) -> np.ndarray:
        """``D`` ``(intervals, m, n_inputs)`` at ``x`` on every interval, or on those the windows of
        the indices ``windows`` cover alone (:meth:`ResidualData.intervals_of`); at the inputs
        moved by ``shift`` ``(n_inputs, those intervals)`` when given (the prefix poses kept)."""
        m = self.motion
        n_pad = m.inputs.shape[1]
        poses = m.poses(x, self.x_fixed)
        if windows is None:
            u = m.inputs
            if shift is not None:
                u = np.array(u, order="F")
                u[:, : shift.shape[1]] += shift
            mapped, backend = {"state": poses[:, :n_pad], "u": u}, self._backend("sensitivities")
        else:
            cols = self.data.intervals_of(windows)
            u = m.inputs[:, cols] if shift is None else m.inputs[:, cols] + shift
            mapped = {"state": np.asfortranarray(poses[:, cols]), "u": np.asfortranarray(u)}
            backend = INTERPRETED
        n = next(iter(mapped.values())).shape[1]
        per = BlockMap(
            backend, self.fns.interval_sensitivity, mapped, {"x_fixed": self.x_fixed}, reduce=False
        )
        (D_all,) = per(x=x)
        return _per_column(D_all, n, m.n_intervals if windows is None else n)

    def prior_information(self, x: np.ndarray) -> np.ndarray:
        """The priors' contribution ``J_pᵀJ_p`` to the normal matrix."""
        return self._prior(x=x)[0]

    def prior_terms(self, x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """The priors' cost, gradient and Hessian in plain coordinates."""
        _, _, cost, grad, hess = self._prior(x=x)
        return float(cost[0]), grad.ravel(), hess

    def tangent_map(self, x: np.ndarray) -> np.ndarray:
        """``∂(x ⊞ Δ)/∂Δ`` at ``Δ = 0``: maps the manifold perturbation to plain coordinates."""
        return self._of_x["tangent_map"](x=x)[0]

    def boxplus(self, x: np.ndarray, step: np.ndarray) -> np.ndarray:
        (x_next,) = self._of_x["boxplus"](x=x, step=step)
        return x_next.ravel()

    def params(self, x: np.ndarray) -> np.ndarray:
        """Full parameter vector (free and fixed, in model order)."""
        return self._of_x["assemble"](x=x, x_fixed=self.x_fixed)[0].ravel()


def _per_column(value: np.ndarray, n_columns: int, n: int) -> np.ndarray:
    """A map's horizontally stacked ``(rows, cols)`` blocks as ``(n, rows, cols)`` (the first ``n``)."""
    return value.reshape(value.shape[0], n_columns, -1)[:, :n].transpose(1, 0, 2)
