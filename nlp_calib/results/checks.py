"""What a run's checks found: cross-validation, the direction check, the tracker lag, observability.

The checks are computed by :mod:`nlp_calib.analysis` (refits, lag search, information matrix);
these records hold what they found, with the thresholds that decide how it reads.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nlp_calib.results.figures import TrajectoryMetrics

#: With fewer converged folds than this the jackknife σ is not reported.
MIN_FOLDS = 5


@dataclass(frozen=True)
class Fold:
    """One fold: the held-out records ``[first, stop)``, the estimate without them and its scores
    on them (``heldout``), and the full fit's scores on the same records (``insample``: the same
    figure, the block's own data in the fit), so that the two read side by side."""

    first: int
    stop: int
    params: np.ndarray
    converged: bool
    heldout: TrajectoryMetrics | None
    insample: TrajectoryMetrics | None = None
    #: The data cost of the windows the fold left out: the fold's estimate's, then each other
    #: parameter set's it was asked to cost there (empty: not costed).
    costs: tuple[float, ...] = ()


def beyond_noise(std: np.ndarray, white: np.ndarray, k: int) -> np.ndarray:
    """``std``, a spread of ``k`` draws, where it exceeds the white-noise σ ``white`` by more than
    its own sampling noise explains (NaN elsewhere): of white noise alone it scatters as
    ``χ²(k − 1)``, so one beyond its 95 % point says errors the white σ does not count."""
    if k < 2:
        return np.full(np.shape(std), np.nan)
    with np.errstate(invalid="ignore"):
        return np.where(std > noise_factor(k) * np.asarray(white, dtype=float), std, np.nan)


def noise_factor(k: int) -> float:
    """How far a spread of ``k ≥ 2`` draws of white noise alone reaches over its σ at its 95 % point:
    √(χ²₀.₉₅(k − 1)/(k − 1))."""
    nu = k - 1.0
    # Wilson-Hilferty: χ²(ν)'s 95 % point within 0.2 % from ν = 3 on.
    return float(np.sqrt((1.0 - 2.0 / (9.0 * nu) + 1.6449 * np.sqrt(2.0 / (9.0 * nu))) ** 3))


@dataclass(frozen=True)
class CrossValidation:
    """The folds of a blocked cross-validation and the jackknife σ of every parameter (model order)."""

    names: tuple[str, ...]
    folds: tuple[Fold, ...]
    std: np.ndarray

    @property
    def converged(self) -> tuple[Fold, ...]:
        return tuple(f for f in self.folds if f.converged)

    @property
    def available(self) -> bool:
        return len(self.converged) >= MIN_FOLDS

    def spread(self) -> np.ndarray:
        """Largest minus smallest estimate of each parameter over the converged folds."""
        P = np.array([f.params for f in self.converged])
        return np.ptp(P, axis=0) if P.size else np.full(len(self.names), np.nan)

    def std_dict(self) -> dict[str, float]:
        return {n: float(s) for n, s in zip(self.names, self.std)}

    def beyond(self, white: np.ndarray) -> np.ndarray:
        """The jackknife σ where it exceeds the white-noise σ by more than its own sampling noise
        explains (NaN elsewhere): a jackknife of ``k`` folds of white noise alone scatters as
        ``χ²(k − 1)``, so one beyond its 95 % point says errors vary along the drive; below it,
        taking the larger of the two would only add that noise to the σ."""
        return beyond_noise(self.std, white, len(self.converged))

    def heldout_mean(self, figure: str) -> float:
        """The mean of one held-out figure over the folds, weighted by the records each scores."""
        return self._mean(figure, "heldout")

    def insample_mean(self, figure: str) -> float:
        """The same mean of the full fit's scores on the same blocks (:meth:`heldout_mean`'s pair)."""
        return self._mean(figure, "insample")

    def _mean(self, figure: str, which: str) -> float:
        values, weights = [], []
        for f in self.converged:
            m = getattr(f, which)
            if m is not None and f.heldout is not None:
                values.append(dict(m.figures())[figure])
                weights.append(m.records)
        ok = np.isfinite(values)
        return (
            float(np.average(np.array(values)[ok], weights=np.array(weights)[ok]))
            if np.any(ok)
            else float("nan")
        )


