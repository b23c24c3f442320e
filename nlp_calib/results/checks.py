"""What a run's checks found: cross-validation, the direction check, the tracker lag, observability.

The checks are computed by :mod:`nlp_calib.analysis` (refits, lag search, information matrix);
these records hold what they found, with the thresholds that decide how it reads.
"""

from __future__ import annotations

from dataclasses import dataclass

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


def believed_std(white: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """The σ to believe: the larger of the white-noise σ (a floor) and the jackknife σ."""
    return np.where(np.isfinite(blocked), np.fmax(white, blocked), white)


#: A difference beyond this many σ is reported as significant.
SIGNIFICANT = 3.0


@dataclass(frozen=True)
class DirectionCheck:
    """Forward-only and reverse-only estimates (model order), their windows, and the differences
    in units of their σ (NaN for parameters held in either part)."""

    names: tuple[str, ...]
    forward: np.ndarray
    reverse: np.ndarray
    windows: tuple[int, int]
    z: np.ndarray

    @property
    def worst(self) -> tuple[str, float]:
        """The parameter that disagrees most, and by how many σ."""
        if not np.any(np.isfinite(self.z)):
            return "", float("nan")
        i = int(np.nanargmax(np.abs(self.z)))
        return self.names[i], float(self.z[i])

    @property
    def significant(self) -> bool:
        return bool(np.nanmax(np.abs(self.z), initial=0.0) > SIGNIFICANT)

    @property
    def compared(self) -> bool:
        """Whether any parameter could be compared (a σ in both parts, held in neither)."""
        return bool(np.any(np.isfinite(self.z)))

    def words(self) -> str:
        """The verdict in words: agree within, disagree by, or could not compare (and why)."""
        if not self.compared:
            return (
                "could not be compared: no parameter has a σ in both parts (each part's σ needs at "
                "least 3 blocks with 20 or more windows of its driving)"
            )
        name, z = self.worst
        return (
            f"DISAGREE: {name} by {abs(z):.1f}σ"
            if self.significant
            else f"agree within {abs(z):.1f}σ ({name})"
        )

    def as_dict(self) -> dict[str, object]:
        return {
            "windows": {"forward": self.windows[0], "reverse": self.windows[1]},
            "forward": dict(zip(self.names, map(float, self.forward))),
            "reverse": dict(zip(self.names, map(float, self.reverse))),
            "difference_in_sigma": {
                n: (None if not np.isfinite(v) else float(v)) for n, v in zip(self.names, self.z)
            },
            "significant": self.significant,
        }


@dataclass(frozen=True)
class LagEstimate:
    """How the fitted tracker lag (s) was reached: the lags the encoders were re-sampled at in
    turn and the internal fit's cost at each, whether the last fit converged, and whether the lag
    ended on a bound of the searched range (then the true lag may lie beyond it, or the drive does
    not determine it)."""

    lag_s: float
    path_s: tuple[float, ...]
    costs: tuple[float, ...]
    at_edge: bool = False
    converged: bool = True

    def as_dict(self) -> dict[str, object]:
        return {
            "lag_s": self.lag_s,
            "path_s": list(self.path_s),
            "costs": [c if np.isfinite(c) else None for c in self.costs],
            "at_edge": self.at_edge,
            "converged": self.converged,
        }


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


#: A difference beyond this many σ (of the difference) is reported as a disagreement.
CONSISTENCY_SIGMAS = 4.0


@dataclass(frozen=True)
class Disagreement:
    """One log's own estimate of a parameter off the joint one by ``z`` σ."""

    log: str
    parameter: str
    own: float
    joint: float
    z: float


@dataclass(frozen=True)
class ConsistencyCheck:
    """Each log's own estimates (rows, model order) against the joint ones, and the differences
    in σ of the difference (NaN where a parameter is held in either fit or has no σ)."""

    names: tuple[str, ...]
    logs: tuple[str, ...]
    joint: np.ndarray
    own: np.ndarray
    z: np.ndarray

    @property
    def compared(self) -> bool:
        """Whether any parameter of any log could be compared."""
        return bool(np.any(np.isfinite(self.z)))

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
        with np.errstate(invalid="ignore"):
            where = np.argwhere(np.abs(self.z) > CONSISTENCY_SIGMAS)
        found = [self._at(int(i), int(j)) for i, j in where]
        return tuple(sorted(found, key=lambda d: -abs(d.z)))

    @property
    def significant(self) -> bool:
        return bool(self.disagreements)

    def _at(self, i: int, j: int) -> Disagreement:
        return Disagreement(
            self.logs[i], self.names[j], float(self.own[i, j]), float(self.joint[j]), float(self.z[i, j])
        )

    def words(self) -> str:
        """One line: which logs disagree on which parameters, that they agree, or that nothing
        could be compared."""
        if not self.compared:
            return (
                "each log's own fit could not be compared with the joint fit (no parameter with a σ in both)"
            )
        if not self.significant:
            w = self.worst
            assert w is not None
            return (
                f"each log's own fit agrees with the joint fit within {abs(w.z):.1f}σ "
                f"(largest: {w.parameter} in {w.log})"
            )
        worst = self.disagreements
        logs = sorted({d.log for d in worst}, key=self.logs.index)
        params = list(dict.fromkeys(d.parameter for d in worst))
        detail = "; ".join(
            f"{d.parameter} in {d.log}: {d.own:.6g} against {d.joint:.6g} jointly ({d.z:+.1f}σ)"
            for d in worst[:3]
        )
        return (
            f"the logs do not agree on one robot: {', '.join(params)} differ in {', '.join(logs)} beyond "
            f"{CONSISTENCY_SIGMAS:g}σ ({detail})"
        )

    def as_dict(self) -> dict[str, object]:
        return {
            "logs": list(self.logs),
            "joint": dict(zip(self.names, map(float, self.joint))),
            "own": {log: dict(zip(self.names, map(float, row))) for log, row in zip(self.logs, self.own)},
            "difference_in_sigma": {
                log: {n: (None if not np.isfinite(v) else float(v)) for n, v in zip(self.names, row)}
                for log, row in zip(self.logs, self.z)
            },
            "significant": self.significant,
        }


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
