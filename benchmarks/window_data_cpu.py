"""CPU of writing an evaluator's window data (``[z, clock, w]`` per window, padded) on a log.

    python benchmarks/window_data_cpu.py LOG                     # this checkout, the demo's scenario
    python benchmarks/window_data_cpu.py LOG --repo ../main      # another checkout's, for before/after

Printed per repeat (``time.process_time``): the whole matrix ``data()`` padded by ``pad_columns``
(the path every checkout has), and where the checkout has ``ResidualData.write_data``, the
evaluator's fill of its buffer and a re-binding's (the clock rows alone), with whether the bits
are the padded matrix's. Logs: ``nlp-calib simulate --records N --seed 11 --out LOG``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("--repo", default=str(Path(__file__).resolve().parents[1]))
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    repo = Path(args.repo).resolve()
    sys.path.insert(0, str(repo))
    import numpy as np

    from nlp_calib import Calibration, load_scenario
    from nlp_calib.solvers.backends import pad_columns

    calib = Calibration(load_scenario(repo / "scenarios" / "demo.yaml").with_dataset(args.log))
    data = calib.stages.problem.binder.windows(calib.log, *calib.fit)
    n_pad = data.n_residuals + 40
    print(f"{repo}: {data.n_residuals} windows")
    for _ in range(args.repeats):
        t = time.process_time()
        padded = pad_columns(data.data(), n_pad)
        line = f"data()+pad_columns {time.process_time() - t:.4f} s"
        if hasattr(data, "write_data"):
            from nlp_calib.solvers.evaluation import _fill

            buffer = np.empty((data.data_rows, n_pad), order="F")
            t = time.process_time()
            _fill(buffer, data)
            line += f"  fill {time.process_time() - t:.4f} s"
            t = time.process_time()
            _fill(buffer, data, clock_only=True)
            line += f"  fill clock rows {time.process_time() - t:.4f} s"
            line += f"  same bits {buffer.tobytes(order='F') == padded.tobytes(order='F')}"
        print(line)


if __name__ == "__main__":
    main()
