"""The bias the inputs' noise gives an estimate (errors in variables), and the step that removes it.

The fit minimises ``F = Σ_w ρ(s_w)`` on noisy inputs. Their noise adds to each window's expected
``s_w`` its share ``T_w(θ) = tr(Ω G_w V_w G_wᵀ)`` (``G_w = ∂e_w/∂end``, ``V_w`` the noise a
window's end collects, see :class:`~nlp_calib.analysis.uncertainty.EndNoise`), and that share
depends on the parameters: a differential drive's heading change per interval is the wheels'
difference over the baseline, so a longer baseline shrinks the noise's share of the cost and the
fit prefers it (the regression on a noisy regressor attenuates ``1/baseline``). On one-record
windows the counts' rounding is a few per cent of the wheels' difference per interval, which
biases the baseline by several σ. The expected cost of the noise-free inputs is ``F − T`` (``T =
Σ_w ρ'_w T_w``, the weights held at the estimate); one Newton step on it from the estimate ``x̂``,
where ``∇F = 0``, is ``Δ = ½ H⁻¹ ∇T`` (``H``, ``g`` are half the Hessian and gradient of ``F``: see
:class:`~nlp_calib.solvers.evaluation.NormalEquations`). ``∇T`` is taken by central differences over
one σ of each free coordinate: ``T`` is smooth on that scale.

Those differences cost a pass over the windows per parameter: of them it takes ``∂e/∂end`` alone
(on the scan of values), and along a coordinate that leaves the kinematic ones (a mount's, a
clock's) the intervals' ``D`` and the noise the ends collect stay, to the bit. ``T`` is a sum
over the windows, so a strided subset's sum scaled by ``N/n`` estimates it without bias, and the
spread of the subset's terms says how far off that estimate can be: where the step it gives
stays, with that margin, below :data:`MATTERS` of every σ, it is taken as it is (it cannot move
an estimate by a share of its σ that matters); elsewhere ``∇T`` is taken on every window.

The noise also has a mean in the residuals where the model is curved in its inputs (second order,
``β_w = ½ E[δᵀ∇²e_w δ]``, :func:`mean_shifts`): the clean residual is the noisy one less ``β``, so
the step adds ``H⁻¹ Σ_w ρ'_w J_wᵀ Ω β_w``. A rate over one interval is what makes it matter (a
skid-steer's turn on its wheels' noisy rate); it costs one pass over every window.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis.degeneracy import motion_scale
from nlp_calib.analysis.observability import directions
from nlp_calib.analysis.uncertainty import EndNoise, per_second, reading_map, split_noise
from nlp_calib.models import rate_rows, reference_scales
from nlp_calib.problem import ResidualData
from nlp_calib.results.checks import WEAK
from nlp_calib.solvers import ProblemEvaluator

#: A step below this share of every σ cannot matter: the subset's estimate of it is taken as it is.
MATTERS = 0.05
#: Windows the subset holds: few, as each pass still integrates the whole log (a pass over every
#: window costs three over these on the shipped scenarios); where the step is thousands of times
#: below :data:`MATTERS`, as there, their estimate's standard error is too. Problems with fewer
#: than :data:`SCREEN_FROM` windows take every window at once.
SUBSET = 64
SCREEN_FROM = 8 * SUBSET
#: The subset's estimate's margin, in its own standard errors.
MARGIN = 3.0
#: A step beyond this many σ of any coordinate is not taken: the counts' rounding biases an
#: estimate by a few σ (tens on long one-record windows); a step of hundreds is a solver's flat
#: valley (a drive that does not determine the parameters), where a Newton step extrapolates.
LARGEST = 100.0


def noise_share(
    evaluator: ProblemEvaluator, x: np.ndarray, weight: np.ndarray, noise: tuple[np.ndarray, np.ndarray]
) -> float:
    """``T(x) = Σ_w weight_w tr(Ω G_w V_w G_wᵀ)``: the inputs' expected share of the cost at ``x``
    (``noise``: the inputs' 1σ and which of them are counters, noise on their readings)."""
    return float(np.sum(window_shares(evaluator, x, weight, noise)))


def window_shares(
    evaluator: ProblemEvaluator,
    x: np.ndarray,
    weight: np.ndarray,
    noise: tuple[np.ndarray, np.ndarray],
    windows: np.ndarray | None = None,
) -> np.ndarray:
    """Each window's term of :func:`noise_share` (those of the window indices ``windows`` alone
    when given, in their order)."""
    return _Shares(evaluator, weight, noise, windows)(x)


class _Shares:
    """:func:`window_shares` of the same windows at any ``x``: what does not depend on ``x`` (the
    windows' spans, the noise's split, the counters' increment variances) taken once for the
    gradient's two passes per parameter."""

    def __init__(
        self,
        evaluator: ProblemEvaluator,
        weight: np.ndarray,
        noise: tuple[np.ndarray, np.ndarray],
        windows: np.ndarray | None,
    ) -> None:
        std, counted = noise
        self.evaluator, self.windows = evaluator, windows
        self.split = split_noise(np.asarray(std, dtype=float) ** 2, counted)
        picked, self.starts, self.stops = _spans(evaluator.data, windows)
        self.weight = weight[picked]
        data = evaluator.data
        cols = slice(None) if windows is None else data.intervals_of(windows)
        self.inputs = data.inputs[:, cols]
        self.counted = np.asarray(counted, dtype=bool)
        self.variance = _increment_variance(data, self.counted)[:, cols] if self.counted.any() else None
        self.last: tuple[bytes, EndNoise] | None = None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        evaluator = self.evaluator
        ends = self._end_noise(x)
        out = np.zeros(self.weight.size)
        for w, de_dend in evaluator.end_sensitivities(x, self.windows):
            V = ends.between(self.starts[w], self.stops[w])
            rows = ((de_dend @ V) * de_dend).sum(axis=2)  # (windows, error rows)
            out[w] = self.weight[w] * (rows @ evaluator.omega)
        return out

    def _end_noise(self, x: np.ndarray) -> EndNoise:
        """The noise the windows' ends collect at ``x``: the last one's again where ``x`` has its
        coordinates that move the intervals' ``D`` (a step of the mount's or the clock's leaves
        them, and ``D``, as they were)."""
        fns = self.evaluator.fns
        key = np.asarray(x)[fns.interval_coordinates].tobytes()
        if self.last is None or self.last[0] != key:
            self.last, n_in = None, fns.n_inputs  # the last one's D let go before the next's
            if fns.prefix:
                D = self.evaluator.interval_sensitivity(x, self.windows)
            else:
                D = np.broadcast_to(np.eye(n_in), (int(self.stops.max(initial=0)), n_in, n_in))
            self.last = (key, EndNoise(self._noise_map(D), self.split))
        return self.last[1]

    def _noise_map(self, D: np.ndarray) -> np.ndarray:
        """``D`` from each source of noise: a rate's column folded into its counter's
        (:func:`~nlp_calib.analysis.uncertainty.reading_map`), and a counter's scaled by
        ``√(v_j/2)``, ``v_j`` its increment's variance in readings' (:func:`_increment_variance`):
        a one-interval window's share is then what records re-sampling a joint stream carry (they
        interpolate its readings, so two records between the same two of them differ by less than
        two readings' noise: about 0.8 of one for 120 Hz records between 100 Hz joints, where two
        overstated the share 2.5-fold and the step overshot a differential drive's baseline by 6σ
        to 11σ). Longer windows, where the share barely depends on the parameters, take it as
        their ends' intervals give it. The σ keeps two readings per increment
        (:mod:`~nlp_calib.analysis.uncertainty`): an upper bound there."""
        D = reading_map(D, self.inputs, rate_rows(self.evaluator.fns.model))
        v = self.variance
        if v is None or np.all(v[self.counted] == 2.0):
            return D
        out = np.array(D, dtype=float)
        out[:, :, self.counted] *= np.sqrt(v[self.counted, : D.shape[0]].T[:, None, :] / 2.0)
        return out


def _spans(data: ResidualData, windows: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The window indices and their first and last interval: of every window, or of ``windows``
    on their intervals alone, renumbered (the evaluator's ``D`` for them covers those alone)."""
    picked = np.arange(data.n_residuals) if windows is None else windows
    starts, stops = data.starts[picked], data.stops[picked]
    if windows is not None:
        cols = data.intervals_of(windows)
        starts, stops = np.searchsorted(cols, starts), np.searchsorted(cols, stops - 1) + 1
    return picked, starts, stops


def mean_shifts(
    evaluator: ProblemEvaluator,
    x: np.ndarray,
    noise: tuple[np.ndarray, np.ndarray],
    windows: np.ndarray | None,
) -> Callable[[slice, np.ndarray], np.ndarray]:
    """Per block of windows (given their ``de_dend``), each one's expected residual ``β_w``
    ``(windows, error rows)`` that the inputs' noise adds through the model's curvature in them
    (second order: ``½ E[δᵀ∇²e δ]`` over each interval's own noise, along each source at a time;
    the sources independent).
    On one-interval windows the residuals' own second differences give it; on longer ones each
    interval's end shift ``¼ (D(u+v) − D(u−v)) v`` (the prefix poses held: the terms across
    intervals have no mean), summed over a window's intervals. A rate taken over one interval is
    what makes it matter: a skid-steer's turn ``Δθ_w/(1 + slip·|ω_w|)`` on a noisy ``ω_w`` turns
    less by ``slip·σ_ω²`` per second whatever the rate, a track short by its share of the turn rate."""
    sources = _sources(evaluator, noise)
    if not sources:
        return lambda w, de_dend: np.zeros(de_dend.shape[:2])
    picked, starts, stops = _spans(evaluator.data, windows)
    if not evaluator.fns.prefix:
        beta = _second_differences(evaluator, x, sources)[:, picked].T
        return lambda w, de_dend: beta[w]
    cols = None if windows is None else evaluator.data.intervals_of(windows)
    moved = [v if cols is None else v[:, cols] for v in sources]
    b = _end_shift(evaluator, x, windows, moved[0])
    for v in moved[1:]:  # one source's at a time: a stack of every source's held them all at once
        b = b + _end_shift(evaluator, x, windows, v)
    B = np.concatenate([np.zeros((1, b.shape[1])), np.cumsum(b, axis=0)])
    return lambda w, de_dend: np.einsum("nrm,nm->nr", de_dend, B[stops[w]] - B[starts[w]])


def _end_shift(
    evaluator: ProblemEvaluator, x: np.ndarray, windows: np.ndarray | None, v: np.ndarray
) -> np.ndarray:
    """Each interval's end shift ``¼ (D(u+v) − D(u−v)) v`` ``(intervals, m)`` along the source ``v``."""
    ahead = evaluator.interval_sensitivity(x, windows, v)
    ahead -= evaluator.interval_sensitivity(x, windows, -v)  # in place: no third array of D's size
    return np.asarray(0.25 * np.einsum("jmi,ij->jm", ahead, v))


def _sources(evaluator: ProblemEvaluator, noise: tuple[np.ndarray, np.ndarray]) -> list[np.ndarray]:
    """Each independent source of an interval's input noise as its 1σ move of every interval's
    inputs ``(n_inputs, intervals)``: an input with noise of its own, or a counter's increment
    (two readings' worth, less where the records re-sample a joint stream: :meth:`Log.increment_variance`,
    or where the counter stood: :func:`stood_still`)
    with the rate it gives over the interval's duration."""
    std, counted = (np.asarray(v) for v in noise)
    u = evaluator.data.inputs
    rates = rate_rows(evaluator.fns.model)
    per_s = per_second(u, rates)
    readings = np.sqrt(_increment_variance(evaluator.data, counted))
    out = []
    for row in np.flatnonzero(std > 0):
        v = np.zeros_like(u, dtype=float)
        v[row] = std[row] * (readings[row] if counted[row] else 1.0)
        for rate in (r for r, of in rates.items() if of == row):
            v[rate] = v[row] * per_s
        out.append(v)
    return out


def _increment_variance(data: ResidualData, counted: np.ndarray) -> np.ndarray:
    """Every counter's increment's variance in readings' ``(n_inputs, intervals)`` as ``data``
    lays its logs' intervals: :meth:`Log.increment_variance` (2 between two logs and wherever a log
    does not fill its columns), less where the counter stood (:func:`stood_still`); 2 on the rows
    that are no counters."""
    counted = np.asarray(counted, dtype=bool)
    inputs = np.asarray(data.inputs)
    out = np.full(inputs.shape, 2.0)
    for log, first in zip(data.logs, data.offsets):
        cols = first + np.arange(log.n_records - 1)
        keep = (cols >= 0) & (cols < inputs.shape[1])
        cols = cols[keep]
        v = log.increment_variance()[keep]
        for row in np.flatnonzero(counted):
            out[row, cols] = v * stood_still(inputs[row, cols])
    return out


def stood_still(increments: np.ndarray) -> np.ndarray:
    """Per interval, the share of a counter's increment's rounding variance (two readings' noise,
    independent) its counts leave: 1 but inside a run of ``L`` unchanged counts, the interval and
    both its neighbours unchanged, where it is ``6/(L + 1)²``. Over such a run the wheel moved less
    than a tick, and a reading's rounding is that of the wheel's position, the same for readings of
    one position: the run's rounding is the travel inside it, which a stop puts at its edges (the
    first and last unchanged interval, which keep two readings: the wheel's stop and its start,
    each a share of a tick). Rolling through the run evenly it is at most ``1/(L + 1)`` of a tick an
    interval, ``12/(L + 1)²`` readings: the bound held inside. Two readings on every interval of a
    stop gave it about ``L`` times the rounding it has, and the step that frees an
    estimate of it pushed a car's rear track +0.020 m, to +4σ (seed 4601 of docs/models.md)."""
    still = np.asarray(increments) == 0
    out = np.ones(still.size)
    # Each run of unchanged counts: where it starts and ends, and each of its intervals' place in it.
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(np.int8), [0]])))
    length = edges[1::2] - edges[::2]
    L = np.repeat(length, length)
    place = np.arange(L.size) - np.repeat(np.cumsum(length) - length, length)
    out[still] = np.where((place > 0) & (place < L - 1), 6.0 / (L + 1.0) ** 2, 1.0)
    return out


