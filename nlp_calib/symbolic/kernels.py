"""Robust kernels ρ(s) of the squared Mahalanobis norm ``s = eᵀΩe``.

Each kernel is defined once, as a CasADi expression of ``s`` and the threshold ``delta`` (on the
norm, so ``s = delta²`` is the switch). Both solvers use the same expression: Gauss-Newton takes
the IRLS weight ρ'(s) by symbolic differentiation, IPOPT takes ρ itself. All kernels satisfy
ρ(s) ≈ s for small s.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca

from nlp_calib.core.errors import ProblemError

KernelFn = Callable[[ca.SX, ca.SX], ca.SX]


def _none(s: ca.SX, delta: ca.SX) -> ca.SX:
    """Plain least squares."""
    return s


def _huber(s: ca.SX, delta: ca.SX) -> ca.SX:
    """Quadratic below ``delta``, linear in the norm above; C¹ at the switch."""
    d2 = delta * delta
    inside = s <= d2
    s_safe = ca.if_else(inside, d2, s)  # keeps sqrt's derivative finite at s = 0
    return ca.if_else(inside, s, 2.0 * delta * ca.sqrt(s_safe) - d2)


def _cauchy(s: ca.SX, delta: ca.SX) -> ca.SX:
    """Logarithmic growth: strongly down-weights gross outliers (not convex)."""
    d2 = delta * delta
    return d2 * ca.log1p(s / d2)


def _pseudo_huber(s: ca.SX, delta: ca.SX) -> ca.SX:
    """Smooth Huber: ``2δ²(√(1 + s/δ²) − 1)``."""
    d2 = delta * delta
    return 2.0 * d2 * (ca.sqrt(1.0 + s / d2) - 1.0)


KERNELS: dict[str, KernelFn] = {
    "none": _none,
    "huber": _huber,
    "cauchy": _cauchy,
    "pseudo_huber": _pseudo_huber,
}


def rho(kernel: str, s: ca.SX, delta: ca.SX) -> ca.SX:
    """ρ(s) of the named kernel."""
    return KERNELS[kernel](s, delta)


def kernel_function(kernel: str) -> ca.Function:
    """``(s, delta) -> (rho, weight)``: ρ(s) and the IRLS weight ρ'(s), one expression differentiated."""
    if kernel not in KERNELS:
        raise ProblemError(f"unknown robust kernel {kernel!r}; valid kernels: {', '.join(KERNELS)}")
    s = ca.SX.sym("s")
    delta = ca.SX.sym("delta")
    r = rho(kernel, s, delta)
    return ca.Function(
        f"kernel_{kernel}", [s, delta], [r, ca.jacobian(r, s)], ["s", "delta"], ["rho", "weight"]
    )