@dataclass(frozen=True)
class PivotSpread:
    """What each pivot of the drive says of the parameters on its own: one fit per pivot of the
    windows off every pivot and that pivot's (``params``, rows in the order of ``pivots``, each
    pivot's records ``[first, stop)``; the slipped pivots the fit left out among them), and the σ
    of the estimate their scatter about it gives (``std``, model order, see
    :func:`nlp_calib.analysis.pivots.pivots_std`)."""

    names: tuple[str, ...]
    pivots: tuple[tuple[int, int], ...]
    params: np.ndarray
    std: np.ndarray

    def beyond(self, white: np.ndarray) -> np.ndarray:
        """The pivots' σ where it exceeds the white-noise σ beyond its own noise (NaN elsewhere;
        :func:`beyond_noise` of its pivots)."""
        return beyond_noise(self.std, white, len(self.pivots))

    def as_dict(self) -> dict[str, Any]:
        return {
            "pivots": len(self.pivots),
            "std_pivots": {n: (float(v) if np.isfinite(v) else None) for n, v in zip(self.names, self.std)},
            "records": [list(p) for p in self.pivots],
        }


def believed_std(white: np.ndarray, *spreads: np.ndarray) -> np.ndarray:
    """The σ to believe: the largest of the white-noise σ (a floor) and each jackknife σ or spread
    (NaN where one has none)."""
    out = np.asarray(white, dtype=float)
    for spread in spreads:
        out = np.where(np.isfinite(spread), np.fmax(out, spread), out)
    return out


#: A difference beyond this many σ is reported as significant.
SIGNIFICANT = 3.0
#: A log's own estimate beyond this many σ (of its difference from the other logs') disagrees; a
#: forward-reverse difference beyond it widens the σ to believe.
CONSISTENCY_SIGMAS = 4.0


@dataclass(frozen=True)
class DirectionCheck:
    """Forward-only and reverse-only estimates (model order), their windows, and the differences
    in units of their σ (NaN for parameters held in either part)."""

    names: tuple[str, ...]
    forward: np.ndarray
    reverse: np.ndarray
    windows: tuple[int, int]
    z: np.ndarray
    #: Per parameter, the difference beyond which the parts cannot both describe one robot.
    apart: np.ndarray | None = None
    #: Per parameter, the precision a useful calibration needs (None: any significant difference).
    needed: np.ndarray | None = None

    @property
    def flagged(self) -> np.ndarray:
        """Per parameter: whether the parts disagree, beyond :data:`SIGNIFICANT` σ of the
        difference AND beyond the precision the calibration needs. Both, because each alone cries
        wolf: the σ of the difference goes to nothing on noise-free or very long data, where a
        re-sampling or clock-correction bias of microseconds is many σ; and a difference within its
        noise says nothing however large. The whole fit lies between the two parts' (driving with
        another mix of directions moves it by up to the difference), so a difference within the
        needed precision changes no use of the calibration. Not a quadrature sum of σ and the
        needed precision: that would let pass a clear fault up to three times the needed precision."""
        with np.errstate(invalid="ignore"):
            out = np.abs(self.z) > SIGNIFICANT
            if self.needed is not None:
                out &= np.abs(self.forward - self.reverse) > self.needed
        return out

    @property
    def worst(self) -> tuple[str, float]:
        """The parameter that disagrees most (of those :attr:`flagged`, when any), and by how many σ."""
        if not np.any(np.isfinite(self.z)):
            return "", float("nan")
        z = np.where(self.flagged, self.z, np.nan) if self.significant else self.z
        i = int(np.nanargmax(np.abs(z)))
        return self.names[i], float(self.z[i])

    @property
    def significant(self) -> bool:
        """Whether any parameter is :attr:`flagged`."""
        return bool(np.any(self.flagged))

    @property
    def compared(self) -> bool:
        """Whether any parameter could be compared (a σ in both parts, held in neither)."""
        return bool(np.any(np.isfinite(self.z)))

    def spread(self) -> np.ndarray:
        """Half the forward-reverse difference beyond its noise, ``√(Δ² − σ_Δ²)/2``, of each
        parameter that differs beyond :data:`CONSISTENCY_SIGMAS` σ but within :attr:`apart` (NaN
        elsewhere): driving with another mix of directions may land anywhere between the two, so
        the σ to believe covers it. An effect size, not a variance estimate: taken in only where
        the difference is clear (a 3σ difference on direction-free truth is rare but not unheard
        of) and could be one robot's (beyond, a part's own fit is in question)."""
        diff = np.abs(self.forward - self.reverse)
        limit = np.inf if self.apart is None else self.apart
        with np.errstate(invalid="ignore", divide="ignore"):
            clear = (np.abs(self.z) > CONSISTENCY_SIGMAS) & (diff <= limit)
            noise = diff / np.abs(self.z)
        return np.where(clear, 0.5 * np.sqrt(np.clip(diff**2 - noise**2, 0.0, None)), np.nan)

    def as_dict(self) -> dict[str, object]:
        return {
            "windows": {"forward": self.windows[0], "reverse": self.windows[1]},
            "forward": dict(zip(self.names, map(float, self.forward))),
            "reverse": dict(zip(self.names, map(float, self.reverse))),
            "difference_in_sigma": {
                n: (None if not np.isfinite(v) else float(v)) for n, v in zip(self.names, self.z)
            },
            "needed": None if self.needed is None else dict(zip(self.names, map(float, self.needed))),
            "significant": self.significant,
        }