def _second_differences(evaluator: ProblemEvaluator, x: np.ndarray, sources: list[np.ndarray]) -> np.ndarray:
    """``½ Σ_v (e(u+v) + e(u−v) − 2e(u))``, every window's ``(error rows, windows)``, on windows of
    one interval each (no terms across intervals); the evaluator's inputs restored."""
    data = evaluator.data
    # Copied: the evaluator's terms are views of its buffers, which the next evaluation overwrites
    # (kept as a view, ``here`` became each perturbed error in turn and every difference was 0).
    here = np.array(evaluator.robust_terms(x)[0])
    out = np.zeros_like(here)
    try:
        for v in sources:
            for sign in (1.0, -1.0):
                evaluator.set_inputs(data.inputs + sign * v)
                out += 0.5 * (evaluator.robust_terms(x)[0] - here)
    finally:
        evaluator.set_inputs(data.inputs)
    return out


@dataclass(frozen=True)
class BiasStep:
    """The manifold ``step`` from the estimate ``x`` that removes the inputs' noise bias, and the
    white-noise σ of each free coordinate there (``sigma``: the scale the step was taken on)."""

    x: np.ndarray
    step: np.ndarray
    sigma: np.ndarray

    def holds_at(self, x: np.ndarray) -> bool:
        """Whether ``x`` is this estimate's optimum (another solver's, within 1e-3 of its σ): the
        step there is this one to well within its own size."""
        return x.shape == self.x.shape and bool(np.all(np.abs(x - self.x) <= 1e-3 * self.sigma))


