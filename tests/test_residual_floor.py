"""The σ never below what the fit's own residuals give it (nlp_calib.analysis.residual_floor).

A chain of windows each measuring the offset θ between consecutive poses, ``z_{u+1} − z_u = θ``:
its estimate is the mean increment. White noise on the poses telescopes (the estimate's variance
is ``2σ²/W²``, the noise model's); an error of each window's own does not (``σ²/W``). Both the
residuals' own variance and its noise are checked against these exact values.
"""

from __future__ import annotations

import numpy as np
import pytest

from nlp_calib.analysis.residual_floor import ScoreRows, beyond

W = 2000


def _chain(own: float, pose: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The residuals of the fitted chain, and its windows' first and last records."""
    rng = np.random.default_rng(seed)
    n = rng.normal(0.0, pose, W + 1)
    e = np.diff(n) + rng.normal(0.0, own, W)
    starts = np.arange(W)
    return e - e.mean(), starts, starts + 1


def _residuals_variance(
    e: np.ndarray, starts: np.ndarray, stops: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    rows = ScoreRows(starts, stops, 1)
    rows.add(slice(0, W), np.ones((W, 1, 1)), e[None, :], np.ones(1), np.ones(W))
    found = rows.variances(lambda meat: meat / W**2)  # H = W: the covariance H⁻¹·S·H⁻¹
    assert found is not None
    return found


def test_an_error_of_each_windows_own_raises_the_noise_models_sigma_to_its_own() -> None:
    e, a, b = _chain(own=1.0, pose=0.0, seed=4971)
    # The noise model reads the residuals' variance (1) as the poses' (1/2 each), which cancels.
    model = np.array([[2 * 0.5 / W**2]])
    std = beyond(model, _residuals_variance(e, a, b))
    assert abs(std[0] ** 2 / (1.0 / W) - 1) < 0.2  # the exact σ²/W, within the estimate's noise


def test_the_poses_own_noise_is_left_to_the_noise_model() -> None:
    """Under white pose noise the residuals' variance is unbiased for the model's (a sum of
    cancelling terms: within three standard errors over the draws) and rarely beyond its noise
    (one-sided 95 %)."""
    exact = 2 * 0.5**2 / W**2
    found = [_residuals_variance(*_chain(own=0.0, pose=0.5, seed=s)) for s in range(4971, 5011)]
    var = np.array([v[0] for v, _ in found])
    assert abs(var.mean() - exact) < 3 * var.std(ddof=1) / np.sqrt(var.size)
    raised = sum(bool(np.isfinite(beyond(np.array([[exact]]), f)[0])) for f in found)
    assert raised <= 5, raised


def test_too_few_windows_to_judge_leave_the_sigma_alone() -> None:
    rows = ScoreRows(np.arange(10), np.arange(10) + 5, 1)
    assert rows.variances(lambda meat: meat) is None
    assert np.isnan(beyond(np.array([[1.0]]), None)).all()


def test_windows_added_a_block_at_a_time_give_the_meats_of_all_at_once() -> None:
    """The uncertainty streams its windows in blocks: windows of three records each (each shares
    records with the two before and after it) added in uneven blocks give the batches' meats of
    every window added at once, and a block out of order is refused."""
    rng = np.random.default_rng(3)
    starts = np.arange(W)
    stops, J = starts + 2, rng.normal(size=(W, 1, 2))
    e = rng.normal(size=(1, W))
    whole = ScoreRows(starts, stops, 2)
    whole.add(slice(0, W), J, e, np.ones(1), np.ones(W))
    parts = ScoreRows(starts, stops, 2)
    for lo, hi in ((0, 7), (7, 700), (700, 701), (701, W)):
        parts.add(slice(lo, hi), J[lo:hi], e[:, lo:hi], np.ones(1), np.ones(hi - lo))
    np.testing.assert_allclose(parts.meats, whole.meats, rtol=1e-12, atol=1e-12 * np.abs(whole.meats).max())
    # Each batch's score and information, from the windows' own (independent sums).
    batch = np.searchsorted(whole.edges, starts, side="right") - 1
    score = np.array(
        [(J[batch == k, 0] * e[0, batch == k, None]).sum(axis=0) for k in range(batch.max() + 1)]
    )
    info = np.array([J[batch == k, 0].T @ J[batch == k, 0] for k in range(batch.max() + 1)])
    np.testing.assert_allclose(parts.scores, score, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(parts.information, info, rtol=1e-12)
    assert whole.meats.shape[0] >= 5 and parts.variances(lambda m: m) is not None
    late = ScoreRows(starts, stops, 2)
    with pytest.raises(ValueError, match="out of order"):
        late.add(slice(7, W), J[7:], e[:, 7:], np.ones(1), np.ones(W - 7))