@dataclass(frozen=True)
class LagEstimate:
    """How the fitted tracker lag (s) was reached: the lags the encoders were re-sampled at in
    turn and the internal fit's cost at each, whether the last fit converged, and whether the lag
    ended on a bound of the searched range (then the true lag may lie beyond it, or the drive does
    not determine it). ``profile_s`` and ``profile_costs``: the cost over the search at the
    settled fit's other parameters (the lags and the cost at each), from which the fit started in
    each valley; ``other``: a second valley of comparable cost, ``(its lag, its fitted cost, the
    kept lag's fitted cost)`` (empty: none), the lag then ambiguous between the two. ``beside_s``:
    a second sensor's clock offset over the reference's the encoders were read at for its records
    (a gyro's beside the reference; None: one clock)."""

    lag_s: float
    path_s: tuple[float, ...]
    costs: tuple[float, ...]
    at_edge: bool = False
    converged: bool = True
    profile_s: tuple[float, ...] = ()
    profile_costs: tuple[float, ...] = ()
    other: tuple[float, ...] = ()
    beside_s: float | None = None
    returned: float | None = None

    @property
    def loose(self) -> bool:
        """Whether the drive does not determine the lag: fits re-sampled off it stay near where they
        were re-sampled (:attr:`returned` below :data:`RETURNS`), so its white-noise σ is no error."""
        return self.returned is not None and self.returned < RETURNS

    def returned_std(self, white: float) -> float:
        """The σ of a lag whose fits re-sampled off it take back only a share of the offset beyond
        their noise (:data:`SHORT`): its white-noise σ ``white`` over that share. The settled lag is
        where the fitted lag meets the re-sampled one, a root the noise of each fit moves by that
        noise over the share taken back; the white σ also counts the noise of the rates at the
        windows' ends as the lag's information (errors in the variables). NaN elsewhere."""
        share = self.returned
        if share is None or not RETURNS <= share < SHORT:
            return float("nan")
        return white / share

    @property
    def ambiguous(self) -> bool:
        """Whether a second valley of comparable cost leaves the lag between two values."""
        return len(self.other) == 3

    @property
    def pinned(self) -> bool:
        """Whether the lag is a held value, not a fitted one: on the search's edge, where no fit
        converged (held where the encoders were read), or not determined by the drive (:attr:`loose`:
        held where the fits settled)."""
        return self.at_edge or not self.converged or self.loose

    @property
    def held_reason(self) -> str:
        """Why a :attr:`pinned` lag is held with no σ, in a few words (every output's, the figure's
        and the terminal's; "" when it is fitted)."""
        if not self.converged:
            return "held where the encoders were read"
        if self.at_edge:
            return "pinned on the edge of alignment.search"
        return "not determined by this drive" if self.loose else ""

    @property
    def held_why(self) -> str:
        """:attr:`held_reason` with what it rests on, as the hand-off files state it."""
        if not self.converged:
            return f"{self.held_reason}: no fit converged at any lag in alignment.search"
        if self.at_edge:
            return f"{self.held_reason}: the data put the lag there or beyond"
        if self.loose:
            share = 100.0 * (self.returned or 0.0)
            return (
                f"{self.held_reason}: held where the fits settled (fits re-sampled off it take back "
                f"{share:.0f} % of the offset)"
            )
        return ""

    def as_dict(self) -> dict[str, object]:
        return {
            "lag_s": self.lag_s,
            "path_s": list(self.path_s),
            "costs": [c if np.isfinite(c) else None for c in self.costs],
            "at_edge": self.at_edge,
            "converged": self.converged,
            "profile_s": list(self.profile_s),
            "profile_costs": [c if np.isfinite(c) else None for c in self.profile_costs],
            "other": list(self.other),
            "returned": self.returned,
        }


