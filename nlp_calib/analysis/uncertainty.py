"""Parameter covariance at the optimum, with the noise propagated through the correlated residuals.

Horizon windows share data: windows that meet share a tracker pose, windows that overlap share
encoder intervals. Treating their residuals as independent (the classical ``σ²·H⁻¹``) is wrong
both ways: tracker noise largely cancels along a chain of windows (consecutive errors
telescope), input noise is counted several times. So the covariance is propagated from the
sources instead, to first order:

- each tracker pose carries white noise ``diag(σ_t², σ_t², σ_θ²)`` (a 3-D pose: ``σ_t²`` on each
  coordinate of its position, ``σ_r²`` on each component of a rotation on the right);
- each interval's model inputs carry white noise ``diag(σ_u²)`` (encoder quantisation by default),
  except a counter's (``counted``): its rounding is on the readings, so its increment over an
  interval is the difference of two readings' noises, ``n_{j+1} − n_j``; a window's count then
  holds ``2σ_u²`` whatever its length, and adjacent windows' counts share a reading.

A residual is ``e_w ≈ E_w^a n_a + E_w^b n_b + Σ_j F_w^j m_j`` (``E = ∂e/∂z·∂z/∂p`` and
``F = ∂e/∂u``, both symbolic), the Gauss-Newton estimate moves by ``−H⁻¹ Σ_w L_w e_w`` with
``L_w = ρ'_w J_wᵀΩ``, so ``Cov = M H⁻¹ S H⁻¹ Mᵀ`` with ``S = Σ_p K_p Σ_p K_pᵀ + Σ_j Q_j Σ_u Q_jᵀ``,
``K_p`` and ``Q_j`` summing ``L_w E_w`` and ``L_w F_w`` over the windows that touch pose ``p`` or
interval ``j``. Every interval ``j`` of a window moves its motion through the window's end alone:
``F_w^j = ∂e_w/∂end · D_j`` with ``D_j`` the interval's own map (see
:mod:`nlp_calib.problem.motion`), so ``Q_j = (Σ_{w ∋ j} L_w ∂e_w/∂end)·D_j`` and the input
noise a window collects, ``Σ_j D_j Σ_u D_jᵀ``, are differences of running sums: the cost is
linear in the number of windows whatever their length. The tracker's variances are estimated
from the squared residuals by non-negative least squares (method of moments, corrected for the
fitted degrees of freedom) over the windows the noise explains; the input noise is given. A robust
kernel's threshold is on a window's whole residual: a window of six rows of noise alone lies beyond
δ = 3 (its squared norm over 9) one time in six. Such a window is counted with the noise where its
squared residual lies within the 99.9 % point of what the noise gives it; only one beyond that adds
its own score as it is (an error the noise does not explain). The poses' noise reaches the score
through the kernel's pulls at their mean slope over the windows of that noise, and each window adds
what its pull holds beyond that slope as its own, both as the estimated noise gives them
(:func:`expected_kernel_terms`); the inputs' noise through
each window's own weight. ``M`` maps the manifold perturbation to plain parameter coordinates.

A reference that measures its own motions (increments: a scan matcher's) carries white noise on
each increment instead, its own and no other's: ``e_w ≈ ∂e/∂z·n_w + …``, one source per window;
nothing telescopes.

Assumptions: white tracker-pose noise explains the residuals beyond the given input noise (no
timing error or slowly varying model error), and the problem is close to linear within a few σ.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from nlp_calib.analysis.block_scatter import block_scatter
from nlp_calib.analysis.degeneracy import free_directions, motion_scale, scales
from nlp_calib.analysis.leverage import stretches
from nlp_calib.analysis.residual_floor import ScoreRows, beyond
from nlp_calib.models import rate_rows
from nlp_calib.problem import ProblemFunctions, ResidualData
from nlp_calib.results.checks import LAG_EFFECT_CORRELATION, LagEffect
from nlp_calib.results.layout import CLOCK, Layout
from nlp_calib.results.uncertainty import Uncertainty
from nlp_calib.solvers import ProblemEvaluator, Sensitivities
from nlp_calib.symbolic.kernels import kernel_function

#: The per-residual Functions the estimate evaluates, per residual (not summed).
FUNCTIONS = ("robust_terms", "sensitivities")


def nnls_small(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Non-negative least squares for a handful of unknowns (exhaustive active sets)."""
    return nnls_gram(A.T @ A, A.T @ y, float(y @ y))


def nnls_gram(G: np.ndarray, h: np.ndarray, yy: float) -> np.ndarray:
    """:func:`nnls_small` from ``G = AᵀA``, ``h = Aᵀy`` and ``yy = yᵀy`` (summed block by block).

    Lawson and Hanson's active set: the problem is convex, so the first point whose free
    coordinates solve their normal equations and whose held ones could only raise the cost is
    the optimum (the exhaustive search over every subset found the same one in 2^k solves)."""
    # In units where every column has length 1 a coordinate's pull is at most the residual's
    # length, whatever the columns' scales: one tolerance serves them all.
    d = np.sqrt(np.diag(G))
    d = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 0.0)
    Gs, hs = G * np.outer(d, d), h * d
    x = np.zeros(h.size)
    free = np.zeros(h.size, dtype=bool)
    tol = 1e-12 * np.sqrt(max(yy, float(np.abs(hs).max(initial=0.0)) ** 2, 1e-300))
    for _ in range(3 * h.size + 3):
        pull = np.where(free | (d == 0), -np.inf, hs - Gs @ x)
        if pull.max(initial=-np.inf) <= tol:
            break
        free[int(np.argmax(pull))] = True
        x = _free_solution(Gs, hs, x, free)
    return x * d


