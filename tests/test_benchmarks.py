"""The benchmark command runs end to end on small sizes (a smoke test: no timing is asserted)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO

from nlp_calib.codegen.compiler import find_compiler


@pytest.mark.skipif(
    find_compiler() is None, reason="no C compiler found: the benchmark measures the compiled backend"
)
@pytest.mark.slow
def test_performance_benchmark_quick_run(tmp_path: Path) -> None:
    env = dict(os.environ, NLP_CALIB_CACHE=str(tmp_path / "cache"))
    proc = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "performance.py"), "--quick", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    doc = json.loads((tmp_path / "performance.json").read_text())
    cases = doc["cases"]
    assert [c["records"] for c in cases] == [500, 2000]
    for c in cases:
        assert c["converged"] and c["agree"] < 1e-4
        for key in (
            "eval_ms",
            "gn_ms",
            "ipopt_ms",
            "scipy_ms",
            "seed_solve_ms",
            "peak_rss_mb",
            "setup_and_compile_s",
        ):
            assert c[key] > 0, key
        assert c["scipy_agree"] < 1e-4  # scipy reaches the same least-squares optimum
    assert (tmp_path / "performance.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "scipy least_squares" in (tmp_path / "performance.md").read_text()
