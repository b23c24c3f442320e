"""What the block seam takes: a block kind is one registry line; nothing else is edited.

A toy per-log wheel scale is registered here alone (no file of the package changes): the second of
two drives of one robot is simulated with its traction wheel 3 % larger, and the joint fit with a
scale per log (the first log's held at 1) recovers it within its σ while the wheels' own
calibration stays the first log's.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping
from pathlib import Path

import casadi as ca
import pytest

from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.problem import blocks
from nlp_calib.results import CalibrationRun
from nlp_calib.simulation import SimulationOptions, simulate, write_simulation
from nlp_calib.symbolic import se2

SCALE = 1.03


def scaled(M: ca.SX, values: Mapping[str, ca.SX]) -> ca.SX:
    """An interval's base motion with its wheel travel ``s`` times as long: the same arc (its
    curvature is the steering's), ``exp(s · log M)`` on SE(2)."""
    s, theta = values["wheel_scale"], M[2]
    a, b = se2.sinc(theta), ca.sin(0.5 * theta) * se2.sinc(0.5 * theta)
    det = a * a + b * b
    rho = ca.vertcat(a * M[0] + b * M[1], -b * M[0] + a * M[1]) / det
    t2 = s * theta
    a2, b2 = se2.sinc(t2), ca.sin(0.5 * t2) * se2.sinc(0.5 * t2)
    return ca.vertcat(s * (a2 * rho[0] - b2 * rho[1]), s * (b2 * rho[0] + a2 * rho[1]), t2)


WHEEL_SCALE = blocks.BlockKind(
    keys=("wheel_scale",),
    transform=scaled,
    applies=lambda model, n_logs: n_logs > 1,
    units={"wheel_scale": "1"},
    defaults={"wheel_scale": 1.0},
    per_log=True,
    held_first=("wheel_scale",),
)


def test_the_transform_scales_an_arc() -> None:
    """Independently of the fit: an arc of length d turning by w becomes one of s·d turning by s·w."""
    d, w, s = 0.7, 0.4, 1.1
    out = ca.evalf(scaled(se2.arc(d, w), {"wheel_scale": s}))
    assert float(ca.norm_2(out - ca.evalf(se2.arc(s * d, s * w)))) < 1e-12


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[CalibrationRun, dict[str, float]]:
    tmp = tmp_path_factory.mktemp("blocks")
    truth = dict(SimulationOptions.of(records=10).truth)
    paths = []
    for i, k in enumerate((truth["k_traction"], SCALE * truth["k_traction"])):
        opts = SimulationOptions.of(
            records=700, seed=70 + i, trajectory="s_curves", truth={**truth, "k_traction": k}
        )
        _, truth_file = write_simulation(simulate(opts), tmp / f"drive{i}.txt")
        assert json.loads(Path(truth_file).read_text())["params"]["k_traction"] == pytest.approx(k)
        paths.append(str(tmp / f"drive{i}.txt"))
    sc = scenario_from_mapping(
        {
            "model": "tricycle",
            "datasets": paths,
            "initial_guess": "auto",
            "alignment": {"tracker_lag": 0.0},
            "residual": {"horizon": 1},
            "solvers": ["gauss_newton"],
        },
        "scaled",
        tmp,
    )
    with pytest.MonkeyPatch.context() as mp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mp.setitem(blocks.BLOCK_KINDS, "wheel_scale", WHEEL_SCALE)
        return Calibration(sc).run(), truth


def test_a_registered_block_is_laid_out_and_recovers_a_simulated_scale(
    run: tuple[CalibrationRun, dict[str, float]],
) -> None:
    found, truth = run
    layout = found.scenario.layout
    own = [p for p in layout.parameters if p.block == "wheel_scale"]
    assert [(p.name, p.log) for p in own] == [("wheel_scale_1", 0), ("wheel_scale_2", 1)]
    assert layout.param("wheel_scale_1").status == "held"
    values, std = found.reports["gauss_newton"].result.param_dict(), found.std("gauss_newton")
    assert values["wheel_scale_1"] == 1.0
    z = (values["wheel_scale_2"] - SCALE) / std["wheel_scale_2"]
    assert abs(z) < 3.0 and std["wheel_scale_2"] < 0.003, (values["wheel_scale_2"], std["wheel_scale_2"])
    # The wheels' own calibration is the first log's, not a blend of the two.
    assert abs(values["k_traction"] - truth["k_traction"]) < 3.0 * std["k_traction"]
