"""The base motion a window's residual compares with the tracker, and the two places it comes from.

A window of records ``a < b`` predicts the base-link motion ``M = Δ_a ⋯ Δ_{b-1}`` (``Δ_j`` the
model's increment over interval ``j``). The residual needs ``M`` as a function of a perturbation
``h`` of the free parameters, to first order (Jacobians, normal equations) or second (IPOPT's
exact Hessian); how that is obtained is the only difference between the two sources, and the rest
of the problem is written once on top of :class:`MotionSymbols`:

- **direct** (``H = 1``): the window is one interval; its motion data are that interval's inputs
  ``u`` and ``M = Δ(k(x + h), u)``, differentiated directly.
- **prefix** (``H > 1``): the prefix poses ``P_j = Δ_0 ⋯ Δ_{j-1}`` are integrated once per
  evaluation by a scan over the intervals (:func:`prefix_step`) as Taylor jets in the free
  kinematic parameters ``k``: the pose, ``∂P/∂k`` and, for order 2, the upper triangle of each
  component's ``∂²P/∂k²``. A window's motion data are the jets of ``P_a`` and ``P_b``, and
  ``M = P_a(h)⁻¹·P_b(h)`` with ``P(h)`` the jet's Taylor polynomial: a window of any length costs
  one ``between``, to any order. Any pair ``a < b`` is a window, so dropped windows, unequal
  lengths and several logs laid end to end need nothing special.

For the noise propagation the motion also depends on its end: ``u`` itself (direct), or a left
perturbation ``P_b → ξ·P_b`` (prefix), which :func:`interval_sensitivity` links to each interval's
inputs: ``∂(ξ·P_b)/∂u_j`` is the same for every ``b > j``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca

from nlp_calib.models.base import KinematicModel
from nlp_calib.symbolic import se2

_CSE = {"cse": True}
#: Inputs of the scans' step Functions.
STEP_INPUTS = ["state", "x", "x_fixed", "u"]


@functools.cache
def pairs(n: int) -> tuple[tuple[int, int], ...]:
    """The upper triangle's ``(i, j)``, column by column (how second derivatives are stored)."""
    return tuple((i, j) for j in range(n) for i in range(j + 1))


def jet_rows(n: int, order: int) -> int:
    """Rows of a pose's jet of ``order`` in ``n`` parameters: value, Jacobian, Hessians' upper triangles."""
    return 3 + (3 * n if order >= 1 else 0) + (3 * len(pairs(n)) if order >= 2 else 0)


def jet_pose(jet: ca.SX, delta: ca.SX, order: int) -> ca.SX:
    """The jet's Taylor polynomial ``P(δ)``."""
    n = delta.numel()
    P = jet[0:3]
    if order >= 1:
        P = P + ca.mtimes(ca.reshape(jet[3 : 3 + 3 * n], 3, n), delta)
    if order >= 2:
        base = 3 + 3 * n
        for p, (i, j) in enumerate(pairs(n)):
            coef = 0.5 if i == j else 1.0
            P = P + coef * delta[i] * delta[j] * jet[base + 3 * p : base + 3 * p + 3]
    return P


def jet_of(P: ca.SX, delta: ca.SX, order: int) -> ca.SX:
    """The jet of ``P(δ)`` at ``δ = 0``."""
    n = delta.numel()
    parts = [P]
    if order >= 1:
        parts.append(ca.reshape(ca.jacobian(P, delta), 3 * n, 1))
    if order >= 2:
        hess = [ca.hessian(P[c], delta)[0] for c in range(3)]
        parts += [ca.vertcat(*[hess[c][i, j] for c in range(3)]) for i, j in pairs(n)]
    return ca.substitute(ca.densify(ca.vertcat(*parts)), delta, ca.DM.zeros(n))


def perturbed(x: ca.SX, h: ca.SX, columns: list[int]) -> ca.SX:
    """``x`` with ``h`` added to the entries at ``columns``."""
    out = ca.SX(x)
    for j, col in enumerate(columns):
        out[col] = x[col] + h[j]
    return out