#: The alignment checks a settled lag by fits on the encoders re-sampled this many of its
#: white-noise σ either side of it: each should take the offset back.
RETURN_SIGMAS = 8.0
#: A fitted lag whose fits, re-sampled off it, take back less than this share of the offset (2 of
#: its white σ: no more than their own noise) is not determined by the drive (:attr:`LagEstimate.loose`).
RETURNS = 0.25
#: The share taken back where the lag is determined scatters about 1 by 1/(√2·RETURN_SIGMAS) (each
#: side's fit by its white σ); below 1 by more than its 95 % point (1.645 of that), the lag's σ is
#: its white σ over the share (:meth:`LagEstimate.returned_std`).
SHORT = 1.0 - 1.645 / (np.sqrt(2.0) * RETURN_SIGMAS)


@dataclass(frozen=True)
class LagEffect:
    """How the other parameters move with a time offset ``lag`` on this drive: each one's change per
    second of it along their joint uncertainty (the covariance's regression), for the parameters
    correlated with it by :data:`LAG_EFFECT_CORRELATION` or more."""

    lag: str
    per_second: dict[str, float]


#: Parameters correlated with a lag by at least this much are said to move with it.
LAG_EFFECT_CORRELATION = 0.3


#: A direction with 1σ beyond this many reference units is weakly observable...
WEAK = 5.0
#: ...and beyond this many, not observable.
NOT_OBSERVABLE = 100.0


@dataclass(frozen=True)
class WeakDirection:
    """A poorly determined combination of parameters and its 1σ in reference units."""

    std_reference: float
    components: dict[str, float]

    def words(self) -> str:
        names = sorted(self.components, key=lambda n: -abs(self.components[n]))
        if self.std_reference > NOT_OBSERVABLE:
            verb = "is" if len(names) == 1 else "are"
            return f"{', '.join(names)} {verb} not observable from this log"
        if len(names) == 1:
            return f"{names[0]} is only weakly observable"
        return f"{', '.join(names)} are only weakly observable apart (one combination of them is loose)"


@dataclass(frozen=True)
class Observability:
    """Condition of the information matrix, weak directions and excitation warnings."""

    condition_number: float
    std_reference: dict[str, float]
    weak: tuple[WeakDirection, ...]
    heading_range_rad: float
    warnings: tuple[str, ...]

    def as_dict(self) -> dict[str, object]:
        return {
            "condition_number": self.condition_number,
            "std_in_reference_units": self.std_reference,
            "weak_directions": [
                {"std_in_reference_units": w.std_reference, "components": w.components} for w in self.weak
            ],
            "heading_range_rad": self.heading_range_rad,
            "warnings": list(self.warnings),
        }