def bias_step(evaluator: ProblemEvaluator, x: np.ndarray, noise: tuple[np.ndarray, np.ndarray]) -> BiasStep:
    """The step from the estimate ``x`` that removes the inputs' noise bias (zeros where the inputs
    carry no noise or the normal matrix is singular). ``∇T`` by central differences over one σ of
    each coordinate (``T`` is smooth on that scale: its curvature changes it by σ over the
    parameter's own scale), on a strided subset of the windows first where there are many: the
    subset's step stands where it cannot matter (see the module's docstring)."""
    n = evaluator.fns.n_free
    none = BiasStep(x, np.zeros(n), np.full(n, np.inf))
    if not np.any(np.asarray(noise[0]) > 0) or n == 0:
        return none
    ne = evaluator.normal_equations(x)
    # Copied: the noise's mean evaluates the windows on moved inputs, which overwrites the buffers
    # these would otherwise be views of.
    _, s, weight = (np.array(v) for v in evaluator.robust_terms(x))
    try:
        H_inv = np.linalg.inv(ne.H)
    except np.linalg.LinAlgError:
        return none
    dof = max(s.size * evaluator.fns.error_rows - n, 1)
    sigma = np.sqrt(np.clip(np.diag(H_inv), 0.0, None) * float(np.sum(weight * s)) / dof)
    if not np.all(np.isfinite(sigma) & (sigma > 0)):
        return none
    H_inv = _determined_inverse(evaluator, x, ne.H, float(np.sum(weight * s)) / dof)
    N = s.size
    # The noise's mean costs one pass over every window; the gradient of its share, one per
    # parameter: that is screened on a subset first.
    mean = H_inv @ _shift_sum(evaluator, x, weight, noise)
    share = None
    if N >= SCREEN_FROM:
        subset = np.linspace(0, N - 1, SUBSET).round().astype(np.intp)
        terms = 0.5 * _gradient_terms(evaluator, x, weight, noise, sigma, subset) @ H_inv
        # The subset's sum scaled by N/n, and its standard error (sampling n of N windows).
        share = N * terms.mean(axis=0)
        err = N * np.sqrt((1.0 - SUBSET / N) * terms.var(axis=0, ddof=1) / SUBSET)
        if not np.all(np.abs(share) + MARGIN * err <= MATTERS * sigma):
            share = None
    if share is None:
        share = 0.5 * H_inv @ _gradient_terms(evaluator, x, weight, noise, sigma, None).sum(axis=0)
    step = np.asarray(mean + share)
    return BiasStep(x, step, sigma) if np.all(np.abs(step) <= LARGEST * sigma) else none