@dataclass(frozen=True)
class MotionSymbols:
    """A window's base motion ``M`` as an expression of its mapped motion data ``data``, of the
    perturbation ``h`` of the free parameters and of ``end`` (the motion's end: ``u`` for the
    direct source, ``ξ`` for the prefix one); ``end_zero`` is the value of ``end`` to evaluate at
    (``None``: ``end`` is data)."""

    data: ca.SX
    M: ca.SX
    end: ca.SX
    end_zero: ca.DM | None


class MotionSource:
    """How the windows of one problem get their motion; see the module docstring."""

    def __init__(
        self,
        model: KinematicModel,
        kinematic: ca.Function,
        x: ca.SX,
        x_fixed: ca.SX,
        kinematic_columns: list[int],
        n_inputs: int,
        integration: str,
        prefix: bool,
    ) -> None:
        self.model = model
        self.kinematic = kinematic  # (x, x_fixed) -> the kinematic parameters
        self.x, self.x_fixed = x, x_fixed
        self.columns = kinematic_columns
        self.n_inputs = n_inputs
        self.integration = integration
        self.prefix = prefix

    def _increment(self, x: ca.SX, u: ca.SX) -> ca.SX:
        return self.model.increment(self.kinematic(x, self.x_fixed), u, self.integration)

    def rows(self, order: int) -> int:
        """Rows of a window's motion data for derivatives of ``order``."""
        return 2 * jet_rows(len(self.columns), order) if self.prefix else self.n_inputs

    def window(self, h: ca.SX, order: int) -> MotionSymbols:
        """The motion for derivatives up to ``order`` in ``h`` (perturbing every free parameter)."""
        if not self.prefix:
            u = ca.SX.sym("motion", self.n_inputs)
            return MotionSymbols(u, self._increment(self.x + h, u), u, None)
        ns = jet_rows(len(self.columns), order)
        data = ca.SX.sym("motion", 2 * ns)
        delta = h[self.columns] if order >= 1 else ca.SX(0, 1)
        xi = ca.SX.sym("xi", 3)
        Pa, Pb = jet_pose(data[0:ns], delta, order), jet_pose(data[ns : 2 * ns], delta, order)
        return MotionSymbols(data, se2.between(Pa, se2.compose(xi, Pb)), xi, ca.DM.zeros(3))

    def step(self, order: int) -> ca.Function:
        """One interval of the prefix scan of ``order``: ``(jet of P) → (jet of P·Δ)``."""
        nk = len(self.columns)
        state = ca.SX.sym("state", jet_rows(nk, order))
        u = ca.SX.sym("u", self.n_inputs)
        delta = ca.SX.sym("delta", nk if order >= 1 else 0)
        x = perturbed(self.x, delta, self.columns) if order >= 1 else self.x
        moved = se2.compose(jet_pose(state, delta, order), self._increment(x, u))
        name = {0: "prefix_value_step", 1: "prefix_step", 2: "prefix_hessian_step"}[order]
        return ca.Function(
            name,
            [state, self.x, self.x_fixed, u],
            [jet_of(moved, delta, order)],
            STEP_INPUTS,
            ["state_next"],
            _CSE,
        )

    def interval_sensitivity(self) -> ca.Function:
        """``(P_j, u_j) → ∂ξ/∂u_j``: the left perturbation ``ξ`` of every later prefix pose that a
        change of interval ``j``'s inputs makes (3 x n_inputs)."""
        P = ca.SX.sym("state", 3)
        u, u_j = ca.SX.sym("u", self.n_inputs), ca.SX.sym("u", self.n_inputs)
        step, step_j = self._increment(self.x, u), self._increment(self.x, u_j)
        # ξ(u) = P_j·Δ(u)·Δ(u_j)⁻¹·P_j⁻¹ moves every later prefix pose on the left: P_b(u) = ξ(u)·P_b.
        xi = se2.compose(se2.compose(P, se2.compose(step, se2.inverse(step_j))), se2.inverse(P))
        sensitivity = ca.substitute(ca.jacobian(xi, u), u, u_j)
        return ca.Function(
            "interval_sensitivity",
            [P, self.x, self.x_fixed, u_j],
            [ca.densify(sensitivity)],
            STEP_INPUTS,
            ["dxi_du"],
            _CSE,
        )