@dataclass(frozen=True)
class Disagreement:
    """One log's own estimate of a parameter off the other logs' by ``z`` σ of the difference."""

    log: str
    parameter: str
    own: float
    others: float
    z: float


@dataclass(frozen=True)
class ConsistencyCheck:
    """Each log's own estimates (rows, model order) against those of the other logs fitted together
    (each log left out of the joint fit in turn), on the parameters the log determines on its own.

    ``z``: the differences in σ of the difference, both sides' honest σ (NaN where the log does not
    determine a parameter, or where either side has no σ). ``apart``: per parameter, the difference
    beyond which two sets of logs cannot be one robot (the loosest a calibration is said to be known
    to: :data:`WEAK` times the precision it needs). A difference beyond :data:`SIGNIFICANT` σ but
    within ``apart`` is a model limit (the parameter moves with the driving); beyond
    :data:`CONSISTENCY_SIGMAS` σ and ``apart``, the logs are not one robot's."""

    names: tuple[str, ...]
    logs: tuple[str, ...]
    joint: np.ndarray
    own: np.ndarray
    others: np.ndarray
    z: np.ndarray
    apart: np.ndarray
    #: Each parameter's unit (model order; empty: not known).
    units: tuple[str, ...] = ()

    @property
    def compared(self) -> bool:
        """Whether any parameter of any log could be compared."""
        return bool(np.any(np.isfinite(self.z)))

    def _beyond(self, sigmas: float) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            return np.abs(self.z) > sigmas

    @property
    def worst(self) -> Disagreement | None:
        """The largest difference, or None when nothing could be compared."""
        if not self.compared:
            return None
        i, j = np.unravel_index(int(np.nanargmax(np.abs(self.z))), self.z.shape)
        return self._at(int(i), int(j))

    @property
    def disagreements(self) -> tuple[Disagreement, ...]:
        """Every difference beyond :data:`CONSISTENCY_SIGMAS`, the largest first."""
        return self._listed(self._beyond(CONSISTENCY_SIGMAS))

    @property
    def different(self) -> tuple[Disagreement, ...]:
        """The disagreements also beyond :attr:`apart`: no one robot gives both."""
        far = np.abs(self.own - self.others) > self.apart[None, :]
        return self._listed(self._beyond(CONSISTENCY_SIGMAS) & far)

    @property
    def significant(self) -> bool:
        """Whether the logs are not one robot's (see :attr:`different`)."""
        return bool(self.different)

    @property
    def moved(self) -> np.ndarray:
        """Per parameter: whether some log's own estimate differs from the others' beyond
        :data:`SIGNIFICANT` σ (the parameter moves with the driving: a model limit)."""
        return np.any(self._beyond(SIGNIFICANT), axis=0)

    def _listed(self, where: np.ndarray) -> tuple[Disagreement, ...]:
        found = [self._at(int(i), int(j)) for i, j in np.argwhere(where)]
        return tuple(sorted(found, key=lambda d: -abs(d.z)))

    def _at(self, i: int, j: int) -> Disagreement:
        return Disagreement(
            self.logs[i], self.names[j], float(self.own[i, j]), float(self.others[i, j]), float(self.z[i, j])
        )

    def of_log(self, log: str) -> ConsistencyCheck:
        """The same check on one log's rows alone (several where entries select parts of one file)."""
        i = [k for k, name in enumerate(self.logs) if name == log]
        logs = tuple(self.logs[k] for k in i)
        return ConsistencyCheck(
            self.names, logs, self.joint, self.own[i], self.others[i], self.z[i], self.apart, self.units
        )

    def as_dict(self) -> dict[str, object]:
        def row(values: np.ndarray) -> dict[str, float | None]:
            return {n: (None if not np.isfinite(v) else float(v)) for n, v in zip(self.names, values)}

        return {
            "logs": list(self.logs),
            "joint": dict(zip(self.names, map(float, self.joint))),
            "own": {log: row(r) for log, r in zip(self.logs, self.own)},
            "others": {log: row(r) for log, r in zip(self.logs, self.others)},
            "difference_in_sigma": {log: row(r) for log, r in zip(self.logs, self.z)},
            "apart": row(self.apart),
            "moved": [n for n, m in zip(self.names, self.moved) if m],
            "significant": self.significant,
        }


