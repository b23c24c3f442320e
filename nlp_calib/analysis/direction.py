"""Whether forward and reverse driving tell the same story: separate fits compared in their σ.

A calibration fitted to forward-only windows and one fitted to reverse-only windows should agree
within their uncertainty. Each part's σ is the jackknife σ of blocks of that part alone (the whole
fit's σ would not do: its blocks mix both directions, so it contains the very disagreement under
test); the difference is judged against ``√(σ_forward² + σ_reverse²)``. A disagreement beyond
:data:`SIGNIFICANT` of that means the model misses something that depends on the direction of
travel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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


def compare(
    names: tuple[str, ...],
    forward: np.ndarray,
    reverse: np.ndarray,
    windows: tuple[int, int],
    std_forward: np.ndarray,
    std_reverse: np.ndarray,
    held: set[str],
) -> DirectionCheck:
    """The check of two part fits and their σ; parameters held in a part are not compared."""
    sigma = np.sqrt(std_forward**2 + std_reverse**2)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(sigma > 0, (forward - reverse) / sigma, np.nan)
    z = np.where([n in held for n in names], np.nan, z)
    return DirectionCheck(names=names, forward=forward, reverse=reverse, windows=windows, z=z)