def _determined_inverse(
    evaluator: ProblemEvaluator, x: np.ndarray, H: np.ndarray, sigma2: float
) -> np.ndarray:
    """``H⁻¹`` on the directions the drive determines well, zero along those the run's
    observability calls weak or not determined (:func:`~nlp_calib.analysis.observability.directions`,
    beyond ``WEAK`` reference units, or free whatever the noise): along those the cost is far from
    its quadratic valley over a σ, and a Newton step extrapolates instead of correcting a small
    bias (a car driven straight down a highway: a step of 10^4 σ along what it leaves free; a car
    with a length that fits nearly as well near zero: a step of 0.7σ along a loose combination,
    which changed by a quarter of itself over its own length). What is stated of them is caveated
    anyway."""
    fns, names = evaluator.fns, evaluator.fns.free
    value = dict(zip(fns.names, np.asarray(fns.assemble(x, evaluator.x_fixed)).ravel()))
    keys = fns.layout.keys(names)
    R = reference_scales(fns.model, keys, np.array([value[n] for n in names]), fns.sensor.reference)
    motion2 = motion_scale(fns, evaluator.data.z, evaluator.omega)
    found = directions(H, sigma2, R, evaluator.n_residuals, motion2)
    lam = np.maximum(found.lam, 1e-12 * max(float(found.lam[-1]), 1e-300))
    keep = ~found.free & (1.0 / np.sqrt(lam) <= WEAK)
    V = found.V[:, keep]
    return (R[:, None] * V / (sigma2 * lam[keep])) @ (V.T * R[None, :])