#: A fit beats another parameter set, or does worse, when their held-out costs differ by this many
#: standard errors (over the cross-validation folds).
BEATS = 2.0


@dataclass(frozen=True)
class CostComparison:
    """The fit against another parameter set (``against``: its start, or the robot's nominal
    values) by what the reference measures well: the objective, in the reference's own noise.

    ``heldout``: per converged cross-validation fold, the other set's and the fold's estimate's
    cost on the windows the fold left out (``(folds, 2)``); ``insample``: the other set's and the
    fit's data cost on every window (no priors)."""

    against: str
    heldout: np.ndarray
    insample: tuple[float, float]

    @property
    def gain_sigmas(self) -> float:
        """The mean held-out cost the fit saves over the other set, in standard errors of that mean
        over the folds (positive: the fit does better; NaN with fewer than 3 folds)."""
        d = self.heldout[:, 0] - self.heldout[:, 1] if self.heldout.size else np.zeros(0)
        d = d[np.isfinite(d)]
        if d.size < 3:
            return float("nan")
        se = float(np.std(d, ddof=1)) / np.sqrt(d.size)
        mean = float(np.mean(d))
        return mean / se if se > 0 else float(np.sign(mean) * np.inf if mean else 0.0)

    @property
    def outcome(self) -> str:
        """``better``, ``worse`` or ``same``: held out when the folds allow (beyond :data:`BEATS`
        standard errors), else in sample (the fit's data cost above the other set's is worse)."""
        t = self.gain_sigmas
        if not np.isnan(t):
            return "better" if t > BEATS else "worse" if t < -BEATS else "same"
        other, fit = self.insample
        return "worse" if fit > other * (1 + 1e-9) + 1e-300 else "better" if fit < other else "same"

    def detail(self) -> str:
        """The figure that decided :attr:`outcome`, in words."""
        t = self.gain_sigmas
        if not np.isnan(t):
            way = "lower" if t > 0 else "higher"
            return (
                f"on held-out data (its residual cost {way} by {abs(t):.1f} standard errors over "
                f"{self.heldout.shape[0]} folds)"
            )
        other, fit = self.insample
        return f"(data cost {fit:.4g} against {other:.4g})"

    def words(self) -> str:
        """How the fit compares with the other set, with the figure that decided it."""
        how = {"better": "better than", "worse": "worse than", "same": "within the noise of"}[self.outcome]
        return f"{how} {self.against} {self.detail()}"


@dataclass(frozen=True)
class NominalCheck:
    """The robot's nominal values where a source knows them (``values``, from ``source``), scored
    like the fit: the set scored (``params``, model order) is nominal where known and the fit's
    estimate elsewhere, so what it measures is what calibrating the known values gained."""

    values: Mapping[str, float]
    source: str
    params: np.ndarray
    metrics: TrajectoryMetrics
    cost: CostComparison | None = None

    def gain(self, ours: TrajectoryMetrics) -> str:
        """The fit's gain over the nominal robot in words (segment ATE on this run's records)."""
        base, mine = self.metrics.segment_ate.mean, ours.segment_ate.mean
        if not (np.isfinite(base) and np.isfinite(mine)):
            return f"the nominal robot ({self.source}) could not be scored"
        figures = f"segment ATE {mine:.3g} m against {base:.3g} m with the nominal values ({self.source})"
        if mine >= base:
            return f"no closer to the tracker than the nominal robot: {figures}"
        return f"{base / max(mine, 1e-12):.2g}× closer to the tracker than the nominal robot: {figures}"


#: Beyond this many σ from the simulator's truth, an estimate is called off in the words.
TRUTH_SIGMAS = 3.0


