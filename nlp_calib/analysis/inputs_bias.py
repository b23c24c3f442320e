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
:class:`~nlp_calib.solvers.evaluation.NormalEquations`). ``∇T`` is taken by differences over one σ
of each free coordinate: ``T`` is smooth on that scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis.uncertainty import EndNoise, split_noise
from nlp_calib.solvers import ProblemEvaluator


def noise_share(
    evaluator: ProblemEvaluator, x: np.ndarray, weight: np.ndarray, noise: tuple[np.ndarray, np.ndarray]
) -> float:
    """``T(x) = Σ_w weight_w tr(Ω G_w V_w G_wᵀ)``: the inputs' expected share of the cost at ``x``
    (``noise``: the inputs' 1σ and which of them are counters, noise on their readings)."""
    std, counted = noise
    split = split_noise(np.asarray(std, dtype=float) ** 2, counted)
    fns, starts, stops = evaluator.fns, evaluator.data.starts, evaluator.data.stops
    total, ends = 0.0, None
    for w, sens in evaluator.sensitivities(x):
        if ends is None:
            n_int, n_in = evaluator.data.inputs.shape[1], fns.n_inputs
            D = sens.D if sens.D is not None else np.broadcast_to(np.eye(n_in), (n_int, n_in, n_in))
            ends = EndNoise(D, split)
        V = ends.between(starts[w], stops[w])
        rows = ((sens.de_dend @ V) * sens.de_dend).sum(axis=2)  # (windows, error rows)
        total += float(weight[w] @ (rows @ evaluator.omega))
    return total


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
    carry no noise or the normal matrix is singular). ``∇T`` by forward differences over one σ of
    each coordinate (``T`` is smooth on that scale: its curvature changes it by σ over the
    parameter's own scale)."""
    n = evaluator.fns.n_free
    none = BiasStep(x, np.zeros(n), np.full(n, np.inf))
    if not np.any(np.asarray(noise[0]) > 0) or n == 0:
        return none
    ne = evaluator.normal_equations(x)
    _, s, weight = evaluator.robust_terms(x)
    try:
        H_inv = np.linalg.inv(ne.H)
    except np.linalg.LinAlgError:
        return none
    dof = max(s.size * evaluator.fns.error_rows - n, 1)
    sigma = np.sqrt(np.clip(np.diag(H_inv), 0.0, None) * float(np.sum(weight * s)) / dof)
    if not np.all(np.isfinite(sigma) & (sigma > 0)):
        return none
    here = noise_share(evaluator, x, weight, noise)
    grad = np.array(
        [
            (noise_share(evaluator, evaluator.boxplus(x, h), weight, noise) - here) / h[i]
            for i, h in _steps(sigma)
        ]
    )
    return BiasStep(x, np.asarray(0.5 * H_inv @ grad), sigma)


def _steps(sigma: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """Each coordinate's step of one σ."""
    return [(i, np.where(np.arange(sigma.size) == i, sigma, 0.0)) for i in range(sigma.size)]
