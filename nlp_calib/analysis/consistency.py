"""Whether several logs tell the same story: each log's own fit against their joint fit, in σ.

A joint fit of several logs (``datasets:``) assumes one robot: one set of parameters explains
every log. Each log's own fit should then agree with the joint fit within their uncertainty. The
joint fit contains the log's own data, so the two are correlated: for estimates combined by
their information, ``var(own − joint) = σ_own² − σ_joint²`` (two logs: the difference to the
joint fit in these units is exactly the difference between the two logs in units of
``√(σ_a² + σ_b²)``). The σ are the honest ones (the larger of the white-noise and the block
jackknife σ), each estimated from ten blocks: their difference is unreliable where the joint σ
comes close to the log's own (a parameter the other logs barely inform, or joint blocks that
disagree among themselves), so the variance of the difference is taken as at least the log's
share ``σ_own² / n_logs`` (below what logs of equal information give, ``σ_own²·(1 − 1/n)``).

A difference beyond :data:`SIGNIFICANT` of that in any parameter of any log says the logs do
not come from one robot (or one of them is not what it seems): the joint result is then not to
be trusted, and the check names the parameter and the logs. The threshold allows for the many
comparisons (every parameter of every log) and for the jackknife σ being itself estimated from
ten blocks; the false-alarm rate it gives on pairs of simulated logs of one robot is measured by
``benchmarks/fault_study.py``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: A difference beyond this many σ (of the difference) is reported as a disagreement.
SIGNIFICANT = 4.0


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
        """Every difference beyond :data:`SIGNIFICANT`, the largest first."""
        with np.errstate(invalid="ignore"):
            where = np.argwhere(np.abs(self.z) > SIGNIFICANT)
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
            f"{SIGNIFICANT:g}σ ({detail})"
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


def compare_logs(
    names: tuple[str, ...],
    logs: Sequence[str],
    joint: np.ndarray,
    std_joint: np.ndarray,
    own: np.ndarray,
    std_own: np.ndarray,
    held: Sequence[set[str]] = (),
) -> ConsistencyCheck:
    """The check of each log's own estimates ``own`` (n_logs, n_params) with their σ ``std_own``
    against the joint estimates ``joint`` with σ ``std_joint``; parameters a log's fit (or the
    joint fit: ``held[i]`` for log i) held are not compared."""
    own, std_own = (
        np.atleast_2d(np.asarray(own, dtype=float)),
        np.atleast_2d(np.asarray(std_own, dtype=float)),
    )
    joint, std_joint = np.asarray(joint, dtype=float), np.asarray(std_joint, dtype=float)
    # The difference of two estimated variances is unreliable where the joint fit is barely more
    # certain than the log's own: never less than the log's share of its own variance.
    var = np.maximum(std_own**2 - std_joint[None, :] ** 2, std_own**2 / max(own.shape[0], 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(np.isfinite(var) & (var > 0), (own - joint[None, :]) / np.sqrt(var), np.nan)
    for i, h in enumerate(held):
        z[i, [n in h for n in names]] = np.nan
    return ConsistencyCheck(tuple(names), tuple(logs), joint, own, z)
