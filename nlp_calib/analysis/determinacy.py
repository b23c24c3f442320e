"""What a drive determines before any fit: the problem's Jacobian at a start, taken apart.

The information ``H = Σ JᵀΩJ`` of the windows is summed from the problem's own ``residual_jacobian``
(the defining residual and its Jacobian, clock correction included) at a start: the scenario's
nominal values or the model's closed-form start, no fit. On a long log a spread subsample of the
windows is evaluated (:data:`MAX_WORK`) and its sum scaled to every window. What the drive leaves
free and how well it holds the rest is then read exactly as a run reads it after its fit:
:func:`nlp_calib.analysis.observability.directions` (the fidelity floor of
:mod:`~nlp_calib.analysis.degeneracy`, 1σ in reference units against
:data:`~nlp_calib.results.checks.WEAK` and :data:`~nlp_calib.results.checks.NOT_OBSERVABLE`) and
:func:`nlp_calib.analysis.uncertainty.white_covariance` (a free direction held only by the
bounds of a parameter in it, such as a lag within its search). The residuals' variance is the
tracker's own scatter about its path (the run takes it from the fit's residuals instead, which
hold the model's errors too: the pre-flight's σ is a floor).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.analysis.degeneracy import free_directions, motion_scale, scales
from nlp_calib.analysis.observability import (
    MIN_TURNING,
    directions,
    held_to,
    needs_turns,
    not_observable,
    scaled_directions,
)
from nlp_calib.analysis.streams import chord_scatter
from nlp_calib.analysis.uncertainty import white_covariance
from nlp_calib.logs import Log
from nlp_calib.models.base import reference_scale
from nlp_calib.problem import ProblemFunctions, ResidualData, over_columns
from nlp_calib.results.checks import WEAK, WeakDirection
from nlp_calib.results.layout import CLOCK
from nlp_calib.results.preflight import (
    DETERMINED,
    HELD_AT_START,
    NOT_DETERMINED,
    WEAKLY,
    Excitation,
    ParameterStatus,
)
from nlp_calib.solvers import ProblemEvaluator
from nlp_calib.symbolic.kernels import kernel_function

#: Windows times their horizon evaluated at most: a spread subsample of a longer log's windows is
#: evaluated and its sum scaled to all of them (about 0.1 s of CPU).
MAX_WORK = 100_000
#: Subsamples are a whole number of this many windows (their mapped Functions are built once).
BUCKET = 256
#: The tracker's scatter is taken over at most this many records.
NOISE_RECORDS = 20_000
#: A parameter moves with another in a free or weak direction when their coupling exceeds this.
COUPLED = 0.3


@dataclass(frozen=True)
class Information:
    """``H = Σ JᵀΩJ`` over ``n_windows`` windows (free parameters, manifold coordinates), the
    windows' mean squared motion (:func:`~nlp_calib.analysis.degeneracy.motion_scale`), and where
    they were evaluated the gradient ``g = Σ JᵀΩe``, the robust cost ``Σ ρ(s)`` (``chi2``) and
    the residuals' variance per row as a run estimates it from its fit (``Σ ρ'(s)·s`` over the
    rows and windows). ``H`` and ``g`` are weighted by the robust kernel's ``ρ'(s)``, as a run's
    normal equations are."""

    H: np.ndarray
    n_windows: int
    motion2: float
    g: np.ndarray
    chi2: float
    spread2: float

    def plus(self, other: Information) -> Information:
        """The information of both sets of windows together."""
        n = self.n_windows + other.n_windows

        def mean(a: float, b: float) -> float:
            return (a * self.n_windows + b * other.n_windows) / max(n, 1)

        return Information(
            self.H + other.H,
            n,
            mean(self.motion2, other.motion2),
            self.g + other.g,
            self.chi2 + other.chi2,
            mean(self.spread2, other.spread2),
        )


def spread(n: int, most: int) -> np.ndarray:
    """At most ``most`` indices spread evenly over ``range(n)``: all of them when there are no more
    than that (the windows a run fits: 1280 of a log's 1499 left a car's barely held rear track
    to slide elsewhere in its flat valley than the run's fit, with a third of the information);
    else a whole number of :data:`BUCKET` of them when there are more than that."""
    if n <= most:
        return np.arange(n)
    size = most
    if size > BUCKET:
        size -= size % BUCKET
    return np.linspace(0, n - 1, size).round().astype(np.int64)


def information(
    fns: ProblemFunctions,
    data: ResidualData,
    x: np.ndarray,
    x_fixed: np.ndarray,
    omega: np.ndarray,
    delta: float,
    work: int = MAX_WORK,
) -> Information:
    """The information of the windows of ``data`` at the free parameters ``x``, evaluated on at most
    ``work`` windows × horizon (see the module docstring); ``delta``: the robust kernel's threshold."""
    n, nf = data.n_residuals, fns.n_free
    if n == 0:
        return Information(np.zeros((nf, nf)), 0, 0.0, np.zeros(nf), 0.0, 0.0)
    idx = spread(n, max(1, work // max(data.horizon, 1)))
    at = (np.asarray(x, dtype=float), np.asarray(x_fixed, dtype=float))
    scale = n / max(idx.size, 1)
    if np.any(data.stops[idx] - data.starts[idx] != data.horizon):
        return _evaluated(fns, data, idx, at, (omega, delta))
    e, J = over_columns(fns.residual_jacobian, *at, data.columns_of(idx))
    J = J.reshape(fns.error_rows, idx.size, nf)
    ok = np.all(np.isfinite(J), axis=(0, 2)) & np.all(np.isfinite(e), axis=0)
    J, e, w = J[:, ok], e[:, ok], np.asarray(omega, dtype=float)
    s = np.sum(w[:, None] * e**2, axis=0)
    rho, weight = _robust(fns.spec.kernel, s, delta)
    # Weighted as a run's normal equations weigh each window: by the robust kernel's ρ'(s).
    H = np.einsum("rwi,r,w,rwj->ij", J, w, weight, J, optimize=True) * scale
    g = np.einsum("rwi,r,w,rw->i", J, w, weight, e, optimize=True) * scale
    return of_terms(fns, data, omega, (H, g, float(np.sum(rho)) * scale), s, weight)


def _evaluated(
    fns: ProblemFunctions,
    data: ResidualData,
    idx: np.ndarray,
    at: tuple[np.ndarray, np.ndarray],
    weights: tuple[np.ndarray, float],
) -> Information:
    """:func:`information` of windows of several lengths (a reference's increments between its own
    stamps: a lidar's scan matches, a motions file, a gyro's intervals beside a reference), which
    have no column layout: the windows ``idx`` through the run's own evaluator (the prefix poses'
    jets take a window of any length), its normal equations scaled to every window. A window whose
    residual is not finite there is left out, as the columns' path leaves it out."""
    (omega, delta), n = weights, data.n_residuals
    part = data.select(idx)
    evaluator = ProblemEvaluator(fns, part.spanned(), x_fixed=at[1], omega=omega, delta=delta)
    e, s, weight = (v.copy() for v in evaluator.robust_terms(at[0]))
    finite = np.all(np.isfinite(e), axis=0)
    if not finite.all():
        part = part.select(finite)
        evaluator = ProblemEvaluator(fns, part.spanned(), x_fixed=at[1], omega=omega, delta=delta)
        s, weight = s[finite], weight[finite]
    whole = evaluator.normal_equations(at[0])
    scale = n / max(part.n_residuals, 1)
    return of_terms(fns, data, omega, (whole.H * scale, whole.g * scale, whole.cost * scale), s, weight)


def of_terms(
    fns: ProblemFunctions,
    data: ResidualData,
    omega: np.ndarray,
    equations: tuple[np.ndarray, np.ndarray, float],
    s: np.ndarray,
    weight: np.ndarray,
) -> Information:
    """The information of the windows of ``data`` from their robust-weighted normal equations
    ``(H, g, Σρ)`` and the windows' ``s = eᵀΩe`` and weights ρ'(s) (all of them, or a spread
    sample's), such as a fit's evaluator gives at its optimum (no second evaluation)."""
    H, g, rho = equations
    spread2 = float(np.sum(weight * s) / max(s.size * fns.error_rows, 1))
    return Information(H, data.n_residuals, motion_scale(fns, data.z, omega), g, rho, spread2)


def _robust(kernel: str, s: np.ndarray, delta: float) -> tuple[np.ndarray, np.ndarray]:
    """The robust kernel's ρ(s) and weight ρ'(s) of each window's ``s = eᵀΩe``."""
    if s.size == 0:
        return s, s
    rho, weight = kernel_function(kernel).map(s.size)(s[None, :], delta)
    return np.asarray(rho.full()).ravel(), np.asarray(weight.full()).ravel()


def step(fns: ProblemFunctions, info: Information, x: np.ndarray) -> np.ndarray:
    """The Gauss-Newton step from ``x`` (manifold coordinates) on the directions the windows
    determine; the others (:func:`~nlp_calib.analysis.degeneracy.free_directions`) are left where
    they are: a start is brought to the data, where a drive's free directions are what a fit would
    find (away from the data, a free direction can lean into parameters the drive determines)."""
    R = scales(fns, np.asarray(x, dtype=float))
    lam, V = np.linalg.eigh(0.5 * (info.H + info.H.T) * np.outer(R, R))
    keep = ~free_directions(lam, info.n_windows, info.motion2) & (lam > 0)
    return np.asarray(-R * ((V[:, keep] / lam[keep]) @ (V[:, keep].T @ (R * info.g))))


def noise(
    fns: ProblemFunctions, logs: Sequence[Log], omega: np.ndarray, info: Information, at: str = "the start"
) -> tuple[float, str]:
    """The variance of a window's residual (``eᵀΩe`` per row) the pre-flight assumes: the larger of
    what the tracker's own scatter about its path gives (two poses per window) and the residuals'
    spread where ``info`` was evaluated (``at``, in words: a converged fit's, what the model misses
    beyond the tracker's noise), in words."""
    per_row = []
    for log in logs:
        # The tracker's scatter is the same all along: a stretch of the middle tells it.
        mid, half = log.n_records // 2, NOISE_RECORDS // 2
        part = log.select(max(0, mid - half), min(log.n_records, mid + half))
        signal, _ = fns.sensor.jump_signal(part)
        # The scatter about the chord between neighbours is √1.5 times a pose's own.
        per_row.append(chord_scatter(part.time_s, signal).floor / np.sqrt(1.5))
    sigma = np.nanmedian(np.array(per_row), axis=0)
    sigma = np.where(np.isfinite(sigma), sigma, 0.0)
    said = ", ".join(
        f"{1e3 * float(np.mean(sigma[list(g)])):.2g} {unit}"
        for g, unit in zip(fns.sensor.noise_groups, ("mm", "mrad"))
    )
    rows = np.asarray(omega, dtype=float)
    tracker = float(np.mean(rows * 2.0 * sigma[: rows.size] ** 2))
    if info.spread2 > tracker and tracker > 0.0:
        times = np.sqrt(info.spread2 / tracker)
        return info.spread2, (
            f"the residuals' spread at {at}, {times:.2g} times what the tracker's scatter about its "
            f"path ({said}) gives"
        )
    if info.spread2 > tracker:
        # Poses without noise, or repeated exactly where the tracker moves slowest (a tracker that
        # lost its target republishes its last pose): no ratio to a scatter of nothing.
        return (
            info.spread2,
            f"the residuals' spread at {at} (the tracker's scatter about its path reads {said})",
        )
    return max(tracker, 1e-18), f"the tracker's scatter about its path: {said}"


@dataclass(frozen=True)
class Standing:
    """Each free parameter's 1σ (its unit; inf: nothing holds it) and in reference units, which
    the drive leaves free (``undetermined``; ``bounded``: held only by its bounds) and, for each,
    the parameters it moves with in a free or weak direction."""

    names: tuple[str, ...]
    std: np.ndarray
    std_reference: np.ndarray
    reference: np.ndarray
    undetermined: np.ndarray
    bounded: np.ndarray
    partners: tuple[tuple[str, ...], ...]
    #: Which the run's verdict would call not determined: along a direction beyond the
    #: not-observable limit (:func:`~nlp_calib.analysis.observability.not_observable`).
    unobservable: np.ndarray
    #: The white noise's correlations of the parameters (NaN where a σ is not finite).
    correlation: np.ndarray | None = None
    #: The combinations of several parameters these σ leave loose (:func:`believed`), loosest first.
    together: tuple[WeakDirection, ...] = ()
    #: Each one's white-noise 1σ in the reference units of the run's observability (its
    #: ``std_reference``, whatever σ and precision ``std`` and ``reference`` become): what
    #: :func:`~nlp_calib.analysis.observability.needs_turns` reads, as the run reads it.
    white_reference: np.ndarray | None = None


def standing(
    fns: ProblemFunctions,
    info: Information,
    sigma2: float,
    values: np.ndarray,
    bounds_std: np.ndarray | None,
) -> Standing:
    """Each free parameter's standing on the windows whose information is ``info``, at the free
    parameters' ``values``, for residuals of variance ``sigma2`` (see the module docstring), in the
    reference units a run reads them in (:func:`~nlp_calib.analysis.degeneracy.scales`)."""
    names = fns.free
    R = scales(fns, values)
    found = directions(info.H, sigma2, R, info.n_windows, info.motion2)

    def free(lam: np.ndarray) -> np.ndarray:
        return free_directions(lam, info.n_windows, info.motion2)

    cov, bounded = white_covariance(info.H, sigma2, R, free, bounds_std)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    std = np.where(np.isfinite(np.diag(cov)), std, np.inf)
    Vf = found.V[:, found.free]
    undetermined = ((Vf**2).sum(axis=1) > 1e-3) | ~np.isfinite(std) | bounded
    weak_dirs = found.V[:, (1.0 / np.sqrt(np.maximum(found.lam, 1e-300)) > WEAK) & ~found.free]
    partners = []
    for i in range(len(names)):
        basis = Vf if undetermined[i] else weak_dirs
        partners.append(_coupled(names, basis, i))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    white = np.where(undetermined, np.inf, held_to(found))
    return Standing(
        names, std, std / R, R, undetermined, np.asarray(bounded), tuple(partners), not_observable(found),
        np.where(np.isfinite(corr), corr, np.nan), white_reference=white,
    )  # fmt: skip


def believed(st: Standing) -> Standing:
    """``st`` with the combinations of several parameters its σ leave loose: the white noise's
    correlations scaled to each σ over the precision it needs, the run's rule for a combination
    loose while each parameter passes alone (:func:`~nlp_calib.analysis.observability.scaled_directions`),
    over the parameters the drive determines."""
    keep = np.flatnonzero(np.isfinite(st.std_reference) & (st.std_reference > 0) & ~st.undetermined)
    if st.correlation is None or keep.size < 2:
        return st
    names = tuple(st.names[i] for i in keep)
    found = scaled_directions(names, st.correlation[np.ix_(keep, keep)], st.std_reference[keep])
    return replace(st, together=tuple(w for w in found if len(w.components) > 1))


def _coupled(names: tuple[str, ...], basis: np.ndarray, i: int) -> tuple[str, ...]:
    """The parameters that move with parameter ``i`` in the subspace ``basis`` spans."""
    if basis.shape[1] == 0:
        return ()
    P = basis @ basis.T
    d = np.sqrt(np.maximum(np.diag(P), 1e-300))
    if P[i, i] < 1e-3:
        return ()
    c = np.abs(P[i]) / (d[i] * d)
    return tuple(names[j] for j in np.flatnonzero((c > COUPLED) & (np.diag(P) > 1e-3)) if j != i)


def _cause(
    fns: ProblemFunctions, name: str, partners: Sequence[str], ex: Excitation | None, unturned: bool
) -> str:
    """What about the drive leaves ``name`` loose, where the excitation shows it ("" when nothing
    simple does); ``unturned``: it needs turns the drive lacks (:func:`_unturned`)."""
    model = fns.model
    if fns.layout.in_block(name, CLOCK):
        moved = ", ".join(p for p in partners if not fns.layout.in_block(p, CLOCK)) or "the other parameters"
        return f"a time shift of the encoders looks like a change of {moved} on this drive"
    turning = (*model.turning_params, *fns.sensor.turning)
    if ex is None or name not in turning:
        return ""
    if ex.heading_span_rad < MIN_TURNING:
        lacks = "never turns" if unturned else "turns little"
        return f"the drive {lacks} (the heading spans {ex.heading_span_rad:.2f} rad)"
    if min(ex.turned_left_rad, ex.turned_right_rad) < MIN_TURNING:
        side = "left" if ex.turned_left_rad >= ex.turned_right_rad else "right"
        return f"the drive turns only to the {side}"
    same = [r for r in (ex.radii_left_m, ex.radii_right_m) if r]
    if same and all(r[2] < 1.5 * r[0] for r in same):
        radii = " and ".join(f"{r[1]:.2g} m" for r in same)
        return f"every turn has about the same radius ({radii} each way)"
    return ""


def statuses(
    fns: ProblemFunctions,
    found: Standing,
    held: Mapping[str, str],
    units: Mapping[str, str],
    ex: Excitation | None,
) -> tuple[ParameterStatus, ...]:
    """Each parameter's standing in words: the held ones (``held``, with why) first, then the
    free ones in model order."""
    out = [
        ParameterStatus(
            name, NOT_DETERMINED, np.inf, np.inf, reference_scale(fns.model, fns.layout.key(name), 1.0),
            units.get(name, ""),
            (), f"{HELD_AT_START}: {why}", held=True,
        )
        for name, why in held.items()
    ]  # fmt: skip
    unturned = _unturned(fns, found, ex)
    for i, name in enumerate(found.names):
        ratio, partners = float(found.std_reference[i]), found.partners[i]
        loose = next((w for w in found.together if name in w.components), None)
        if loose is not None and not partners:
            partners = tuple(n for n in loose.components if n != name)
        if found.undetermined[i] or found.unobservable[i] or unturned[i]:
            status = NOT_DETERMINED
        else:
            status = WEAKLY if ratio > WEAK or loose is not None else DETERMINED
        words = [_cause(fns, name, partners, ex, bool(unturned[i]))] if status != DETERMINED else []
        if status == DETERMINED:
            words.append(_bends(fns, name, ex, ratio, float(found.reference[i])))
        if status == WEAKLY and ratio <= WEAK and loose is not None:
            words.append(_together(name, loose))
        elif status != DETERMINED:
            words.append(_trade(partners, bool(found.bounded[i]), found.undetermined[i]))
        out.append(
            ParameterStatus(
                name, status, float(found.std[i]), ratio, float(found.reference[i]), units.get(name, ""),
                partners, "; ".join(w for w in words if w),
            )
        )  # fmt: skip
    return tuple(out)


def _unturned(fns: ProblemFunctions, found: Standing, ex: Excitation | None) -> np.ndarray:
    """Which parameters need turns the drive lacks: the run's observability's rule
    (:func:`~nlp_calib.analysis.observability.needs_turns`) on the white σ both compute, so that the
    gate (which has no σ to believe) and the report refuse alike."""
    if ex is None:
        return np.zeros(len(found.names), dtype=bool)
    white = found.std_reference if found.white_reference is None else found.white_reference
    turning = (*fns.model.turning_params, *fns.sensor.turning)
    return needs_turns(turning, found.names, ex.heading_span_rad, white)


def _bends(fns: ProblemFunctions, name: str, ex: Excitation | None, ratio: float, needed: float) -> str:
    """The caveat of a turning parameter determined on a drive whose heading spans less than
    :data:`~nlp_calib.analysis.observability.MIN_TURNING` ("" elsewhere)."""
    turning = (*fns.model.turning_params, *fns.sensor.turning)
    if ex is None or name not in turning or not ex.heading_span_rad < MIN_TURNING:
        return ""
    return (
        f"the heading spans only {ex.heading_span_rad:.2f} rad, yet the drive's bends hold it to "
        f"{ratio:.3g}× the {needed:.2g} needed"
    )


def _together(name: str, w: WeakDirection) -> str:
    """Why ``name``, determined alone, is loose as part of the combination ``w``, in words."""
    others = ", ".join(n for n in w.components if n != name)
    return (
        f"it moves with {others}: one combination of them is known only to ±{w.std_reference:.3g}× the "
        "precision it needs (their σ, with the white noise's correlations), looser than each one's σ shows"
    )


def _trade(partners: Sequence[str], bounded: bool, free: bool) -> str:
    """How a loose parameter is loose, in words."""
    if not partners:
        return "the drive carries no information on it" if free else ""
    text = f"it trades off with {', '.join(partners)} (a change of one is undone by the others)"
    return text + ("; only its bounds hold it" if bounded else "")