def _free_solution(G: np.ndarray, h: np.ndarray, x: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Lawson and Hanson's inner loop: the free coordinates' unconstrained solution, stepping
    back to the last feasible point (and holding the coordinates that reach 0) while it is not."""
    for _ in range(free.size + 1):
        z = np.zeros_like(x)
        cols = np.flatnonzero(free)
        z[cols] = np.linalg.lstsq(G[np.ix_(cols, cols)], h[cols], rcond=None)[0]
        if np.all(z[cols] > 0):
            return z
        back = free & (z <= 0)
        alpha = float(np.min(x[back] / (x[back] - z[back])))
        x = x + alpha * (z - x)
        free &= x > 0
        x[~free] = 0.0
        if not free.any():
            return x
    return x


def _pseudo_inverse(
    H: np.ndarray, scale: np.ndarray, free: Callable[[np.ndarray], np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of ``H`` on the subspace the data determine, and a mask of the parameters in the rest.

    The eigen-analysis runs in reference units (``scale``), where an undetermined direction
    stands out cleanly whatever the parameters' units; ``free`` says which eigenvalues belong to
    directions the drive leaves free (:func:`~nlp_calib.analysis.degeneracy.free_directions`).
    """
    lam, V = np.linalg.eigh(H * np.outer(scale, scale))
    keep = ~free(lam)
    inv = (V[:, keep] / lam[keep]) @ V[:, keep].T * np.outer(scale, scale)
    undetermined = (V[:, ~keep] ** 2).sum(axis=1) > 1e-3
    return inv, undetermined


def not_available(evaluator: ProblemEvaluator) -> Uncertainty:
    """No uncertainty at all (NaN) for an estimate where the residual is NaN or infinite."""
    fns = evaluator.fns
    n = len(fns.names)
    free = np.array([name in fns.free for name in fns.names])
    corr = np.full((n, n), np.nan)
    corr[~free, :] = 0.0
    corr[:, ~free] = 0.0
    np.fill_diagonal(corr, 1.0)
    return Uncertainty(
        names=fns.names,
        free=fns.free,
        covariance=np.full((fns.n_free, fns.n_free), np.nan),
        std=np.where(free, np.nan, 0.0),
        correlation=corr,
        noise={},
        dof=0,
    )


#: Windows (or intervals) handled at a time: bounds the temporaries, whatever the log's length.
STEP = 1 << 16
#: Rows a per-row buffer grows by at least (:class:`_Rows`).
GROW = 1 << 14
#: Rows summed stretch by stretch (or only those with something in them) where fewer than one in
#: this many differ from the row before: windows spread over a log (the pre-flight's judged ones).
SPARSE = 8


def _add(out: np.ndarray, index: np.ndarray, values: np.ndarray, distinct: bool) -> None:
    """``out[index[w]] += values[w]`` for every ``w`` (``distinct``: no index repeats)."""
    if index.size and index[-1] - index[0] == index.size - 1 and distinct:
        out[index[0] : index[-1] + 1] += values  # consecutive windows: a slice, no gather
    elif distinct:
        out[index] += values
    else:
        np.add.at(out, index, values)


def _weighted_gram(A: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``Σ_p A_p diag(weights) A_pᵀ`` for ``A`` ``(P, n, k)``, one matrix product per :data:`STEP`
    of ``p`` (the weighted copy is a block's, not the whole ``A``'s)."""
    n = A.shape[1]
    out = np.zeros((n, n))
    for lo in range(0, max(A.shape[0], 1), STEP):
        Aw = (A[lo : lo + STEP] * np.sqrt(weights)).transpose(1, 0, 2).reshape(n, -1)
        out += Aw @ Aw.T
    return out


def range_std(lower: np.ndarray | None, upper: np.ndarray | None, n: int) -> np.ndarray:
    """The 1σ of a uniform distribution over each free parameter's bounds (inf where unbounded)."""
    if lower is None or upper is None:
        return np.full(n, np.inf)
    width = np.asarray(upper, dtype=float) - np.asarray(lower, dtype=float)
    return np.where(np.isfinite(width), width / np.sqrt(12.0), np.inf)


def estimate(
    evaluator: ProblemEvaluator,
    x: np.ndarray,
    data: ResidualData,
    input_noise_std: np.ndarray,
    bounds_std: np.ndarray | None = None,
    counted: np.ndarray | None = None,
) -> Uncertainty:
    """Covariance of the estimate ``x`` fitted to ``data``, given the inputs' 1σ noise (on the
    readings where ``counted``, per input row: a counter's increment differences two of them).

    ``bounds_std`` (per free parameter, inf where unbounded; see :func:`range_std`) enters as a
    prior: a direction the data do not determine is then known as well as the bounds of the
    parameters in it allow (a lag within its search), and every parameter that moves along it
    carries that σ (listed in :attr:`Uncertainty.bounded`); a direction with no bounded parameter
    in it leaves its parameters' σ infinite."""
    fns = evaluator.fns
    ne = evaluator.normal_equations(x)
    if not (np.isfinite(ne.cost) and np.all(np.isfinite(ne.H))):
        return not_available(evaluator)
    # Copied, and the bound outputs let go of: beside them they hold each window's gradient, which
    # nothing here reads (96 MB at 10^6 windows, under the stream of sensitivities below).
    e, s, weight = (np.array(v) for v in evaluator.robust_terms(x))
    evaluator.unbind("robust_terms")
    blocks = evaluator.sensitivities(x)
    first = next(blocks)
    # Input noise is known (encoder resolution, or set by the user); the tracker's two variances
    # follow from the squared residuals by the method of moments, on inliers only. Estimating the
    # input noise the same way is ill-posed: its share of the residuals is small, its effect on the
    # parameters is not (it does not telescope), so residual noise would masquerade as it.
    Sigma_in = np.asarray(input_noise_std, dtype=float) ** 2
    n_int, n_in = data.inputs.shape[1], fns.n_inputs
    D = first[1].D if first[1].D is not None else np.broadcast_to(np.eye(n_in), (n_int, n_in, n_in))
    D = reading_map(D, data.inputs, rate_rows(fns.model))
    use = s <= evaluator.delta**2 if fns.spec.kernel != "none" else np.ones(s.size, dtype=bool)
    split = split_noise(Sigma_in, counted)
    running = EndNoise(D, split)
    kernel = (fns.spec.kernel, float(evaluator.delta))
    sums = _Sums.zero(fns, data, first[1].de_dend.shape[2], D, (split, running), kernel)
    residuals = _Residuals(e=e, weight=weight, use=use, Omega=evaluator.omega)
    own = ScoreRows(data.starts, data.stops, fns.n_free)
    for w, sens in itertools.chain([first], blocks):
        sums.add(w, sens, residuals, running)
        own.add(w, sens.J, weight[w] * e[:, w], evaluator.omega, weight[w])
    var, explained = sums.variances((fns.error_rows, fns.n_free), int(use.sum()), residuals.Omega)
    use = use.copy()
    use[sums.kernel.index[explained]] = True
    dof = max(fns.error_rows * int(use.sum()) - fns.n_free, 1)
    meat = white_meat = sums.meat(var, explained)
    # The data term is not divided by the residuals' variance σ², so a prior of weight σ²/std² (the
    # scenario's, weighed so; the bounds' below) adds σ² times that weight to the score's covariance.
    sigma2 = float(np.sum(weight[use] * s[use])) / dof
    if evaluator.priors.active:
        meat = meat + sigma2 * evaluator.prior_information(x)
    scale = scales(fns, _free_values(evaluator, x))  # reference units, for the free directions
    sandwich = _covariance(evaluator, x, ne.H, sigma2, (bounds_std, scale))
    (cov, bounded), residual = _with_residuals(sandwich, meat, own)
    out = _packaged(fns, cov, _noise_levels(fns, var, Sigma_in), dof)
    out = replace(out, bounded=tuple(n for n, b in zip(fns.free, bounded) if b))
    return _with_stretches(_with_spreads(out, residual, own, white_meat), evaluator, scale, own)


def _with_stretches(
    out: Uncertainty, evaluator: ProblemEvaluator, scale: np.ndarray, own: ScoreRows
) -> Uncertainty:
    """``out`` with the stretches of the drive that alone determine a direction
    (:func:`~nlp_calib.analysis.leverage.stretches`, from ``own``'s batches' information, judged in
    the reference units ``scale``)."""
    if own.done != own.hi.size:  # not every window's information summed (too few to batch)
        return out
    batches = (own.information, own.edges)
    return replace(out, stretches=stretches(evaluator.fns, evaluator.data, evaluator.omega, scale, batches))


def _free_values(evaluator: ProblemEvaluator, x: np.ndarray) -> np.ndarray:
    """The free parameters' values at ``x`` (evaluator coordinates), in :attr:`free` order."""
    fns = evaluator.fns
    return np.asarray(fns.assemble(x, evaluator.x_fixed)).ravel()[[fns.names.index(f) for f in fns.free]]


def _with_spreads(
    out: Uncertainty, residual: np.ndarray, own: ScoreRows, white_meat: np.ndarray
) -> Uncertainty:
    """``out`` with the spreads of the fit's own residuals: each free parameter's σ from its
    residuals' own scores where beyond the noise model's (``residual``), and the blocks'
    disagreement (:mod:`block_scatter`, from ``own``'s batches and the noise model's meat)."""
    with np.errstate(invalid="ignore"):
        floor = np.fmax(np.sqrt(np.diag(out.covariance)), residual)
    scatter, chi2, blocks = block_scatter((*own.blocks(), white_meat), floor)

    def in_names(v: np.ndarray) -> np.ndarray:
        return np.array([dict(zip(out.free, v)).get(n, np.nan) for n in out.names], dtype=float)

    return replace(
        out,
        std_residuals=in_names(residual),
        std_block_scatter=in_names(scatter),
        block_chi2=np.vstack([in_names(chi2), in_names(blocks)]),
    )


def _noise_levels(fns: ProblemFunctions, var: np.ndarray, Sigma_in: np.ndarray) -> dict[str, float]:
    """Each noise source's 1σ by name: the tracker's groups, then the inputs'."""
    noise = {name: float(np.sqrt(v)) for name, v in zip(fns.sensor.noise_names, var)}
    noise.update({f"input_{name}": float(np.sqrt(v)) for name, v in zip(fns.model.input_names, Sigma_in)})
    return noise


def _with_residuals(
    sandwich: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], meat: np.ndarray, own: ScoreRows
) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """The covariance of ``meat`` and which parameters it leaves bounded; and each parameter's σ
    from the residuals' own scores where beyond it (:mod:`residual_floor`: an error of each
    window's own, read as the poses' noise, cancels along the chain with it), NaN elsewhere."""
    cov, bounded = sandwich(meat)
    zero = sandwich(np.zeros_like(meat))[0]

    def meat_part(m: np.ndarray) -> np.ndarray:
        # A parameter the drive leaves undetermined is inf in both: NaN, which beyond() leaves out.
        with np.errstate(invalid="ignore"):
            return sandwich(m)[0] - zero

    return (cov, bounded), beyond(cov, own.variances(meat_part))


def _covariance(
    evaluator: ProblemEvaluator,
    x: np.ndarray,
    H: np.ndarray,
    sigma2: float,
    bounds_and_scale: tuple[np.ndarray | None, np.ndarray],
) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """:func:`_bounded_covariance` at ``x`` as a function of the meat: in the reference units
    ``scale`` (the estimate's), the drive's free directions from its windows' motion, the bounds'
    prior in the data's units."""
    fns, data = evaluator.fns, evaluator.data
    bounds_std, scale = bounds_and_scale
    motion2 = motion_scale(fns, data.z, evaluator.omega)

    def free(lam: np.ndarray) -> np.ndarray:
        return free_directions(lam, data.n_residuals, motion2)

    prior = bounds_prior(bounds_std, sigma2, fns.n_free)
    M = np.asarray(fns.tangent_map(x))
    return functools.partial(_sandwich_of, H, (scale, M), free, (prior, sigma2))


def _sandwich_of(
    H: np.ndarray,
    scale_and_map: tuple[np.ndarray, np.ndarray],
    free: Callable[[np.ndarray], np.ndarray],
    prior_sigma2: tuple[np.ndarray, float],
    meat: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    return _bounded_covariance(H, meat, scale_and_map, free, prior_sigma2)


def white_covariance(
    H: np.ndarray,
    sigma2: float,
    scale: np.ndarray,
    free: Callable[[np.ndarray], np.ndarray],
    bounds_std: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The white-noise covariance ``σ²·H⁻¹`` of the information ``H = JᵀΩJ`` (manifold coordinates)
    as :func:`estimate` treats it: the directions the drive leaves free (``free``, on eigenvalues
    of ``H`` in the reference units ``scale``) held only by the bounds' prior (``bounds_std``, see
    :func:`range_std`), inf where nothing holds them; and which parameters only the bounds hold.
    What a drive, or a drive with a manoeuvre appended, would determine before any fit."""
    n = H.shape[0]
    prior = bounds_prior(bounds_std, sigma2, n)
    return _bounded_covariance(H, sigma2 * H, (scale, np.eye(n)), free, (prior, sigma2))


def bounds_prior(bounds_std: np.ndarray | None, sigma2: float, n: int) -> np.ndarray:
    """The bounds' prior weights in the data's units (``σ²/std²``; 0 where unbounded)."""
    if bounds_std is None:
        return np.zeros(n)
    std = np.asarray(bounds_std, dtype=float)
    # A pinned parameter's bounds meet (a lag no fit converged from): its weight is infinite, as meant.
    with np.errstate(divide="ignore"):
        return sigma2 * np.where(np.isfinite(std), std**-2.0, 0.0)


def _bounded_covariance(
    H: np.ndarray,
    meat: np.ndarray,
    scale_and_map: tuple[np.ndarray, np.ndarray],
    free: Callable[[np.ndarray], np.ndarray],
    prior_sigma2: tuple[np.ndarray, float],
) -> tuple[np.ndarray, np.ndarray]:
    """The sandwich covariance (plain coordinates, ``M`` the tangent map) with the bounds' prior
    (its weights in the data's units and the residuals' variance σ²) where the drive leaves a
    direction free, and which parameters move along such a direction (their σ is the bounds')."""
    scale, M = scale_and_map
    prior, sigma2 = prior_sigma2
    n = H.shape[0]
    RR = np.outer(scale, scale)
    lam, V = np.linalg.eigh(H * RR)
    loose = free(lam)
    undetermined = (V[:, loose] ** 2).sum(axis=1) > 1e-3
    P = np.diag(prior) if undetermined.any() else np.zeros((n, n))
    # What the data say along a free direction is rounding and the model's discretisation: it is
    # not counted, and the bounds' prior alone holds the direction.
    H_kept = H - (V[:, loose] * lam[loose]) @ V[:, loose].T / RR
    # ... and nor is the score's noise along it (the score, a gradient, projected onto the other
    # directions in reference units: g_ref = R·g).
    keep = (np.eye(n) - V[:, loose] @ V[:, loose].T) * np.outer(1.0 / scale, scale)
    meat_kept = keep @ meat @ keep.T
    # With the prior, only a direction no bounded parameter enters is still free.
    bread_inv, still = _pseudo_inverse(H_kept + P, scale, lambda lam: free(lam) & ~_bounded(lam, P, scale))
    cov = M @ bread_inv @ (meat_kept + sigma2 * P) @ bread_inv @ M.T
    # A parameter the drive and the bounds leave undetermined has no finite variance: say so.
    lost = np.abs(M) @ still > 0
    cov[lost, :] = np.inf
    cov[:, lost] = np.inf
    return cov, undetermined & ~still


def _bounded(lam: np.ndarray, P: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Which eigenvalues ``lam`` of ``(H + P)`` in reference units reach the bounds' prior ``P``: a
    direction the prior holds (at least its smallest entry, in reference units)."""
    held = np.diag(P) * scale**2
    least = float(np.min(held[held > 0])) if np.any(held > 0) else np.inf
    return np.asarray(lam >= 0.5 * least)


def per_second(inputs: np.ndarray, rates: Mapping[int, int]) -> np.ndarray:
    """Each interval's ``1/Δt`` as its rate rows say (a rate over its increment; where no
    increment moved, its neighbours'), ``(intervals,)``; zeros without ``rates``."""
    out = np.full(inputs.shape[1], np.nan)
    for rate, row in rates.items():
        moved = inputs[row] != 0
        out[moved] = np.abs(inputs[rate, moved] / inputs[row, moved])
    known = np.flatnonzero(np.isfinite(out))
    if not known.size:
        return np.zeros(inputs.shape[1])
    return np.interp(np.arange(out.size), known, out[known])


def reading_map(D: np.ndarray, inputs: np.ndarray, rates: Mapping[int, int]) -> np.ndarray:
    """``D`` ``(intervals, m, n_inputs)`` from the noise of each input that has noise of its own:
    a rate row's column (see :func:`~nlp_calib.models.rate_rows`) added to its increment's over
    the interval's duration, as the increment's noise reaches both (a skid-steer's turn rate)."""
    if not rates:
        return D
    out = np.array(D, dtype=float)
    per_s = per_second(inputs, rates)[: D.shape[0]]
    for rate, row in rates.items():
        out[:, :, row] += D[:, :, rate] * per_s[:, None]
    return out


def split_noise(Sigma_in: np.ndarray, counted: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The inputs' variances ``Sigma_in`` as (each interval's own, the readings' of a counter)."""
    mask = np.zeros(Sigma_in.shape, dtype=bool) if counted is None else np.asarray(counted, dtype=bool)
    return np.where(mask, 0.0, Sigma_in), np.where(mask, Sigma_in, 0.0)


class _Prefix:
    """``value[k] = Σ_{j<k} parts(j)`` ``(m, m)`` for ``k`` in ``0 … n``, indexed by an array of
    ``k``, without holding every ``k``'s: the sums at each :data:`STEP`-th ``k`` and the few blocks
    of :data:`STEP` last asked for (windows come in driving order: an ask falls in the blocks of
    the one before or the next), each summed in the same order as one running sum would."""

    #: Blocks held at a time: a block of windows reaches back over its longest window's intervals
    #: (the one before) and on into the next.
    KEPT = 2

    def __init__(self, parts: Callable[[int, int], np.ndarray], n: int, m: int):
        self.parts, self.n, self.m = parts, n, m
        self.at = np.zeros((n // STEP + 2, m, m))  # at[i]: value[i · STEP]
        self.kept: dict[int, np.ndarray] = {}
        for i in range(0, -(-n // STEP)):
            self.at[i + 1] = self._block(i)[-1]

    def _block(self, i: int) -> np.ndarray:
        """``value[i·STEP + 1 … (i + 1)·STEP]`` (to ``n``)."""
        if i not in self.kept:
            lo = i * STEP
            if len(self.kept) >= self.KEPT:
                del self.kept[next(iter(self.kept))]
            self.kept[i] = np.cumsum(self.parts(lo, min(self.n, lo + STEP)), axis=0) + self.at[i]
        return self.kept[i]

    def __getitem__(self, k: np.ndarray) -> np.ndarray:
        k = np.asarray(k)
        out = np.zeros((*k.shape, self.m, self.m))
        block = (k - 1) // STEP  # k = 0: the empty sum (block −1)
        for i in np.unique(block[k > 0]):
            sel = block == i
            out[sel] = self._block(int(i))[k[sel] - 1 - int(i) * STEP]
        return out


class EndNoise:
    """The input noise a window's end collects, ``(m, m)`` per window: ``Σ_j D_j Σ_u D_jᵀ`` over its
    intervals ``j`` for the inputs with noise of their own, and for a counter's (noise ``n_r`` on
    its readings, ``Σ_j D_j (n_{j+1} − n_j)``) ``D_a Σ_c D_aᵀ + D_{b−1} Σ_c D_{b−1}ᵀ`` plus
    ``Σ_r (D_{r−1} − D_r) Σ_c (D_{r−1} − D_r)ᵀ`` over the readings inside: running sums, held a
    few blocks at a time (:class:`_Prefix`: at 10^6 intervals, whole they were 200 MB)."""

    def __init__(self, D: np.ndarray, split: tuple[np.ndarray, np.ndarray]):
        own, reading = split
        n_int, m = D.shape[0], D.shape[1]
        self.D, self.reading = D, reading
        # The sums' parts close over the arrays, never over self: no cycle keeps D alive after.
        self.own = _Prefix(lambda lo, hi: _sandwich(D[lo:hi], own), n_int, m)
        self.counted = bool(n_int and np.any(reading))
        # inside[k] = Σ_{1 ≤ r < k} of the reading r's term (reading r lies between intervals r−1 and r)
        steps = lambda lo, hi: _sandwich(D[max(lo, 1) - 1 : hi - 1] - D[max(lo, 1) : hi], reading)  # noqa: E731
        inside = _Prefix(lambda lo, hi: _pad_first(steps(lo, hi), lo), n_int if self.counted else 0, m)
        self.inside = inside

    def between(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The noise at the end of the windows of intervals ``a`` to ``b − 1``, ``(N, m, m)``."""
        if not self.counted:
            return self.own[b] - self.own[a]
        first, last = _sandwich(self.D[a], self.reading), _sandwich(self.D[b - 1], self.reading)
        return self.own[b] - self.own[a] + first + last + self.inside[b] - self.inside[a + 1]


def _sandwich(D: np.ndarray, Sigma: np.ndarray) -> np.ndarray:
    """``D Σ Dᵀ`` per item, ``Σ`` diagonal."""
    return np.asarray((D * Sigma) @ D.transpose(0, 2, 1))


def _pad_first(values: np.ndarray, lo: int) -> np.ndarray:
    """Reading 0 (before interval 0) lies inside no window: nothing at item 0."""
    return np.concatenate([np.zeros((1, *values.shape[1:])), values]) if lo == 0 else values


@dataclass(frozen=True)
class _Residuals:
    """Per residual at the estimate: error ``e`` ``(rows, N)``, IRLS weight, whether it counts as an
    inlier; and the information weights ``Omega`` of the error rows."""

    e: np.ndarray
    weight: np.ndarray
    use: np.ndarray
    Omega: np.ndarray


#: Points of χ(k)'s density the kernel's expected terms are summed on, how far beyond √k they reach,
#: the step (in the logarithm) of the scales of the noise (a window's mean squared residual) they
#: are computed at, interpolated between, and the points (evenly in log s) the kernel's weight is
#: evaluated on and interpolated from (Huber's on three rows: within 1e-5 of the closed form).
CHI_POINTS = 600
CHI_SPAN = 9.0
SCALE_STEP = 0.01
WEIGHT_POINTS = 20_000


@functools.lru_cache(maxsize=8)
def _weight_map(kernel: str) -> ca.Function:
    """The kernel's Function mapped over :data:`WEIGHT_POINTS` values of ``s``, built once per
    kernel (each uncertainty reads its weight table through it)."""
    return kernel_function(kernel).map(WEIGHT_POINTS)


def expected_kernel_terms(
    kernel: str, delta: float, mean_s: np.ndarray, k: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per window, the mean slope of its pull ``ψ = ρ'(s)·Ω·e`` along its ``k`` rows of noise,
    ``E[ρ' + 2ρ''·s/k]``, and the pull's mean square, ``E[ρ'²·s]``, over that noise: ``k`` equal
    rows whose squares sum to ``mean_s`` on average (``s·k/mean_s ~ χ²(k)``); 1 and ``mean_s``
    where the kernel is quadratic. The slope is ``E[ρ'·s]/E[s]`` (Stein's lemma: the divergence of
    ``ψ`` against the noise's density), smooth where Huber's ``ρ''`` jumps. Integrated over χ(k)'s
    density on :data:`CHI_POINTS` points at scales :data:`SCALE_STEP` apart in the logarithm.

    By the same lemma the pulls of two windows that share a pose are correlated through the mean
    slope alone, so the pose's noise cancels along a chain of windows as in a plain fit, scaled by
    the slope, and each window's pull adds what its slope does not carry, ``E[ψ²] − slope²·E[e²]``,
    as its own. Both are means over the noise, not over the windows' own residuals: their
    difference is a few thousandths (Huber's δ = 3 on six rows: 0.918 − 0.9546²), and the windows'
    sample means' difference scatters by about half of it over 1,200 windows."""
    mean_s, k = np.asarray(mean_s, dtype=float), np.maximum(np.rint(k), 1.0)
    slope, spread = np.ones_like(mean_s), mean_s.copy()
    if kernel == "none":
        return slope, spread
    weights = _weight_map(kernel)
    for rows in np.unique(k):
        on = (k == rows) & (mean_s > 0)
        if not on.any():
            continue
        u = np.linspace(0.0, np.sqrt(rows) + CHI_SPAN, CHI_POINTS)
        p = u ** (rows - 1.0) * np.exp(-0.5 * u**2)
        p[0] *= 0.5  # the trapezoid's end (one row's density is largest at 0)
        p /= p.sum()
        low, high = mean_s[on].min(), mean_s[on].max()
        scales = np.geomspace(low, high, int(np.ceil(np.log(high / low) / SCALE_STEP)) + 2)
        s = scales[:, None] / rows * u[None, :] ** 2
        # The weight on one grid of log s, read at every (scale, point) pair: a window's scales
        # over decades would otherwise cost the kernel's evaluation at each of them.
        log_s = np.linspace(np.log(s[:, 1].min()), np.log(s.max()), WEIGHT_POINTS)
        table = np.asarray(weights(np.exp(log_s)[None, :], delta)[1]).ravel()
        with np.errstate(divide="ignore"):
            weight = np.interp(np.log(s), log_s, table)  # s = 0 takes the smallest s's
        at, grid = np.log(mean_s[on]), np.log(scales)
        slope[on] = np.interp(at, grid, (weight * s) @ p / scales)
        spread[on] = np.interp(at, grid, (weight**2 * s) @ p / scales) * mean_s[on]
    return slope, spread


class _Rows:
    """Per-row matrices ``(n, k)`` summed over the windows in their order, held only for the rows a
    later window can still add to: rows below a limit are final and are summed (:meth:`take`),
    :data:`STEP` at a time from row 0 (the last ones at the end), and let go of. One buffer, grown
    in place and shifted down in place as rows are let go of: a doubling held up to twice the rows
    a window adds to, and a copy of the rows kept beside the buffer at each growth and release
    (at 10^5 windows the rows held were a third of a camera run's traced peak)."""

    def __init__(self, n_rows: int, shape: tuple[int, int], distinct: bool):
        self.n_rows, self.shape, self.distinct = n_rows, shape, distinct
        self.base = 0
        self.buf = np.zeros((0, *shape))

    def add(self, index: np.ndarray, values: np.ndarray) -> None:
        """``row[index[w]] += values[w]`` (no index below the last limit released)."""
        need = int(index.max()) + 1 - self.base if index.size else 0
        if need > self.buf.shape[0]:
            self._grow(need)
        _add(self.buf, index - self.base, values, self.distinct)

    def _grow(self, need: int) -> None:
        """Room for ``need`` rows, the new ones zero: the buffer resized in place (a large one's
        pages remapped by ``realloc``, not copied beside it), by at least :data:`GROW` rows."""
        rows = max(need, self.buf.shape[0] + GROW)
        if self.buf.flags.owndata:
            self.buf.resize((rows, *self.shape), refcheck=False)  # no view of it outlives a call
        else:
            grown = np.zeros((rows, *self.shape))
            grown[: self.buf.shape[0]] = self.buf
            self.buf = grown

    def release(self, limit: int | None) -> None:
        """Sum the final rows below ``limit`` (None: every row)."""
        stop = self.n_rows if limit is None else min(limit, self.n_rows)
        taken = 0  # rows of the buffer summed; what is left is moved down once, at the end (not
        # after each step: windows spread over the log hold a buffer of every row)
        while self.base < stop and (limit is None or stop - self.base >= STEP):
            size = min(STEP, self.n_rows - self.base)
            held = min(size, self.buf.shape[0] - taken)
            # A fresh array, not a view of the buffer: numpy's loops over it take their sums in
            # an order that depends on the memory's alignment.
            rows = np.zeros((size, *self.shape))
            rows[:held] = self.buf[taken : taken + held]
            self.take(self.base, rows)
            taken += held
            self.base += size
        if taken:
            self._drop(taken)

    def _drop(self, taken: int) -> None:
        """The buffer's first ``taken`` rows let go of: the rest moved down in place, in pieces
        that do not overlap, and the rows freed at the end zeroed for the rows to come."""
        left = self.buf.shape[0] - taken
        for lo in range(0, left, taken):
            hi = min(left, lo + taken)
            self.buf[lo:hi] = self.buf[taken + lo : taken + hi]
        self.buf[max(left, 0) :] = 0.0

    def take(self, first: int, rows: np.ndarray) -> None:
        raise NotImplementedError


def _component_grams(a: np.ndarray) -> np.ndarray:
    """``Σ_p a[p, :, c] a[p, :, c]ᵀ`` for each component ``c`` of ``a`` ``(p, n, components)``:
    ``(components, n, n)``, one batched matrix product (BLAS: an order of magnitude under
    ``einsum``'s loop over ``p``; the same sums to rounding)."""
    by_component = a.transpose(2, 1, 0)
    return by_component @ by_component.transpose(0, 2, 1)


class _PoseRows(_Rows):
    """Each pose's noise map into the score, ``K_p`` ``(n, noise components)``, summed as each
    component's Gram ``Σ_p K_p[:, c] K_p[:, c]ᵀ`` (``gram``, ``(components, n, n)``)."""

    def __init__(self, n_rows: int, shape: tuple[int, int], distinct: bool):
        super().__init__(n_rows, shape, distinct)
        self.gram = np.zeros((shape[1], shape[0], shape[0]))
        #: Each window's own noise maps' Gram, no two windows summed (what does not cancel).
        self.own = np.zeros((shape[1], shape[0], shape[0]))

    def add_own(self, *maps: np.ndarray) -> None:
        """Each window's maps ``(., n, components)`` into :attr:`own`, each alone."""
        for m in maps:
            self.own += _component_grams(m)

    def take(self, first: int, rows: np.ndarray) -> None:
        live = np.flatnonzero(np.any(rows != 0, axis=(1, 2)))
        if live.size * SPARSE < rows.shape[0]:  # windows spread over the log: most poses in none
            rows = rows[live]
        self.gram += _component_grams(rows)


class _InputRows(_Rows):
    """The input noise map as differences over the intervals ``C`` (``Q_j`` is its running sum
    through interval ``j``'s ``D_j``), summed as the score's covariance ``Σ_j Q_j Σ_u Q_jᵀ``
    (``gram``) for the inputs with noise of their own, and ``Σ_r (Q_{r−1} − Q_r) Σ_c (…)ᵀ`` over
    the readings ``r`` of a counter (``Q_{−1} = Q_n = 0``: the first and last reading)."""

    def __init__(
        self,
        n_rows: int,
        shape: tuple[int, int],
        distinct: bool,
        noise: tuple[np.ndarray, tuple[np.ndarray, np.ndarray], EndNoise],
    ):
        super().__init__(n_rows, shape, distinct)
        #: Each interval's ``D_j``, the inputs' own and reading variances and their running sums.
        self.D, (self.Sigma_own, self.Sigma_reading), self.running = noise
        self.gram = np.zeros((shape[0], shape[0]))
        self.carry = np.zeros(shape)
        self.last_Q = np.zeros((shape[0], self.D.shape[2]))

    def take(self, first: int, rows: np.ndarray) -> None:
        changes = np.any(rows[1:] != 0, axis=(1, 2))
        rows[0] += self.carry  # the running sum goes on from the previous block's last
        C = np.cumsum(rows, axis=0, out=rows)
        self.carry = C[-1].copy()
        n_int = self.D.shape[0]
        if first > n_int:
            return
        inside = min(C.shape[0], n_int - first)
        ends = np.append(np.flatnonzero(changes[: max(inside - 1, 0)]) + 1, inside) if inside else None
        if ends is not None and ends.size * SPARSE < inside:
            self._stretches(first, C, ends)
        elif inside:
            Q = C[:inside] @ self.D[first : first + inside]  # (., n, n_in)
            self.gram += _weighted_gram(Q, self.Sigma_own)
            if np.any(self.Sigma_reading):
                steps = np.diff(np.concatenate([self.last_Q[None], Q]), axis=0)
                self.gram += _weighted_gram(steps, self.Sigma_reading)
            self.last_Q = Q[-1].copy()
        if C.shape[0] > inside and np.any(self.Sigma_reading):
            # Q past the last interval is 0: the last reading's term is −Q_{n−1}.
            self.gram += _weighted_gram(-self.last_Q[None], self.Sigma_reading)
            self.last_Q = np.zeros_like(self.last_Q)

    def _stretches(self, first: int, C: np.ndarray, ends: np.ndarray) -> None:
        """Windows spread over the log: ``C`` is the same over each stretch between two windows'
        ends, so a stretch's intervals sum to ``C (Σ_j D_j Σ_u D_jᵀ) Cᵀ`` and its readings inside
        to ``C (Σ_r (D_{r−1} − D_r) Σ_c (…)ᵀ) Cᵀ``, from the running sums; only each stretch's
        first reading (where ``C`` changes) is summed on its own."""
        starts = np.concatenate([[0], ends[:-1]])
        Cs, at, to = C[starts], first + starts, first + ends
        self.gram += np.einsum("sam,smk,sbk->ab", Cs, self.running.own[to] - self.running.own[at], Cs)
        if not np.any(self.Sigma_reading):
            return
        inner = self.running.inside[to] - self.running.inside[at + 1]
        self.gram += np.einsum("sam,smk,sbk->ab", Cs, inner, Cs)
        Q_first, Q_last = Cs @ self.D[at], Cs @ self.D[to - 1]
        before = np.concatenate([self.last_Q[None], Q_last[:-1]])
        self.gram += _weighted_gram(Q_first - before, self.Sigma_reading)
        self.last_Q = Q_last[-1].copy()


#: The normal deviate of the point of its noise's distribution within which a window's squared
#: residual is explained by the noise (99.9 %), and the passes that settle which windows are.
EXPLAINED_Z = 3.0902
MAX_PASSES = 8


def chi2_point(k: np.ndarray, z: float) -> np.ndarray:
    """χ²(k)'s point at the normal deviate ``z`` (Wilson-Hilferty; ``k`` may be fractional: a sum of
    unequal squares' effective degrees of freedom)."""
    k = np.maximum(np.asarray(k, dtype=float), 1e-9)
    return np.asarray(k * np.clip(1.0 - 2.0 / (9.0 * k) + z * np.sqrt(2.0 / (9.0 * k)), 0.0, None) ** 3)


@dataclass(frozen=True)
class _Window:
    """Windows beyond the kernel's threshold: their indices, each row's coefficients of the noise
    groups' variances ``(n, rows, groups)``, known input noise and squared error ``(n, rows)`` and
    each one's own score ``(n, n_free)``."""

    index: np.ndarray
    coef: np.ndarray
    known: np.ndarray
    e2: np.ndarray
    score: np.ndarray

    def explained(self, var: np.ndarray, Omega: np.ndarray) -> np.ndarray:
        """Whether each window's ``s = eᵀΩe`` lies within the 99.9 % point of what the noise
        (``var`` per group, the inputs' known) gives it: a weighted sum of squares, read as
        χ² of its effective degrees of freedom ``(Σλ)²/Σλ²`` scaled to its mean ``Σλ``."""
        lam = Omega[None, :] * np.clip(self.known + self.coef @ var, 0.0, None)
        total, square = lam.sum(axis=1), (lam**2).sum(axis=1)
        k = np.where(square > 0, total**2 / np.where(square > 0, square, 1.0), 1.0)
        s = (Omega[None, :] * self.e2).sum(axis=1)
        return np.asarray((total > 0) & (s <= total * chi2_point(k, EXPLAINED_Z) / k))


@dataclass
class _Kernel:
    """The robust kernel (its name and δ), each window's noise as its squared residual's mean is
    linear in the groups' variances (``Σ Ω·known``, then ``Σ Ω·coef`` per group, then its rows of
    noise: ``(n, groups + 2)`` block by block) and the windows beyond its threshold, collected
    block by block (see :class:`_Window`)."""

    name: str
    delta: float
    noise: list[np.ndarray] = field(default_factory=list)
    parts: list[tuple[np.ndarray, tuple[np.ndarray, ...], np.ndarray]] = field(default_factory=list)

    def add(self, index: np.ndarray, rows: tuple[np.ndarray, ...], score: np.ndarray) -> None:
        if index.size:
            self.parts.append((index, rows, score))

    def slopes(self, left_out: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per noise group, the pulls' mean slope and their mean square over the residuals' over the
        windows that carry it, as the noise ``var`` gives them (:func:`expected_kernel_terms`), but
        those beyond the threshold that it does not explain (``left_out``): 1 and 1 where the
        kernel is quadratic."""
        if self.name == "none" or not self.noise:
            return np.ones(var.size), np.ones(var.size)
        noise = np.concatenate(self.noise)
        noise[left_out] = 0.0
        known, coef, rows = noise[:, 0], noise[:, 1:-1], noise[:, -1]
        mean_s = np.clip(known + coef @ var, 0.0, None)
        slope, spread = expected_kernel_terms(self.name, self.delta, mean_s, rows)
        carries = ((coef > 0) & (mean_s > 0)[:, None]).astype(float)  # (., groups)
        n, s = carries.sum(axis=0), carries.T @ mean_s
        a = np.where(n > 0, (carries.T @ slope) / np.where(n > 0, n, 1.0), 1.0)
        b = np.where(s > 0, (carries.T @ spread) / np.where(s > 0, s, 1.0), 1.0)
        return a, b

    @property
    def index(self) -> np.ndarray:
        return np.concatenate([p[0] for p in self.parts]) if self.parts else np.zeros(0, dtype=int)

    def arrays(self, groups: int, rows: int, n_free: int) -> _Window:
        """Every window collected (empty arrays of these sizes where none is)."""
        if not self.parts:
            z = np.zeros
            empty = (z((0, rows, groups)), z((0, rows)), z((0, rows)), z((0, n_free)))
            return _Window(z(0, dtype=int), *empty)
        cat = np.concatenate
        return _Window(
            cat([p[0] for p in self.parts]),
            cat([p[1][0] for p in self.parts]),
            cat([p[1][1] for p in self.parts]),
            cat([p[1][2] for p in self.parts]),
            cat([p[2] for p in self.parts]),
        )


@dataclass
class _Sums:
    """What the pass over the windows collects: the method-of-moments system for the tracker's
    variances (``gram``, ``proj``, ``yy``), each pose's noise map into the score (``K``, a row per
    pose: summed as each noise component's Gram ``KK``, row by row once no later window adds to a
    row), the input noise map as differences over the intervals (``C``: its running sum's map
    through each interval's ``D`` summed as the score's covariance ``inputs``, the same way) and the
    windows beyond the kernel's threshold (their rows of the method of moments, their own scores)."""

    groups: tuple[tuple[int, ...], ...]
    gram: np.ndarray
    proj: np.ndarray
    yy: float
    K: _PoseRows
    C: _InputRows
    #: The kernel's slopes and the windows beyond its threshold (whether the noise explains each is
    #: decided once the variances are known).
    kernel: _Kernel
    starts: np.ndarray
    #: Per window, the least first record of the windows from it on: rows below it are final.
    final: np.ndarray
    stops: np.ndarray
    #: Per window, whether its ``z`` is a measured increment (its noise its own, not a pose's);
    #: None: none is.
    increment: np.ndarray | None = None
    #: The row of ``z`` each noise component lies on in a measured increment.
    increment_rows: tuple[int, ...] = ()

    @classmethod
    def zero(
        cls,
        fns: ProblemFunctions,
        data: ResidualData,
        m: int,
        D: np.ndarray,
        noise: tuple[tuple[np.ndarray, np.ndarray], EndNoise],
        kernel: tuple[str, float],
    ) -> _Sums:
        """Nothing summed yet; ``noise``: the inputs' own and reading variances and their running
        sums (:class:`EndNoise`); ``kernel``: the robust kernel's name and δ."""
        groups = tuple(tuple(g) for g in fns.sensor.noise_groups)
        n, a, b = fns.n_free, data.starts, data.stops
        inc = data.increment if data.increment is not None and data.increment.any() else None
        k = sum(len(g) for g in groups)
        distinct = bool(np.all(np.diff(a) > 0) and np.all(np.diff(b) > 0))
        n_int = data.inputs.shape[1]
        return cls(
            groups=groups,
            gram=np.zeros((len(groups), len(groups))),
            proj=np.zeros(len(groups)),
            yy=0.0,
            K=_PoseRows(data.T_world_sensor.shape[0], (n, k), distinct),
            C=_InputRows(n_int + 1, (n, m), distinct, (D, *noise)),
            kernel=_Kernel(*kernel),
            starts=a,
            final=np.minimum.accumulate(a[::-1])[::-1] if a.size else a,
            stops=b,
            increment=inc,
            increment_rows=tuple(fns.sensor.increment_noise_rows),
        )

    def _sources(
        self, w: slice, sens: Sensitivities
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each window's noise sources and its maps from them: its first and last pose's (an
        increment's noise, its own, is summed where it is added; nothing at its poses)."""
        a, b = self.starts[w], self.stops[w]
        Ea, Eb = sens.de_dz @ sens.dz_da, sens.de_dz @ sens.dz_db  # (., error rows, pose noise)
        if self.increment is not None and self.increment[w].any():
            inc = self.increment[w]
            Ea, Eb = Ea.copy(), Eb.copy()
            # An increment's noise lies on the sensor's rows for it (a planar one's are all its
            # noise's; a gyro's duration is exact; beside a camera, after its seven rows).
            Ea[inc], Eb[inc] = sens.de_dz[inc][:, :, self.increment_rows], 0.0
        return a, b, Ea, Eb

    def add(self, w: slice, sens: Sensitivities, r: _Residuals, running: EndNoise) -> None:
        """Add the windows ``w``."""
        a, b, Ea, Eb = self._sources(w, sens)
        known = ((sens.de_dend @ running.between(self.starts[w], b)) * sens.de_dend).sum(axis=2)
        E2 = Ea**2 + Eb**2  # per residual component c, pose component k
        coef = np.stack([E2[:, :, list(g)].sum(axis=2) for g in self.groups], axis=2)  # (., rows, groups)
        u, e = r.use[w], r.e[:, w]
        A, y = coef[u].reshape(-1, len(self.groups)), (e.T[u] ** 2 - known[u]).ravel()
        self.gram, self.proj, self.yy = self.gram + A.T @ A, self.proj + A.T @ y, self.yy + float(y @ y)
        # The poses' noise through each window's pull at the kernel's mean slope (applied with the
        # variances, :meth:`meat`), the inputs' at the window's own weight.
        unit = sens.J.transpose(0, 2, 1) * r.Omega[None, None, :]  # (., n, rows)
        L = r.weight[w, None, None] * unit
        La, Lb = unit @ Ea, unit @ Eb
        self.K.add_own(La, Lb)
        rows_of_noise = (e != 0).sum(axis=0)[:, None]
        self.kernel.noise.append(np.hstack([(known @ r.Omega)[:, None], r.Omega @ coef, rows_of_noise]))
        if self.increment is not None and self.increment[w].any():
            inc = self.increment[w]
            self.K.take(-1, La[inc])  # an increment's noise is its own: no other window adds to it
            La[inc] = 0.0
        self.K.add(a, La)
        self.K.add(b, Lb)
        # Σ over the windows containing interval j of L_w ∂e_w/∂end: +at the first interval, −after the last.
        G = L @ sens.de_dend
        self.C.add(self.starts[w], G)
        self.C.add(b, -G)
        # Residuals beyond the kernel threshold: whether the noise explains them is decided with the
        # variances (:meth:`variances`); their own scores are kept for those it does not.
        score = np.einsum("wic,cw->wi", L[~u], e[:, ~u])
        rows = (coef[~u], known[~u], e.T[~u] ** 2)
        self.kernel.add(np.arange(w.start, w.stop)[~u], rows, score)
        # Rows below the first record of every window to come are final.
        last = w.stop >= self.final.size
        self.K.release(None if last else int(self.final[w.stop]))
        self.C.release(None if last else int(self.final[w.stop]))

    def variances(
        self, rows_free: tuple[int, int], inliers: int, Omega: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The noise groups' variances (method of moments, corrected for the ``rows_free``: error
        rows per window, fitted parameters) over the windows the noise explains, and which of the
        windows beyond the kernel's threshold (``beyond``) it explains: the ``inliers``' variances
        first, then each window beyond whose squared residual lies within the noise's 99.9 % point
        at the variances found, until the set settles."""
        rows, n_free = rows_free
        b = self.kernel.arrays(len(self.groups), rows, n_free)
        explained = np.zeros(b.index.size, dtype=bool)
        for _ in range(MAX_PASSES):
            A = b.coef[explained].reshape(-1, len(self.groups))
            y = (b.e2 - b.known)[explained].ravel()
            mm = rows * (inliers + int(explained.sum()))
            G, h, yy = self.gram + A.T @ A, self.proj + A.T @ y, self.yy + float(y @ y)
            var = nnls_gram(G, h, yy) * (mm / max(mm - n_free, 1))
            now = b.explained(var, Omega)
            if np.array_equal(now, explained):
                break
            explained = now
        return var, explained

    def meat(self, var: np.ndarray, explained: np.ndarray) -> np.ndarray:
        """``S``: the score's covariance from the tracker poses' noise ``var`` (per group) through
        the kernel's mean slope ``a`` (cancelling along a chain of windows) and what each window's
        pull holds beyond it (``b − a²`` of its own map, :func:`expected_kernel_terms`), the inputs', plus
        the own scores of the windows beyond the kernel's threshold that the noise does not explain
        (``explained``: which of them it does)."""
        beyond = self.kernel.arrays(len(self.groups), 0, self.K.shape[0])
        a, b = self.kernel.slopes(beyond.index[~explained], var)
        per = [np.full(len(g), 1.0) for g in self.groups]
        Sigma_pose = np.concatenate([v * p for v, p in zip(var, per)])
        chain = Sigma_pose * np.concatenate([a_g**2 * p for a_g, p in zip(a, per)])
        # E[ψ²] ≥ slope²·E[e²] for any kernel (the pull's variance holds its linear part): a
        # difference below 0 is the quadrature's rounding, and would take the chain's variance away.
        own = Sigma_pose * np.concatenate([max(b_g - a_g**2, 0.0) * p for a_g, b_g, p in zip(a, b, per)])
        score = beyond.score[~explained]
        pose = np.einsum("c,cij->ij", chain, self.K.gram) + np.einsum("c,cij->ij", own, self.K.own)
        return pose + score.T @ score + self.C.gram


def _packaged(fns: ProblemFunctions, cov: np.ndarray, noise: dict[str, float], dof: int) -> Uncertainty:
    """The free parameters' covariance ``cov`` as the result's :class:`Uncertainty` over every
    parameter (fixed ones: 0)."""
    names = fns.names
    idx = [names.index(f) for f in fns.free]
    full = np.zeros((len(names), len(names)))
    full[np.ix_(idx, idx)] = cov
    std = np.sqrt(np.clip(np.diag(full), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = np.where(np.isfinite(full), full, 0.0) / np.outer(std, std)
    corr[~np.isfinite(corr)] = 0.0
    for i in idx:
        corr[i, i] = 1.0
    return Uncertainty(
        names=names, free=fns.free, covariance=cov, std=std, correlation=corr, noise=noise, dof=dof
    )


def lag_effects(u: Uncertainty, layout: Layout) -> tuple[LagEffect, ...]:
    """Each free time offset's (``layout``'s clock block) effect on the parameters correlated with
    it (see :class:`LagEffect`)."""
    out = []
    for lag in (n for n in u.free if layout.in_block(n, CLOCK)):
        i = u.free.index(lag)
        var = float(u.covariance[i, i])
        if not (np.isfinite(var) and var > 0):
            continue
        per = {}
        for j, name in enumerate(u.free):
            c, other = float(u.covariance[i, j]), float(u.covariance[j, j])
            # (A parameter the data leave unbounded, an infinite variance, correlates with nothing.)
            corr = c / np.sqrt(var * other) if 0 < other < np.inf else 0.0
            if j != i and np.isfinite(c) and abs(corr) >= LAG_EFFECT_CORRELATION:
                per[name] = c / var
        out.append(LagEffect(lag, per))
    return tuple(out)
