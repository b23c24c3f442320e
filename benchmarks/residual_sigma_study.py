"""Why a white-noise σ can lie far below what a fit's own residuals say, on one scenario.

    python3 benchmarks/residual_sigma_study.py SCENARIO.yaml [--blocks 10] [--param sensor_y]

Prints, per free parameter at the Gauss-Newton fit: the white-noise σ (the tracker poses' and
encoders' noise propagated through the windows), the σ the residuals' own scores give (each
window's score times those sharing a record with it; ``std_residuals`` where beyond its noise),
the same with every window's score alone (independent windows) and ``σ²·H⁻¹`` with the residuals'
variance. Then ``--param`` fitted on each of ``--blocks`` contiguous blocks alone (the others held
at the fit, one Gauss-Newton step), each with its σ from the block's own scores, and the χ² of the
blocks' values about their weighted mean: a χ² near its degrees of freedom says the blocks scatter
as those σ allow; far above, errors vary along the drive beyond them. Holding the others makes
white noise disagree too (each block weighs the others' errors its own way): the run's own figure,
``block_chi2`` in result.json, fits every parameter a block determines at once
(``nlp_calib.analysis.block_scatter``).
"""

from __future__ import annotations

import argparse
import itertools
import warnings

import numpy as np

from nlp_calib import Calibration, load_scenario


def scores(cal: Calibration, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each window's score ``ρ'·JᵀΩe`` and its information ``ρ'·JᵀΩJ`` (diagonal)."""
    ev = cal.evaluator
    e, _, weight = (np.array(v) for v in ev.robust_terms(x))
    g, h = [], []
    for w, sens in ev.sensitivities(x):
        g.append(np.einsum("wrn,r,rw->wn", sens.J, ev.omega, weight[w] * e[:, w]))
        h.append(np.einsum("wrn,r,wrn->wn", sens.J, ev.omega, sens.J * weight[w, None, None]))
    return np.vstack(g), np.vstack(h)


def shared_meat(g: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``Σ g_u g_vᵀ`` over every pair of windows that share a record (windows ordered by start)."""
    hi = np.searchsorted(a, b, side="right")
    P = np.vstack([np.zeros((1, g.shape[1])), np.cumsum(g, axis=0)])
    later = P[hi] - P[1:]
    return g.T @ g + g.T @ later + later.T @ g


def sigmas(cal: Calibration, x: np.ndarray, g: np.ndarray) -> None:
    run = cal.run(["gauss_newton"])
    u = run.reports["gauss_newton"].uncertainty
    ne = cal.evaluator.normal_equations(x)
    fns, data = cal.fns, cal.data
    Hi, M = np.linalg.inv(ne.H), np.asarray(fns.tangent_map(x))
    s2 = ne.cost / (fns.error_rows * data.n_residuals - fns.n_free)
    believe = run.std("gauss_newton")

    def sd(meat: np.ndarray) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(M @ Hi @ meat @ Hi @ M.T), 0, None))

    shared, alone = sd(shared_meat(g, data.starts, data.stops)), sd(g.T @ g)
    heads = ("white", "residuals", "(beyond)", "alone", "σ²H⁻¹", "believe")
    print(f"{'parameter':24s} " + " ".join(f"{h:>9s}" for h in heads))
    for i, n in enumerate(fns.free):
        j = u.names.index(n)
        print(
            f"{n:24s} {u.std[j]:9.5f} {shared[i]:9.5f} {u.residual_spread()[j]:9.5f} {alone[i]:9.5f} "
            f"{np.sqrt(s2 * Hi[i, i]):9.5f} {believe[n]:9.5f}"
        )


def blocks(cal: Calibration, x: np.ndarray, g: np.ndarray, h: np.ndarray, k: int, name: str) -> None:
    c = cal.fns.free.index(name)
    a, b = cal.data.starts, cal.data.stops
    edges = np.linspace(a.min(), b.max() + 1, k + 1)
    vals, sds = [], []
    for lo, up in itertools.pairwise(edges):
        m = (a >= lo) & (a < up)
        H = h[m, c].sum()
        if H <= 0:
            continue
        meat = shared_meat(g[m][:, [c]], a[m], b[m])[0, 0]
        vals.append(x[c] - g[m, c].sum() / H)
        sds.append(np.sqrt(max(meat, 0.0)) / H)
        print(f"  block [{lo:.0f}, {up:.0f}) {name} {vals[-1]:+.4f} ± {sds[-1]:.4f}")
    v, w = np.array(vals), np.array(sds) ** -2.0
    mean = (w * v).sum() / w.sum()
    print(
        f"  χ² {(w * (v - mean) ** 2).sum():.1f} on {v.size - 1} dof; the blocks' weighted mean "
        f"{mean:+.4f} ± {w.sum() ** -0.5:.4f}; their standard deviation {v.std(ddof=1):.4f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario")
    ap.add_argument("--blocks", type=int, default=10)
    ap.add_argument("--param", default="sensor_y")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    cal = Calibration.setup(load_scenario(args.scenario))
    x = cal.solve("gauss_newton").x
    g, h = scores(cal, x)
    sigmas(cal, x, g)
    blocks(cal, x, g, h, args.blocks, args.param)


if __name__ == "__main__":
    main()
