"""The benchmark command runs end to end on small sizes (a smoke test: no timing is asserted)."""

from __future__ import annotations

import json
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
    # The compile cache the other tests use (the user's): the benchmark's warm runs are warm there,
    # and its cold runs compile in folders of their own.
    proc = subprocess.run(
        [
            sys.executable,
            str(REPO / "benchmarks" / "performance.py"),
            "--quick",
            "--repeats",
            "1",
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    doc = json.loads((tmp_path / "performance.json").read_text())
    # One repeat: the smoke run proves every section runs and agrees; the medians are the benchmark's.
    assert doc["repeats"] == 1 and doc["environment"]["cores"] >= 1
    assert doc["end_to_end"]["import_floor_s"] > 0 and doc["end_to_end"]["import_floor_cpu_s"] > 0
    demo = doc["end_to_end"]["scenarios"]["demo"]
    for key in ("cold_wall_s", "warm_wall_s", "warm_cpu_s", "warm_peak_mb", "gauss_newton_ms", "ipopt_ms"):
        assert demo[key] > 0, key
    for section in ("end_to_end", "solvers", "scaling"):
        assert len(doc[section]["load_start"]) == 3
    for case in doc["solvers"]["cases"].values():
        assert set(case["median_ms"]) >= {"gauss_newton", "ipopt", "scipy (numpy, prefix)"}
        for name, agree in case["agreement"].items():
            # Every solver reaches the same optimum of the same objective.
            assert agree["cost_rel"] < 1e-8, name
    sizes = doc["scaling"]["sizes"]
    assert list(sizes) == ["2000", "8000"] and all(s["peak_mb"] > 0 for s in sizes.values())
    assert (tmp_path / "performance.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| target | measured |" in (tmp_path / "performance.md").read_text()
