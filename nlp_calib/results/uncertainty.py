"""The white-noise covariance of an estimate (computed by :mod:`nlp_calib.analysis.uncertainty`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Stretch:
    """A stretch of the drive, records ``[first, stop)`` of the fit's windows (numbered from the
    fit's first record), without whose windows the rest leaves the parameters ``names`` free: they
    are determined by that stretch alone. ``shortfall``: the information the rest gives along its
    weakest direction over the floor that determines a direction (below 1); ``of``: how many
    stretches the drive was cut into; ``n_records``: the fit's records (several logs: every log's,
    end to end); ``span``: how many neighbouring stretches of those it takes."""

    first: int
    stop: int
    names: tuple[str, ...]
    shortfall: float
    of: int
    n_records: int
    span: int = 1

    def as_dict(self, offset: int = 0) -> dict[str, object]:
        """As result.json holds it, its records numbered from ``offset``."""
        return {
            "records": [offset + self.first, offset + self.stop],
            "parameters": list(self.names),
            "shortfall": self.shortfall,
            "stretches": self.span,
        }


@dataclass(frozen=True)
class Uncertainty:
    """Covariance of the free parameters (plain coordinates) and the noise it was built from.

    ``std`` and ``correlation`` cover all parameters in model order; fixed ones have std 0 and
    correlation 0 with the rest. ``noise`` holds the estimated 1σ of each source.
    """

    names: tuple[str, ...]
    free: tuple[str, ...]
    covariance: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    noise: dict[str, float]
    dof: int
    #: Free parameters the data leave undetermined, known only as well as the bounds of a
    #: parameter they move with allow (a tracker lag within its search).
    bounded: tuple[str, ...] = ()
    #: Each parameter's σ from the residuals' own scores where it exceeds ``std`` beyond its noise
    #: (an error of each window's own that the poses' noise, cancelling along a chain, does not
    #: carry), NaN elsewhere (None: not estimated).
    std_residuals: np.ndarray | None = None
    #: Each parameter's σ (the larger of ``std`` and ``std_residuals``) scaled by the Birge ratio
    #: where contiguous blocks of the drive, each estimating it alone, disagree beyond their own
    #: σ; NaN elsewhere (None: not estimated).
    std_block_scatter: np.ndarray | None = None
    #: The blocks' χ² about their weighted mean (row 0) and its degrees of freedom (row 1; 0 and
    #: NaN: not judged), per parameter.
    block_chi2: np.ndarray | None = None
    #: The stretches of the drive that alone determine a direction (see
    #: :mod:`nlp_calib.analysis.leverage`; empty: none, or not judged).
    stretches: tuple[Stretch, ...] = ()

    def residual_spread(self) -> np.ndarray:
        """:attr:`std_residuals`, NaN everywhere when it was not estimated: a spread the σ to
        believe takes in."""
        return np.full(len(self.names), np.nan) if self.std_residuals is None else self.std_residuals

    def block_spread(self) -> np.ndarray:
        """:attr:`std_block_scatter`, NaN everywhere when it was not estimated."""
        return np.full(len(self.names), np.nan) if self.std_block_scatter is None else self.std_block_scatter

    def spreads(self) -> list[np.ndarray]:
        """The spreads of the estimate's own residuals the σ to believe takes in beside the
        white-noise σ: the residuals' own σ and the blocks' disagreement."""
        return [self.residual_spread(), self.block_spread()]

    def std_dict(self) -> dict[str, float]:
        return {n: float(s) for n, s in zip(self.names, self.std)}
