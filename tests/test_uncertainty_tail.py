"""Which windows beyond a robust kernel's threshold the noise explains (nlp_calib.analysis.uncertainty)."""

from __future__ import annotations

import numpy as np
import pytest

from nlp_calib.analysis.uncertainty import EXPLAINED_Z, _Window, chi2_point


@pytest.mark.parametrize(("k", "point"), [(1, 10.828), (3, 16.266), (6, 22.458), (9, 27.877)])
def test_the_chi_square_point_is_the_tables(k: int, point: float) -> None:
    """χ²(k)'s 99.9 % points as the tables give them (Wilson-Hilferty: within 4 % from k = 1 on)."""
    assert float(chi2_point(np.array([k]), EXPLAINED_Z)[0]) == pytest.approx(point, rel=0.04)


def test_a_window_is_explained_by_its_rows_noise_not_by_the_kernels_threshold() -> None:
    """Six rows of unit noise (Ω 1): a squared residual of 12 is the noise's (beyond δ = 3, within
    χ²(6)'s 99.9 % point), one of 30 is not; with the noise's variance four times larger, 30 is too.
    Rows of no noise (another sensor's) count for nothing."""
    rows = 9
    coef = np.zeros((3, rows, 2))
    coef[:, :6, 0] = 1.0  # six rows of the first group's noise, three of the other's (none)
    e2 = np.zeros((3, rows))
    e2[0, :6], e2[1, :6], e2[2, :6] = 2.0, 5.0, 5.0
    window = _Window(np.arange(3), coef, np.zeros((3, rows)), e2, np.zeros((3, 4)))
    omega = np.ones(rows)
    assert window.explained(np.array([1.0, 0.0]), omega).tolist() == [True, False, False]
    assert window.explained(np.array([4.0, 0.0]), omega).tolist() == [True, True, True]
    # Noise on rows of unequal weight: fewer effective degrees of freedom (1.1), a wider tail: 60
    # lies beyond six equal rows' point (10.5 × 22.46 / 6 = 39) but within this one's (about 111).
    unequal = np.ones(rows)
    unequal[0] = 100.0
    e2_one = np.zeros((1, rows))
    e2_one[0, 0] = 0.6  # 60 in Ω's units, on the heavily weighted row
    one = _Window(np.arange(1), coef[:1], np.zeros((1, rows)), e2_one, np.zeros((1, 4)))
    assert one.explained(np.array([0.1, 0.0]), unequal).tolist() == [True]