@dataclass(frozen=True)
class TruthCheck:
    """The estimate against a simulated log's known truth (the truth file beside the log):
    ``error`` = estimate − truth and ``z`` = that in the σ to believe, per parameter; held
    parameters (no σ) have a ``z`` of nan."""

    path: str
    solver: str
    names: tuple[str, ...]
    truth: np.ndarray
    error: np.ndarray
    z: np.ndarray

    def words(self) -> str:
        """``"estimate − truth within 1.3σ (largest: <name> +1.3σ)"``, or which are off."""
        z = np.where(np.isfinite(self.z), self.z, 0.0)
        if not np.any(np.isfinite(self.z)):
            return "estimate − truth could not be put in σ (no parameter has one)"
        k = int(np.argmax(np.abs(z)))
        off = [f"{n} {v:+.1f}σ" for n, v in zip(self.names, z) if abs(v) > TRUTH_SIGMAS]
        if off:
            return f"estimate − truth beyond {TRUTH_SIGMAS:g}σ for {', '.join(off)}"
        return f"estimate − truth within {abs(z[k]):.1f}σ (largest: {self.names[k]} {z[k]:+.1f}σ)"


#: A plug-in check's levels: nothing against the calibration, a caveat the verdict names, or a
#: reason the estimate is not to be used (the verdict is NOT USABLE).
FINE = "fine"
CAVEAT = "caveat"
UNUSABLE = "unusable"


@dataclass(frozen=True)
class CheckResult:
    """What a plug-in check found, as one generic record every check stores as (so a new check
    needs no record, reader or wording of its own elsewhere): its registry ``name``, its
    ``level`` (:data:`FINE`, or :data:`CAVEAT`: the verdict names it), its one wording (``words``:
    what the terminal, the report and the summary say, after its name), further lines
    (``details``), what it refers to (``about``: a file, a solver, by name) and what it measured
    (``table``: columns of values by parameter or item). At :data:`CAVEAT` or :data:`UNUSABLE`,
    the verdict names ``caveat`` (its words when empty) and ``concerns``, each parameter it puts in
    doubt with why; ``how``: how it measured, which the report adds to its sentence;
    ``section``: the report's own section for it (its title, then lines), where a table of what it
    found is too long for one paragraph; ``record``: what result.json holds under its name (JSON
    types; None: nothing); ``caveats``: further caveats, each a reason of the verdict of its own."""

    name: str
    level: str
    words: str
    details: tuple[str, ...] = ()
    about: Mapping[str, str] = field(default_factory=dict)
    table: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    caveat: str = ""
    concerns: Mapping[str, str] = field(default_factory=dict)
    how: str = ""
    section: tuple[str, ...] = ()
    record: Any = None
    caveats: tuple[str, ...] = ()

    def lines(self) -> list[str]:
        """Its name and words, then its details indented: the terminal's lines."""
        return [f"{self.name}: {self.words}", *(f"  {d}" for d in self.details)]

    def sentence(self) -> str:
        """Its words and details as one sentence, then how it measured: the report's paragraph."""
        said = self.words + (": " + "; ".join(self.details) if self.details else "")
        return said[0].upper() + said[1:] + "." + (f" {self.how}" if self.how else "")

    @property
    def reason(self) -> str:
        """What the verdict says of it first, at :data:`CAVEAT` or :data:`UNUSABLE`."""
        return self.caveat or self.words

    @property
    def reasons(self) -> tuple[str, ...]:
        """Everything the verdict says of it, at :data:`CAVEAT` or :data:`UNUSABLE`."""
        return (self.reason, *self.caveats)


def truth_view(result: CheckResult | None) -> TruthCheck | None:
    """The truth check's result as its figures (:class:`TruthCheck`), or None."""
    if result is None:
        return None
    names = tuple(result.table["truth"])
    column = lambda key: np.array([result.table[key][n] for n in names], dtype=float)  # noqa: E731
    return TruthCheck(
        result.about["file"], result.about["solver"], names, column("truth"), column("error"),
        column("error_in_sigma"),
    )  # fmt: skip