def _shift_sum(
    evaluator: ProblemEvaluator, x: np.ndarray, weight: np.ndarray, noise: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """``Σ_w ρ'_w J_wᵀ Ω β_w`` ``(n_free,)`` over every window (``β_w``, the noise's mean in its
    residual: :func:`mean_shifts`): the clean residual is the noisy one less ``β``, so the clean
    fit's gradient at ``x`` is minus it. Summed block by block in the windows' order, each block
    onto the running total (the sum of one pass over every window's term, without holding them)."""
    shift = mean_shifts(evaluator, x, noise, None)
    total = np.zeros((1, evaluator.fns.n_free))
    for w, J, de_dend in evaluator.jacobians(x):
        beta = shift(w, de_dend) * evaluator.omega
        terms = weight[w, None] * np.einsum("nrk,nr->nk", J, beta)
        total = np.cumsum(np.concatenate([total, terms]), axis=0)[-1:]
    return total[0]


def _gradient_terms(
    evaluator: ProblemEvaluator,
    x: np.ndarray,
    weight: np.ndarray,
    noise: tuple[np.ndarray, np.ndarray],
    sigma: np.ndarray,
    windows: np.ndarray | None,
) -> np.ndarray:
    """Each window's term of ``∇T`` ``(windows, n_free)``: central differences over one σ. A forward
    difference's error is of the order of σ times ``T``'s curvature: beside a gyro its windows'
    large share of ``T`` (a few counts' rounding against a 0.1 mrad gyro) depends on the wheels'
    ratios alone, and that error leaked into their scale, held by the reference alone (a text log
    beside a gyro: the radii and the separation +1.2 mm, 1.6σ, on seed 22)."""
    shares = _Shares(evaluator, weight, noise, windows)
    return np.stack(
        [
            (shares(evaluator.boxplus(x, h)) - shares(evaluator.boxplus(x, -h))) / (2.0 * h[i])
            for i, h in _steps(sigma)
        ],
        axis=1,
    )


def _steps(sigma: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """Each coordinate's step of one σ."""
    return [(i, np.where(np.arange(sigma.size) == i, sigma, 0.0)) for i in range(sigma.size)]
