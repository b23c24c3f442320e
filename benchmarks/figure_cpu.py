"""CPU time of each figure nlp_calib writes, on runs computed once in this process.

    python benchmarks/figure_cpu.py                       # the four cases below, 3 repeats
    python benchmarks/figure_cpu.py --repeats 5 --out /tmp/figs   # keep the PNGs to look at
    python benchmarks/figure_cpu.py --records 200000      # add a long simulated log's run
    python benchmarks/figure_cpu.py --repo ../main        # another checkout's figures (before/after)

Cases: a 300-record simulated tricycle log (S-curves, both solvers), scenarios/camera_demo.yaml,
scenarios/diff_drive_demo.yaml and a 300-record straight drive (a run with a plan). Each figure
function of ``nlp_calib.outputs.figures`` is called ``--repeats`` times; printed per figure: the
CPU time (``time.process_time``) of its first call in this process and the median of the rest.
The first figure drawn also pays matplotlib's one-off set-up (fonts, imports), which a fresh
``nlp-calib run --report`` pays once; the warm-up line times that set-up on its own.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# ``--repo PATH`` (first) measures another checkout's figures, e.g. main's, on the same runs.
if len(sys.argv) > 2 and sys.argv[1] == "--repo":
    REPO = Path(sys.argv.pop(2)).resolve()
    sys.argv.pop(1)
sys.path.insert(0, str(REPO))

from nlp_calib.pipeline import Calibration, Wanted, load_scenario  # noqa: E402
from nlp_calib.results import CalibrationRun  # noqa: E402
from nlp_calib.simulation import SimulationOptions, simulate_to_file  # noqa: E402

FIGURES = (
    "trajectory",
    "convergence",
    "residuals",
    "residuals_time",
    "model_check",
    "trust",
    "lag",
    "plan",
    "odometry",
)


def _simulated(folder: Path, name: str, records: int, trajectory: str) -> Path:
    options = SimulationOptions.of(records=records, seed=7, trajectory=trajectory)
    log, _ = simulate_to_file(options, folder / f"{name}.txt")
    return log


def _runs(folder: Path, records: int, only: str) -> dict[str, CalibrationRun]:
    demo = load_scenario(REPO / "scenarios" / "demo.yaml")
    cases = {
        "tricycle300": demo.with_dataset(_simulated(folder, "s300", 300, "s_curves")),
        "camera_demo": load_scenario(REPO / "scenarios" / "camera_demo.yaml"),
        "diff_drive_demo": load_scenario(REPO / "scenarios" / "diff_drive_demo.yaml"),
        "straight300": demo.with_dataset(_simulated(folder, "straight", 300, "straight")),
    }
    if records:
        cases[f"tricycle{records}"] = demo.with_dataset(_simulated(folder, "long", records, "s_curves"))
    # The odometry figure (``nlp-calib odometry``) on the first case only.
    if only:
        cases = {name: sc for name, sc in cases.items() if name in only.split(",")}
    return {
        name: Calibration(sc).run(wanted=Wanted(series=True, odometry="gauss_newton" if i == 0 else None))
        for i, (name, sc) in enumerate(cases.items())
    }


def _warm_up() -> float:
    """CPU of matplotlib's one-off set-up: importing it and drawing one empty figure."""
    t0 = time.process_time()
    from matplotlib.figure import Figure

    from nlp_calib.outputs.plots.style import figure_png

    figure_png(Figure(figsize=(2, 2)))
    return time.process_time() - t0


def _time(run: CalibrationRun, folder: Path, name: str, repeats: int) -> list[float]:
    from nlp_calib.outputs import figures

    function = getattr(figures, name)
    out = []
    for _ in range(repeats):
        t0 = time.process_time()
        drawn = function(run, folder, f"{name}.png")
        out.append(time.process_time() - t0)
        if not drawn:
            return []
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--records", type=int, default=0, help="also a simulated log of this many records")
    parser.add_argument("--cases", default="", help="only these cases (comma-separated names)")
    parser.add_argument("--out", type=Path, default=None, help="folder for the PNGs (default: temporary)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        runs = _runs(Path(tmp), args.records, args.cases)
        print(f"matplotlib set-up (import, one empty figure): {_warm_up():.3f} s CPU")
        print(f"{'case':<18}{'figure':<16}{'first [s]':>10}{'median [s]':>11}")
        total = 0.0
        for case, run in runs.items():
            folder = out / case
            folder.mkdir(parents=True, exist_ok=True)
            for name in FIGURES:
                times = _time(run, folder, name, args.repeats)
                if not times:
                    continue
                rest = statistics.median(times[1:]) if len(times) > 1 else times[0]
                total += rest
                print(f"{case:<18}{name:<16}{times[0]:>10.3f}{rest:>11.3f}")
        print(f"sum of medians: {total:.3f} s CPU")


if __name__ == "__main__":
    main()
