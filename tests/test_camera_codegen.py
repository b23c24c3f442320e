"""The C export of a camera's 3-D residual and Jacobian: compiled, it computes what Python does."""

from __future__ import annotations

import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from conftest import assert_close
from test_codegen import COMPILER, needs_compiler

from nlp_calib.codegen.export import Example, build_for_export, export_functions, generate
from nlp_calib.core import poses3d
from nlp_calib.models import get_model

MODEL = "diff_drive"
TRUTH = np.array([0.1, 0.1005, 0.45, 0.25, 0.06, 0.3, -2.09, 0.05, -1.57, 2.0])


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    out = tmp_path_factory.mktemp("codegen3d")
    problems = build_for_export(get_model(MODEL), 4, "exact", sensor="3d", scale="free")
    z = np.r_[0.02, -0.01, 0.05, poses3d.rotvec_to_quat(np.array([0.0, -0.01, 0.004]))]
    column = np.r_[np.full(8, 0.05), z, 1.0]
    example = Example(TRUTH, "a test's values", column, "a made-up window")
    generate(problems, out, example, "a test")
    return out, [e for fns in problems for e in export_functions(fns)]


def test_the_3d_export_takes_every_parameter_and_differentiates_the_estimated_ones(exported) -> None:
    _, functions = exported
    jac = next(e for e in functions if "jacobian" in e.function.name() and e.horizon == 4)
    assert (jac.n_params, jac.n_free, jac.error_rows, jac.z_rows) == (10, 9, 6, 7)
    assert jac.function.size_in(2) == (7, 1) and jac.function.size_out(1) == (6, 9)
    header = (exported[0] / "nlp_calib_residual.h").read_text()
    assert "nlp_calib_residual_jacobian_h4" in header and "nlp_calib_residual_h1" in header


@needs_compiler
def test_compiled_3d_residual_equals_python(exported) -> None:
    out, functions = exported
    lib = out / "lib3d.so"
    subprocess.run(
        [str(COMPILER), "-O2", "-fPIC", "-shared", "-o", str(lib), "nlp_calib_residual.c", "-lm"],
        cwd=out, check=True, capture_output=True, timeout=300,
    )  # fmt: skip
    rng = np.random.default_rng(0)
    for exp in functions:
        ext = ca.external(exp.function.name(), str(lib))
        for _ in range(10):
            params = TRUTH + rng.normal(0, 0.05, TRUTH.size)
            u = rng.uniform(-3, 3, (2, exp.horizon))
            z = np.r_[rng.normal(0, 0.3, 3), poses3d.rotvec_to_quat(rng.normal(0, 0.3, 3))]
            got, want = ext(params, u, z), exp.function(params, u, z)
            for a, b in zip(
                got if exp.function.n_out() > 1 else [got], want if exp.function.n_out() > 1 else [want]
            ):
                a, b = np.asarray(a), np.asarray(b)
                assert_close(a, b, rtol=1e-12, atol=1e-12 * max(np.abs(b).max(), 1.0))
    exe = out / "example"
    subprocess.run(
        [str(COMPILER), "-O2", "-o", str(exe), "example.c", "nlp_calib_residual.c", "-lm"],
        cwd=out,
        check=True,
        timeout=300,
    )
    printed = subprocess.run([str(exe)], capture_output=True, text=True, check=True, timeout=60).stdout
    diff = printed.strip().splitlines()[-1]
    assert diff.startswith("largest difference from Python: e ")
    de, dJ = (float(v.rstrip(",")) for v in diff.split()[5::2])
    assert de < 1e-14 and dJ < 1e-12
    assert sum(ln.startswith("e ") for ln in printed.splitlines()) == 6
    assert sum(ln.startswith("J ") for ln in printed.splitlines()) == 54
