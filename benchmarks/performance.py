"""Performance benchmark: the shipped scenarios end to end, the solvers against fair baselines on the
same objective and data, and runs on 10^4 to 10^6 simulated records.

    python benchmarks/performance.py                 # everything; prints a summary table
    python benchmarks/performance.py --quick         # small sizes, few repeats: the tests' smoke run
    python benchmarks/performance.py --sections batch,simulate   # some sections only

Every figure is a median over ``--repeats`` (default 7) interleaved repeats, with the load average
recorded at the start and end of each section (the machine is shared: read the figures with it).
End-to-end and scaling runs are fresh ``nlp-calib`` processes started by a launcher that does
nothing else, so their peak RSS is their own (``getrusage(RUSAGE_CHILDREN)``); cold runs start
from an empty compile cache, warm ones from a filled one. Solver times are measured in-process on
the same windows: Gauss-Newton and IPOPT against ``scipy.optimize.least_squares`` (vectorised
numpy residual with its analytic Jacobian, the same Huber objective; ``baselines.py``) and, when
installed (``pip install .[bench]``), GTSAM and Ceres through their standard Python APIs.
``ipopt_lag`` solves the recommended real-log scenario with IPOPT at 14 lags 0.06 ms apart, with
the project's ``tiny_step_tol`` and with IPOPT's default (the iterations a lag's last digits
decided). ``horizon`` runs the demo's settings (``nlp-calib run scenarios/demo.yaml --data LOG``)
on simulated logs of 10^5 and 10^6 records, ``camera`` the camera demo's on drives of 10^5 and
10^6 poses. ``gn_pass`` times one Gauss-Newton pass of the evaluator against the same computation
fused into one C loop. ``simulate`` times ``nlp-calib simulate --records 10^6`` (its peak RSS: the
block-wise writer's); ``batch`` runs ``nlp-calib batch`` over 20 simulated logs with ``--jobs 1``
and ``--jobs 2``, interleaved; ``reader`` reads 10^6 records against ``numpy.loadtxt``. Writes
``results/performance.{json,md,png}`` (``--out`` elsewhere).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import itertools
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

# One BLAS thread, set before numpy loads: a baseline's BLAS threads left spinning after its call
# would otherwise slow down whichever solver is timed next (every solver here is single-threaded).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(REPO))

#: Runs a command and prints its wall time and the peak RSS of its process tree, nothing else.
LAUNCHER = (
    "import json, resource, subprocess, sys, time\n"
    "t0 = time.perf_counter()\n"
    "rc = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode\n"
    "wall = time.perf_counter() - t0\n"
    "use = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
    "peak, cpu = use.ru_maxrss / 1024.0, use.ru_utime + use.ru_stime\n"
    "print(json.dumps({'wall_s': wall, 'peak_mb': peak, 'cpu_s': cpu, 'rc': rc}))\n"
)
TARGETS = {
    "compare real_tricycle.yaml, warm [s]": 1.5,
    "compare real_tricycle.yaml, cold [s]": 3.0,
    "real_tricycle GN [ms]": 15.0,
    "real_tricycle IPOPT [ms]": 60.0,
    "real_tricycle_seed GN [ms]": 5.0,
    "real_tricycle_seed IPOPT [ms]": 25.0,
    "scipy (per window) / GN, H=1 [x]": 10.0,
    "scipy (per window) / GN, H=25 [x]": 30.0,
    "scipy (prefix) / GN, H=1 [x]": 10.0,
    "scipy (prefix) / GN, H=25 [x]": 30.0,
    "compare real_tricycle.yaml, warm / import floor [x]": 4.0,
    "compare real_tricycle.yaml, cold / import floor [x]": 8.0,
    "compare camera_demo.yaml, warm / import floor [x]": 6.0,
    "import nlp_calib.cli.commands / import floor [x]": 1.3,
    "10^6 records run --solver gauss_newton [s]": 12.0,
    "10^6 records peak RSS [MB]": 1000.0,
    "demo settings, 10^6 records run [s]": 30.0,
    "demo settings, 10^6 records peak RSS [MB]": 1000.0,
    "demo settings, run time 10^6 / 10^5 records [x]": 11.0,
    "camera_demo settings, 10^6 poses run [s]": 30.0,
    "camera_demo settings, 10^6 poses peak RSS [MB]": 1000.0,
    "camera_demo settings, run time 10^6 / 10^5 poses [x]": 11.0,
    "reader / numpy.loadtxt, 10^6 records [x]": 1.5,
    "Gauss-Newton pass / fused C loop [x]": 1.5,
    "batch of 20 logs, --jobs 1 / --jobs 2 [x]": 1.0,
}
#: Targets a figure must reach or exceed (the others are upper bounds).
AT_LEAST = frozenset({"batch of 20 logs, --jobs 1 / --jobs 2 [x]"}) | {
    name for name in TARGETS if name.startswith("scipy")
}
#: The sections a run measures (``--sections``), in order.
SECTIONS = (
    "end_to_end",
    "solvers",
    "ipopt_lag",
    "scaling",
    "horizon",
    "camera",
    "simulate",
    "batch",
    "reader",
    "gn_pass",
)
#: The camera demo's images per second (scenarios/data/camera_demo.sim.yaml): a drive of ``n``
#: poses lasts ``n / CAMERA_RATE_HZ`` seconds.
CAMERA_RATE_HZ = 50.0


def load() -> list[float]:
    return [round(v, 2) for v in os.getloadavg()]


def launch(cmd: list[str], env: dict[str, str]) -> dict[str, Any]:
    """Run ``cmd`` in a fresh launcher process; its wall time, peak RSS, CPU time (its processes'
    together) and exit code."""
    out = subprocess.run(
        [sys.executable, "-c", LAUNCHER, *cmd], capture_output=True, text=True, env=env, check=True
    )
    return dict(json.loads(out.stdout))


def warm_env() -> dict[str, str]:
    """The environment of the timed runs: this checkout's code, and the compile cache a user's runs
    keep (``cache_dir()``), warm after its first run (a smoke run's first run of a scenario may
    compile there, once, as a user's first run does; a folder of its own would compile again)."""
    from nlp_calib.codegen.compiler import cache_dir

    return dict(os.environ, PYTHONPATH=str(REPO), PYTHONWARNINGS="ignore", NLP_CALIB_CACHE=str(cache_dir()))


def with_bytecode(env: dict[str, str]) -> dict[str, str]:
    """``env`` in which Python keeps the compiled bytecode of what it imports (beside the source, or
    under ``PYTHONPYCACHEPREFIX`` where that is set), as an installed package has it from its
    installation: a machine that sets ``PYTHONDONTWRITEBYTECODE`` would have every run compile this
    package from source again (about 0.7 s of CPU on compare) while the floor loads numpy's and
    CasADi's compiled files."""
    return {k: v for k, v in env.items() if k != "PYTHONDONTWRITEBYTECODE"}


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "nlp_calib", *args]


def simulate_log(*args: str) -> None:
    """``nlp-calib simulate ARGS`` in this process: the same command writes the same bytes, without
    a fresh interpreter's imports (1.5 s of CPU each, most of a smoke run's small log); what it
    prints is dropped. The ``simulate`` section times the command in processes of its own."""
    import contextlib
    import io
    import warnings

    from nlp_calib.cli.main import main as nlp_calib_main

    err = io.StringIO()
    with (
        warnings.catch_warnings(),
        contextlib.redirect_stdout(io.StringIO()),
        contextlib.redirect_stderr(err),
    ):
        warnings.simplefilter("ignore")
        code = nlp_calib_main(["simulate", *args])
    if code != 0:
        raise SystemExit(f"nlp-calib simulate {' '.join(args)} failed ({code}): {err.getvalue()[-500:]}")


def med(values: list[float]) -> float:
    return float(np.median(values)) if values else float("nan")


def end_to_end(
    scenarios: list[tuple[str, list[str]]], repeats: int, tmp: Path, warm_up: bool = True
) -> dict[str, Any]:
    """``compare`` of each scenario, cold and warm cache, interleaved; wall, peak RSS, solver times
    (without ``warm_up`` the first warm run may also compile, as a user's first run does)."""
    from nlp_calib.codegen.compiler import cache_dir

    env = with_bytecode(dict(os.environ, PYTHONPATH=str(REPO), PYTHONWARNINGS="ignore"))
    warm = cache_dir()  # the cache a user's runs keep: warm after the first
    for name, extra in scenarios if warm_up else ():  # fill the warm cache (not timed)
        launch(
            cli("compare", str(REPO / "scenarios" / f"{name}.yaml"), *extra, "--out", str(tmp / "w")),
            {**env, "NLP_CALIB_CACHE": str(warm)},
        )
    runs: dict[str, dict[str, list[float]]] = {name: {} for name, _ in scenarios}
    floor: dict[str, list[float]] = {}
    commands: dict[str, list[float]] = {}
    start = load()
    for k in range(repeats):
        # The floor every run pays: a fresh interpreter importing numpy and CasADi; beside it, what
        # the command line loads before it knows the command.
        for kept, code in ((floor, "import numpy, casadi"), (commands, "import nlp_calib.cli.commands")):
            r = launch([sys.executable, "-c", code], env)
            kept.setdefault("wall_s", []).append(r["wall_s"])
            kept.setdefault("cpu_s", []).append(r["cpu_s"])
        for name, extra in scenarios:
            for mode in ("cold", "warm"):
                cache = tmp / f"cache-cold-{k}-{name}" if mode == "cold" else warm
                out = tmp / f"out-{name}-{mode}"
                r = launch(
                    cli("compare", str(REPO / "scenarios" / f"{name}.yaml"), *extra, "--out", str(out)),
                    {**env, "NLP_CALIB_CACHE": str(cache)},
                )
                if r["rc"] not in (0, 1):
                    raise SystemExit(f"compare {name} failed with exit code {r['rc']}")
                rec = runs[name]
                rec.setdefault(f"{mode}_wall_s", []).append(r["wall_s"])
                rec.setdefault(f"{mode}_cpu_s", []).append(r["cpu_s"])
                rec.setdefault(f"{mode}_peak_mb", []).append(r["peak_mb"])
                if mode == "warm":
                    doc = json.loads((out / "result.json").read_text())
                    for solver, res in doc["solvers"].items():
                        rec.setdefault(f"{solver}_ms", []).append(1e3 * res["time_s"])
                if mode == "cold":
                    shutil.rmtree(cache, ignore_errors=True)
    return {
        "load_start": start,
        "load_end": load(),
        "import_floor_s": med(floor["wall_s"]),
        "import_floor_cpu_s": med(floor["cpu_s"]),
        "import_commands_s": med(commands["wall_s"]),
        "import_commands_cpu_s": med(commands["cpu_s"]),
        "scenarios": {n: {k: med(v) for k, v in r.items()} for n, r in runs.items()},
    }


def solver_cases(real: Path | None, quick: bool) -> list[tuple[str, Any]]:
    """(label, scenario) of the in-process solver comparisons."""
    from nlp_calib.pipeline.scenario import AlignmentOptions, load_scenario

    if quick or real is None:
        # The baselines model no clock: the demo's lag held at its truth (the log has none).
        demo = load_scenario(REPO / "scenarios" / "demo.yaml").with_options(
            alignment=AlignmentOptions(tracker_lag=0.0)
        )
        seed = demo.with_options(residual=dataclasses.replace(demo.objective.residual, horizon=1))
        return [("demo, H=1", seed), ("demo, H=10", demo)]
    # The baselines are written for the tricycle model: the scenarios' windows on that model, with
    # the lag the recommended scenario estimates, fixed (the solvers' own time is compared here).
    seed = load_scenario(REPO / "scenarios" / "real_tricycle_seed.yaml").with_dataset(real)
    rec = load_scenario(REPO / "scenarios" / "real_tricycle.yaml").with_dataset(real)
    seed = seed.with_options(model="tricycle")
    rec = rec.with_options(model="tricycle", alignment=AlignmentOptions(tracker_lag=0.049361))
    return [("real_tricycle_seed (H=1)", seed), ("real_tricycle (H=25)", rec)]


def solvers(cases: list[tuple[str, Any]], repeats: int, per_factor: bool) -> dict[str, Any]:
    """Our solvers and the baselines on each case's windows, interleaved repeats."""
    start = load()
    out = {label: compare_solvers(sc, repeats, per_factor) for label, sc in cases}
    return {"load_start": start, "load_end": load(), "cases": out}


def compare_solvers(sc: Any, repeats: int, per_factor: bool) -> dict[str, Any]:
    """Median solve times of every solver on the windows of ``sc``, and how far each lands from
    Gauss-Newton's optimum."""
    import baselines

    from nlp_calib.pipeline import Calibration

    calib = Calibration(sc)
    data, ev = calib.data, calib.evaluator
    exact = sc.objective.residual.integration == "exact"
    windows = (data.inputs, data.starts, data.stops, data.z.T, exact)
    prefix = baselines.NumpyTricycle(*windows, prefix=True)
    composed = baselines.NumpyTricycle(*windows, prefix=False)
    ours = calib.solve("gauss_newton")
    runners: dict[str, Callable[[], np.ndarray]] = {
        "gauss_newton": lambda: calib.solve("gauss_newton").x,
        "ipopt": lambda: calib.solve("ipopt").x,
        "scipy (numpy, prefix)": lambda: baselines.scipy_solve(prefix, calib.x0, ev.omega, ev.delta).x,
        "scipy (numpy, per window)": lambda: baselines.scipy_solve(composed, calib.x0, ev.omega, ev.delta).x,
    }
    if per_factor and sc.objective.residual.horizon == 1:
        # One window per interval: each window's own interval (faulty ones are left out).
        args = (data.inputs[:, data.starts], data.z.T, calib.x0, ev.omega, ev.delta, exact)
        for name, module, fn in (
            ("gtsam", "gtsam", baselines.gtsam_solve),
            ("ceres", "pyceres", baselines.ceres_solve),
        ):
            try:
                __import__(module)
            except ImportError:
                continue
            runners[name] = functools.partial(fn, *args)
    times: dict[str, list[float]] = {n: [] for n in runners}
    agree: dict[str, dict[str, float]] = {}
    for k in range(-1, repeats):  # the first round warms up (imports, first calls), untimed
        for name, run in runners.items():
            t0 = time.perf_counter()
            x = run()
            if k >= 0:
                times[name].append(1e3 * (time.perf_counter() - t0))
            else:
                agree[name] = {
                    "cost_rel": abs(ev.cost(x) - ours.cost) / ours.cost,
                    "param_rel": float(np.max(np.abs(ev.params(x) - ours.params) / np.abs(ours.params))),
                }
    return {
        "residuals": data.n_residuals,
        "median_ms": {n: med(t) for n, t in times.items()},
        "agreement": agree,
    }


def ipopt_lag(real: Path | None, quick: bool, repeats: int) -> dict[str, Any]:
    """IPOPT's iterations and time on the recommended real-log scenario at lags a few hundredths of
    a millisecond apart, with the project's ``tiny_step_tol`` (√ε) and with IPOPT's default (10 ε)."""
    from nlp_calib.pipeline import Calibration
    from nlp_calib.pipeline.scenario import AlignmentOptions, load_scenario
    from nlp_calib.solvers.ipopt import Ipopt, IpoptOptions

    if quick or real is None:
        base, lags = load_scenario(REPO / "scenarios" / "demo.yaml"), [0.0, 0.00006]
    else:
        base = load_scenario(REPO / "scenarios" / "real_tricycle.yaml").with_dataset(real)
        lags = [round(0.049 + 0.00006 * k, 6) for k in range(14)]
    settings: dict[str, dict[str, float]] = {
        "sqrt(eps)": {},
        "ipopt default (10 eps)": {"tiny_step_tol": 10 * float(np.finfo(float).eps)},
    }
    start = load()
    out: dict[str, dict[str, list[float]]] = {name: {"iterations": [], "ms": []} for name in settings}
    for lag in lags:
        calib = Calibration(base.with_options(alignment=AlignmentOptions(tracker_lag=lag)))
        x0, lo, hi = (
            calib.fitting.problem.start.x0,
            calib.fitting.problem.start.lower,
            calib.fitting.problem.start.upper,
        )
        for name, options in settings.items():
            solver = Ipopt(calib.evaluator, IpoptOptions(options=options))
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                res = solver.solve(x0, lo, hi)
                times.append(1e3 * (time.perf_counter() - t0))
            out[name]["iterations"].append(res.trace.iterations)
            out[name]["ms"].append(med(times))
    return {"load_start": start, "load_end": load(), "lags_s": lags, "settings": out}


def ipopt_lag_lines(sweep: dict[str, Any]) -> list[str]:
    lags = sweep["lags_s"]
    lines = [
        "",
        f"IPOPT on the same scenario at {len(lags)} lags from {lags[0]} to {lags[-1]} s "
        f"(load average {sweep['load_start']} → {sweep['load_end']}):",
        "",
        "| tiny_step_tol | iterations (min–max) | time [ms] (min–max) |",
        "|---|---|---|",
    ]
    for name, r in sweep["settings"].items():
        it, ms = r["iterations"], r["ms"]
        lines.append(f"| {name} | {min(it)}–{max(it)} | {min(ms):.1f}–{max(ms):.1f} |")
    return lines


def scaling(sizes: list[int], repeats: int, tmp: Path, warm_up: bool = True) -> dict[str, Any]:
    """``run --solver gauss_newton`` on simulated logs of each size: wall, peak RSS, GN time
    (without ``warm_up`` the first run also compiles)."""
    env = warm_env()
    logs = {}
    for n in sizes:
        logs[n] = tmp / f"sim_{n}.txt"
        # Coarse sub-steps above 2·10^5 records: the logs these figures were first measured on (the
        # simulator then held a whole log in memory); the command writes the same bytes.
        config = tmp / f"sim_{n}.yaml"
        config.write_text(f"records: {n}\nseed: 11\nsubsteps: {4 if n > 200000 else 20}\n")
        simulate_log("--config", str(config), "--out", str(logs[n]), "--force")
    scenario = str(REPO / "scenarios" / "real_tricycle_seed.yaml")
    if warm_up:
        first = str(logs[sizes[0]])
        launch(
            cli("run", scenario, "--data", first, "--solver", "gauss_newton", "--out", str(tmp / "s")), env
        )
    runs: dict[int, dict[str, list[float]]] = {n: {} for n in sizes}
    start = load()
    for _ in range(repeats):
        for n in sizes:
            out = tmp / f"scale-{n}"
            r = launch(
                cli("run", scenario, "--data", str(logs[n]), "--solver", "gauss_newton", "--out", str(out)),
                env,
            )
            doc = json.loads((out / "result.json").read_text())
            runs[n].setdefault("wall_s", []).append(r["wall_s"])
            runs[n].setdefault("peak_mb", []).append(r["peak_mb"])
            runs[n].setdefault("gn_ms", []).append(1e3 * doc["solvers"]["gauss_newton"]["time_s"])
    cases = {str(n): {k: med(v) for k, v in runs[n].items()} for n in sizes}
    slope = float(np.polyfit(np.log(sizes), np.log([cases[str(n)]["wall_s"] for n in sizes]), 1)[0])
    return {"load_start": start, "load_end": load(), "sizes": cases, "wall_slope": slope}


def sized_runs(
    scenario: str, logs: dict[int, Path], repeats: int, tmp: Path, warm_up: bool = True
) -> dict[str, Any]:
    """``nlp-calib run SCENARIO --data LOG`` (the scenario's own settings and solvers) on each log,
    interleaved: wall, CPU (its processes'), peak RSS, each solver's time; and how the wall time
    grows from each size to the next. Without ``warm_up`` the first run also compiles (the smoke
    run's figures are not the benchmark's)."""
    env = warm_env()
    path = str(REPO / "scenarios" / f"{scenario}.yaml")
    first = min(logs)
    if warm_up:
        launch(cli("run", path, "--data", str(logs[first]), "--out", str(tmp / "warm-up")), env)  # compiles
    runs: dict[int, dict[str, list[float]]] = {n: {} for n in logs}
    start = load()
    for _ in range(repeats):
        for n, log in logs.items():
            out = tmp / f"{scenario}-{n}"
            r = launch(cli("run", path, "--data", str(log), "--out", str(out), "--force"), env)
            if r["rc"] not in (0, 1):
                raise SystemExit(f"run {scenario} on {n} failed with exit code {r['rc']}")
            rec = runs[n]
            for key in ("wall_s", "cpu_s", "peak_mb"):
                rec.setdefault(key, []).append(r[key])
            for solver, res in json.loads((out / "result.json").read_text())["solvers"].items():
                rec.setdefault(f"{solver}_ms", []).append(1e3 * res["time_s"])
    sizes = sorted(logs)
    cases = {str(n): {k: med(v) for k, v in runs[n].items()} for n in sizes}
    growth = {
        f"{b}/{a}": cases[str(b)]["wall_s"] / cases[str(a)]["wall_s"] for a, b in itertools.pairwise(sizes)
    }
    return {"load_start": start, "load_end": load(), "scenario": scenario, "sizes": cases, "growth": growth}


def horizon(sizes: list[int], repeats: int, tmp: Path, warm_up: bool = True) -> dict[str, Any]:
    """The demo's settings (windows of several records, both solvers, every check) on simulated
    tricycle logs of each size."""
    logs = {}
    for n in sizes:
        logs[n] = tmp / f"horizon_{n}.txt"
        simulate_log("--records", str(n), "--seed", "11", "--out", str(logs[n]), "--force")
    return sized_runs("demo", logs, repeats, tmp, warm_up)


def camera(sizes: list[int], repeats: int, tmp: Path, warm_up: bool = True) -> dict[str, Any]:
    """The camera demo's settings (3-D mount, lag search, both solvers) on simulated camera drives of
    each number of poses (the demo's simulation options, longer)."""
    config = REPO / "scenarios" / "data" / "camera_demo.sim.yaml"
    logs = {}
    for n in sizes:
        logs[n] = tmp / f"camera_{n}.tum"  # a fresh folder: nothing to replace
        duration = f"{n / CAMERA_RATE_HZ:g}"
        simulate_log("--config", str(config), "--duration", duration, "--out", str(logs[n]))
    return sized_runs("camera_demo", logs, repeats, tmp, warm_up)


#: One Gauss-Newton pass fused into one C loop: the prefix scan interval by interval, then each
#: window's normal-equation terms from its two prefix jets, summed as they come (no buffer between).
FUSED_DRIVER = """
#include <string.h>
int fused_pass(const double* U, long n_int, const double* x, const double* xf, const double* omega,
               const double* delta, const long* a, const long* b, const double* data, long n_win,
               double* P, double* out) {
  casadi_int iw[IW + 1]; casadi_real w[W + 1]; const casadi_real* arg[ARG]; casadi_real* res[RES];
  double motion[2 * SR], o[NOUT];
  memset(P, 0, SR * sizeof(double));
  for (long j = 0; j < n_int; ++j) {
    arg[0] = P + j * SR; arg[1] = x; arg[2] = xf; arg[3] = U + j * NU; res[0] = P + (j + 1) * SR;
    STEP(arg, res, iw, w, 0);
  }
  memset(out, 0, NOUT * sizeof(double));
  for (long k = 0; k < n_win; ++k) {
    memcpy(motion, P + a[k] * SR, SR * sizeof(double));
    memcpy(motion + SR, P + b[k] * SR, SR * sizeof(double));
    ARGS
    OUTS
    NE(arg, res, iw, w, 0);
    for (int i = 0; i < NOUT; ++i) out[i] += o[i];
  }
  return 0;
}
"""


def fused_loop(fns: Any, tmp: Path) -> Any:
    """The problem's scan step and per-window normal equations generated as C (CasADi's code, as the
    compiled backend generates it) with :data:`FUSED_DRIVER`, compiled with the solvers' flags."""
    import ctypes

    import casadi as ca

    from nlp_calib.codegen.compiler import CFLAGS, find_compiler

    step, ne = fns.step(1), fns.function("normal_equations")
    cg = ca.CodeGenerator("fused.c", {"with_header": False})
    cg.add(step)
    cg.add(ne)
    sources = {"x": "x", "x_fixed": "xf", "omega": "omega", "delta": "delta", "motion": "motion"}
    sources["data"] = f"data + k * {ne.nnz_in(ne.index_in('data'))}"
    args = " ".join(f"arg[{i}] = {sources[ne.name_in(i)]};" for i in range(ne.n_in()))
    offsets = np.cumsum([0] + [ne.nnz_out(i) for i in range(ne.n_out())])
    outs = " ".join(f"res[{i}] = o + {offsets[i]};" for i in range(ne.n_out()))
    sizes = {
        "IW": max(step.sz_iw(), ne.sz_iw()),
        "W": max(step.sz_w(), ne.sz_w()),
        "ARG": max(step.sz_arg(), ne.sz_arg()),
        "RES": max(step.sz_res(), ne.sz_res()),
        "SR": step.nnz_in(0),
        "NU": step.nnz_in(3),
        "NOUT": int(offsets[-1]),
    }
    driver = FUSED_DRIVER.replace("ARGS", args).replace("OUTS", outs)
    driver = driver.replace("STEP(", f"{step.name()}(").replace("NE(", f"{ne.name()}(")
    for key, value in sizes.items():
        driver = driver.replace(key, str(value))
    src, so = tmp / "fused.c", tmp / "fused.so"
    src.write_text(cg.dump() + driver)
    subprocess.run([find_compiler() or "cc", *CFLAGS, str(src), "-o", str(so)], check=True)
    lib = ctypes.CDLL(str(so))
    lib.fused_pass.restype = ctypes.c_int
    return lib, sizes


def gn_pass(records: int, repeats: int, tmp: Path) -> dict[str, Any]:
    """One Gauss-Newton pass (prefix scan, each window's residual, Jacobian, Huber weight and normal
    equations, summed) on the demo's settings over a simulated log: the evaluator the solvers call
    against the same computation fused into one C loop, at a new point each time, interleaved."""
    import ctypes

    from nlp_calib.pipeline import Calibration, load_scenario

    log = tmp / f"pass_{records}.txt"
    simulate_log("--records", str(records), "--seed", "11", "--out", str(log), "--force")
    calib = Calibration(load_scenario(REPO / "scenarios" / "demo.yaml").with_dataset(log))
    ev = calib.evaluator
    lib, sizes = fused_loop(ev.fns, tmp)
    data = ev.data
    U = np.asfortranarray(data.inputs, dtype=float)
    windows = np.asfortranarray(data.data())
    a, b = (np.ascontiguousarray(v, dtype=np.int64) for v in (data.starts, data.stops))
    P = np.zeros((sizes["SR"], U.shape[1] + 1), order="F")
    out = np.zeros(sizes["NOUT"])
    fixed, omega, delta = ev.x_fixed.copy(), ev.omega.copy(), np.array([ev.delta])

    def ptr(v: np.ndarray) -> Any:
        return v.ctypes.data_as(ctypes.c_void_p)

    def fused(x: np.ndarray) -> np.ndarray:
        lib.fused_pass(ptr(U), ctypes.c_long(U.shape[1]), ptr(x), ptr(fixed), ptr(omega), ptr(delta),
                       ptr(a), ptr(b), ptr(windows), ctypes.c_long(a.size), ptr(P), ptr(out))  # fmt: skip
        return out[ev.fns.n_free * (ev.fns.n_free + 1) // 2 :][: ev.fns.n_free].copy()

    times: dict[str, list[float]] = {"evaluator": [], "fused C loop": []}
    # The process's CPU time (every thread's) beside the wall time: on a shared machine the wall
    # time measures the other processes too.
    cpu: dict[str, list[float]] = {"evaluator": [], "fused C loop": []}
    agree = 0.0
    start = load()
    for k in range(repeats + 1):  # the first round warms up, untimed
        x = calib.x0 * (1.0 + 1e-6 * (k + 1))
        t0, c0 = time.perf_counter(), time.process_time()
        g_ours = ev.normal_equations(x).g
        t1, c1 = time.perf_counter(), time.process_time()
        g_fused = fused(x)
        t2, c2 = time.perf_counter(), time.process_time()
        if k:
            times["evaluator"].append(1e3 * (t1 - t0))
            times["fused C loop"].append(1e3 * (t2 - t1))
            cpu["evaluator"].append(1e3 * (c1 - c0))
            cpu["fused C loop"].append(1e3 * (c2 - c1))
        agree = max(agree, float(np.max(np.abs(g_ours - g_fused)) / np.max(np.abs(g_ours))))
    medians = {name: med(t) for name, t in times.items()}
    cpu_medians = {name: med(t) for name, t in cpu.items()}
    return {
        "load_start": start,
        "load_end": load(),
        "records": records,
        "windows": int(a.size),
        "median_ms": medians,
        "ratio": medians["evaluator"] / medians["fused C loop"],
        "median_cpu_ms": cpu_medians,
        "cpu_ratio": cpu_medians["evaluator"] / cpu_medians["fused C loop"],
        "gradient_rel_difference": agree,
    }


def simulate_big(records: int, repeats: int, tmp: Path) -> dict[str, Any]:
    """``nlp-calib simulate --records N`` (written block by block): wall and peak RSS."""
    env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONWARNINGS="ignore")
    start = load()
    runs = [
        launch(cli("simulate", "--records", str(records), "--out", str(tmp / "big.txt"), "--force"), env)
        for _ in range(repeats)
    ]
    size = (tmp / "big.txt").stat().st_size
    (tmp / "big.txt").unlink()
    return {
        "load_start": start,
        "load_end": load(),
        "records": records,
        "file_mb": size / 1e6,
        "wall_s": med([r["wall_s"] for r in runs]),
        "peak_mb": med([r["peak_mb"] for r in runs]),
    }


def batch(n_logs: int, records: int, repeats: int, tmp: Path, warm_up: bool = True) -> dict[str, Any]:
    """``nlp-calib batch`` of ``n_logs`` simulated logs with ``--jobs 1`` and ``--jobs 2``,
    interleaved: median walls and their ratio (without ``warm_up`` the first also compiles)."""
    env = warm_env()
    logs = tmp / "fleet"
    logs.mkdir(exist_ok=True)
    for seed in range(n_logs):
        drive = logs / f"drive_{seed:02d}.txt"
        simulate_log("--records", str(records), "--seed", str(100 + seed), "--out", str(drive), "--force")
    scenario = str(REPO / "scenarios" / "demo.yaml")

    def once(jobs: int) -> tuple[float, float]:
        out = tmp / f"batch-{jobs}"
        shutil.rmtree(out, ignore_errors=True)
        args = ("--scenario", scenario, "--solver", "gauss_newton", "--out", str(out), "--jobs", str(jobs))
        r = launch(cli("batch", str(logs), *args), env)
        if r["rc"] != 0:
            raise SystemExit(f"batch --jobs {jobs} failed with exit code {r['rc']}")
        return float(r["wall_s"]), float(r["cpu_s"])

    if warm_up:
        once(1)  # fills the compile cache (not timed)
    start = load()
    walls: dict[int, list[float]] = {1: [], 2: []}
    cpus: dict[int, list[float]] = {1: [], 2: []}
    for _ in range(repeats):
        for jobs in (1, 2):
            wall, cpu = once(jobs)
            walls[jobs].append(wall)
            cpus[jobs].append(cpu)
    return {
        "load_start": start,
        "load_end": load(),
        "logs": n_logs,
        "records": records,
        "jobs_1_s": walls[1],
        "jobs_2_s": walls[2],
        "jobs_1_cpu_s": cpus[1],
        "jobs_2_cpu_s": cpus[2],
        "speedup": med(walls[1]) / med(walls[2]),
    }


def reader(records: int, repeats: int, tmp: Path) -> dict[str, Any]:
    """The log reader on a simulated log of ``records`` records against the compiled CSV readers
    installed (pandas' C parser; pyarrow's): medians of interleaved reads, in this process, and
    whether their poses are the reader's to the bit."""
    import warnings

    from nlp_calib.logs.reader import read_log

    path = tmp / "reader.txt"
    simulate_log("--records", str(records), "--out", str(path), "--force")
    kinds: dict[str, Any] = {"steering": "absolute", "traction_wheel": "counter"}
    ours = read_log(path, kinds)
    poses = np.hstack([ours.model_pose, ours.T_world_sensor])
    candidates: dict[str, Callable[[], Any]] = {
        "nlp_calib": lambda: read_log(path, kinds),
        # The same numbers of every record (time, counters, poses), as doubles, by numpy's C reader.
        "numpy.loadtxt": lambda: np.loadtxt(path, usecols=(1, 3, 4, 6, 7, 8, 10, 11, 12), comments="#"),
    }
    try:
        import pandas as pd

        def with_pandas() -> np.ndarray:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cols = [6, 7, 8, 10, 11, 12]
                df = pd.read_csv(path, sep=r"\s+", comment="#", header=None, usecols=cols)
            return np.asarray(df.to_numpy(float))

        candidates["pandas.read_csv (poses only)"] = with_pandas
    except ImportError:
        pass
    times: dict[str, list[float]] = {name: [] for name in candidates}
    start = load()
    for _ in range(repeats):
        for name, fn in candidates.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    exact = {
        name: bool(np.array_equal(np.asarray(fn())[:, -6:].view(np.int64), poses.view(np.int64)))
        for name, fn in candidates.items()
        if name != "nlp_calib"
    }
    return {"load_start": start, "load_end": load(), "records": records, "times_s": times, "bitwise": exact}


def environment() -> dict[str, Any]:
    import casadi

    cc = shutil.which(os.environ.get("CC") or "cc") or "none"
    version = (
        subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()[:1]
        if cc != "none"
        else []
    )
    cpu = (
        next(
            (
                ln.split(":", 1)[1].strip()
                for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")
            ),
            platform.processor(),
        )
        if Path("/proc/cpuinfo").exists()
        else platform.processor()
    )
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "casadi": casadi.__version__,
        "numpy": np.__version__,
        "compiler": version[0] if version else cc,
    }


def fleet_lines(doc: dict[str, Any], figures: dict[str, float]) -> list[str]:
    """The simulate and batch sections' lines; their figures into ``figures``."""
    lines = []
    sim, fleet = doc.get("simulate"), doc.get("batch")
    if sim:
        lines += [
            "",
            f"`nlp-calib simulate --records {sim['records']:,}` (written block by block; load average "
            f"{sim['load_start']} → {sim['load_end']}): {sim['wall_s']:.1f} s, "
            f"peak RSS {sim['peak_mb']:.0f} MB, "
            f"{sim['file_mb']:.0f} MB of text.",
        ]
        figures[f"simulate {sim['records']} records peak RSS [MB]"] = sim["peak_mb"]
    if fleet:
        lines += [
            "",
            f"`nlp-calib batch` of {fleet['logs']} simulated logs of {fleet['records']} records "
            "(demo scenario, "
            f"Gauss-Newton; load average {fleet['load_start']} → {fleet['load_end']}): --jobs 1 "
            f"{med(fleet['jobs_1_s']):.1f} s, --jobs 2 {med(fleet['jobs_2_s']):.1f} s, "
            f"{fleet['speedup']:.2f}× faster"
            + (
                f"; CPU time {med(fleet['jobs_1_cpu_s']):.1f} s and {med(fleet['jobs_2_cpu_s']):.1f} s "
                f"(--jobs 1 / wall {med(fleet['jobs_1_cpu_s']) / med(fleet['jobs_1_s']):.2f} cores)."
                if "jobs_1_cpu_s" in fleet
                else "."
            ),
        ]
        figures[f"batch of {fleet['logs']} logs, --jobs 1 / --jobs 2 [x]"] = fleet["speedup"]
    gp = doc.get("gn_pass")
    if gp:
        lines += [
            "",
            f"One Gauss-Newton pass (prefix scan, residuals, Jacobians, Huber weights, normal equations) "
            f"on the demo's settings, {gp['windows']:,} windows (load average {gp['load_start']} → "
            f"{gp['load_end']}): the evaluator {gp['median_ms']['evaluator']:.1f} ms, the same fused into "
            f"one C loop {gp['median_ms']['fused C loop']:.1f} ms (×{gp['ratio']:.2f}; gradients agree "
            f"to {gp['gradient_rel_difference']:.1e}).",
        ]
        if "cpu_ratio" in gp:
            lines[-1] += (
                f" CPU: {gp['median_cpu_ms']['evaluator']:.1f} ms against "
                f"{gp['median_cpu_ms']['fused C loop']:.1f} ms (×{gp['cpu_ratio']:.2f})."
            )
            figures["Gauss-Newton pass / fused C loop, CPU [x]"] = gp["cpu_ratio"]
        figures["Gauss-Newton pass / fused C loop [x]"] = gp["ratio"]
    rd = doc.get("reader")
    if rd:
        each = ", ".join(
            f"{name} {med(t):.2f} s"
            + ("" if name not in rd["bitwise"] else f" (poses to the bit: {rd['bitwise'][name]})")
            for name, t in rd["times_s"].items()
        )
        lines += [
            "",
            f"Reading a simulated log of {rd['records']:,} records (load average {rd['load_start']} → "
            f"{rd['load_end']}): {each}.",
        ]
        if "numpy.loadtxt" in rd["times_s"]:
            ratio = med(rd["times_s"]["nlp_calib"]) / med(rd["times_s"]["numpy.loadtxt"])
            figures[f"reader / numpy.loadtxt, {rd['records']:g} records [x]".replace("1e+06", "10^6")] = ratio
    return lines


def summary(doc: dict[str, Any]) -> tuple[str, dict[str, float]]:
    """The report's tables and the figures each target is judged by."""
    e2e, sol, scale = doc.get("end_to_end"), doc.get("solvers"), doc.get("scaling")
    env = doc["environment"]
    lines = [
        f"Machine: {env['cpu']}, {env['cores']} cores; {env['compiler']}; Python {env['python']}, "
        f"CasADi {env['casadi']}, numpy {env['numpy']}. Medians of {doc['repeats']} interleaved repeats.",
    ]
    figures: dict[str, float] = {}
    if e2e:
        lines += e2e_lines(e2e)
    if sol:
        lines += solver_lines(sol, figures)
    if doc.get("ipopt_lag"):
        lines += ipopt_lag_lines(doc["ipopt_lag"])
    if scale:
        lines += scale_lines(scale, figures)
    lines += fleet_lines(doc, figures)
    for key in ("horizon", "camera"):
        if doc.get(key):
            lines += sized_lines(doc[key], figures)
    if e2e:
        floor_figures(e2e, figures)
    lines += ["", "| target | measured | target | met |", "|---|---|---|---|"]
    for name, target in TARGETS.items():
        if name in figures:
            v = figures[name]
            at_least = name in AT_LEAST
            met = v >= target if at_least else v <= target
            sign = "≥" if at_least else "≤"
            lines.append(f"| {name} | {v:.3g} | {sign} {target:g} | {'yes' if met else 'no'} |")
    return "\n".join(lines), figures


def floor_figures(e2e: dict[str, Any], figures: dict[str, float]) -> None:
    """The end-to-end figures judged by a target: times, and ratios to the import floor in CPU
    (user+sys of the processes: a wall time says as much of the machine's load as of the run)."""
    floor = e2e.get("import_floor_cpu_s") or float("nan")
    r = e2e["scenarios"].get("real_tricycle")
    if r:
        figures["compare real_tricycle.yaml, warm [s]"] = r["warm_wall_s"]
        figures["compare real_tricycle.yaml, cold [s]"] = r["cold_wall_s"]
        figures["compare real_tricycle.yaml, warm / import floor [x]"] = r["warm_cpu_s"] / floor
        figures["compare real_tricycle.yaml, cold / import floor [x]"] = r["cold_cpu_s"] / floor
    cam = e2e["scenarios"].get("camera_demo")
    if cam:
        figures["compare camera_demo.yaml, warm / import floor [x]"] = cam["warm_cpu_s"] / floor
    if e2e.get("import_commands_cpu_s"):
        figures["import nlp_calib.cli.commands / import floor [x]"] = e2e["import_commands_cpu_s"] / floor


def sized_lines(run: dict[str, Any], figures: dict[str, float]) -> list[str]:
    """A scenario's settings on growing logs: the table, and its 10^5 and 10^6 figures."""
    name = run["scenario"]
    word = "poses" if name == "camera_demo" else "records"
    solvers = sorted({k[:-3] for r in run["sizes"].values() for k in r if k.endswith("_ms")})
    lines = [
        "",
        f"`nlp-calib run scenarios/{name}.yaml --data LOG` (its settings and solvers) on simulated logs "
        f"(load average {run['load_start']} → {run['load_end']}):",
        "",
        f"| {word} | wall [s] | CPU [s] | peak RSS [MB] | " + " | ".join(f"{s} [ms]" for s in solvers) + " |",
        "|---|---|---|---|" + "---|" * len(solvers),
    ]
    for n, r in run["sizes"].items():
        each = " | ".join(f"{r.get(f'{s}_ms', float('nan')):.0f}" for s in solvers)
        lines.append(f"| {int(n):,} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r['peak_mb']:.0f} | {each} |")
    for k, v in run["growth"].items():
        big, small = k.split("/")
        lines.append(f"\nWall time from {int(small):,} to {int(big):,} {word}: ×{v:.2f}.")
    million = run["sizes"].get("1000000")
    if million:
        figures[f"{name} settings, 10^6 {word} run [s]"] = million["wall_s"]
        figures[f"{name} settings, 10^6 {word} peak RSS [MB]"] = million["peak_mb"]
    if "1000000/100000" in run["growth"]:
        figures[f"{name} settings, run time 10^6 / 10^5 {word} [x]"] = run["growth"]["1000000/100000"]
    return lines


def e2e_lines(e2e: dict[str, Any]) -> list[str]:
    lines = [
        "",
        "End to end, `nlp-calib compare SCENARIO` in a fresh process "
        f"(load average {e2e['load_start']} → {e2e['load_end']}); solver times as the run reports them; "
        "the code's bytecode kept between runs, as an installed package keeps it; the floor, "
        f"`python -c 'import numpy, casadi'`: {e2e.get('import_floor_cpu_s', float('nan')):.3f} s CPU "
        f"({e2e.get('import_floor_s', float('nan')):.3f} s wall); "
        "`python -c 'import nlp_calib.cli.commands'`: "
        f"{e2e.get('import_commands_cpu_s', float('nan')):.3f} s CPU; CPU is user+sys, the ratios "
        "to the floor are CPU's:",
        "",
        "| scenario | cold cache [s] | warm cache [s] | cold CPU [s] | warm CPU [s] | peak RSS [MB] "
        "| Gauss-Newton [ms] | IPOPT [ms] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, r in e2e["scenarios"].items():
        lines.append(
            f"| {name} | {r['cold_wall_s']:.2f} | {r['warm_wall_s']:.2f} "
            f"| {r.get('cold_cpu_s', float('nan')):.2f} | {r.get('warm_cpu_s', float('nan')):.2f} "
            f"| {r['warm_peak_mb']:.0f} | "
            f"{r.get('gauss_newton_ms', float('nan')):.1f} | {r.get('ipopt_ms', float('nan')):.1f} |"
        )
    return lines


def solver_lines(sol: dict[str, Any], figures: dict[str, float]) -> list[str]:
    lines = [
        "",
        "Solvers on the same windows and objective, in-process "
        f"(load average {sol['load_start']} → {sol['load_end']}):",
        "",
        "| case | residuals | solver | median [ms] | × Gauss-Newton | cost vs GN (rel.) "
        "| parameters vs GN (max rel.) |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, c in sol["cases"].items():
        gn = c["median_ms"]["gauss_newton"]
        for name, ms in c["median_ms"].items():
            a = c["agreement"][name]
            lines.append(
                f"| {label} | {c['residuals']} | {name} | {ms:.1f} | {ms / gn:.1f} | {a['cost_rel']:.1e} "
                f"| {a['param_rel']:.1e} |"
            )
        h = "H=1" if "H=1" in label else "H=25" if "H=25" in label else None
        if h:
            for kind in ("prefix", "per window"):
                figures[f"scipy ({kind}) / GN, {h} [x]"] = c["median_ms"][f"scipy (numpy, {kind})"] / gn
        scenario = label.split(" ")[0]
        if scenario.startswith("real_tricycle"):
            figures[f"{scenario} GN [ms]"] = gn
            figures[f"{scenario} IPOPT [ms]"] = c["median_ms"]["ipopt"]
    return lines


def scale_lines(scale: dict[str, Any], figures: dict[str, float]) -> list[str]:
    lines = [
        "",
        "`run --solver gauss_newton` on simulated logs "
        f"(load average {scale['load_start']} → {scale['load_end']}):",
        "",
        "| records | wall [s] | peak RSS [MB] | Gauss-Newton [ms] |",
        "|---|---|---|---|",
    ]
    for n, r in scale["sizes"].items():
        lines.append(f"| {int(n):,} | {r['wall_s']:.2f} | {r['peak_mb']:.0f} | {r['gn_ms']:.0f} |")
    lines.append(f"\nWall time ∝ N^{scale['wall_slope']:.2f} over these sizes.")
    if "1000000" in scale["sizes"]:
        figures["10^6 records run --solver gauss_newton [s]"] = scale["sizes"]["1000000"]["wall_s"]
        figures["10^6 records peak RSS [MB]"] = scale["sizes"]["1000000"]["peak_mb"]
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small sizes and 2 repeats (smoke test)")
    ap.add_argument(
        "--repeats", type=int, default=None, help="interleaved repeats (default 7; 2 with --quick)"
    )
    ap.add_argument(
        "--data",
        type=Path,
        default=None,
        help="the real log (default: shared/data/dataset.txt above the checkout)",
    )
    ap.add_argument(
        "--sections",
        default=",".join(SECTIONS),
        help=f"comma-separated sections to measure (default: all of {', '.join(SECTIONS)})",
    )
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args()
    sections = [x.strip() for x in args.sections.split(",")]
    if not set(sections) <= set(SECTIONS):
        ap.error(f"--sections takes {', '.join(SECTIONS)}")
    repeats = args.repeats or (2 if args.quick else 7)
    real = args.data or next(
        (p / "shared/data/dataset.txt" for p in REPO.parents if (p / "shared/data/dataset.txt").is_file()),
        None,
    )
    doc: dict[str, Any] = {"environment": environment(), "repeats": repeats, "quick": args.quick}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        for section in sections:
            print(f"{section} ...", file=sys.stderr)
            doc[section] = measure(section, args.quick, real, repeats, tmp)
    text, figures = summary(doc)
    doc["figures"] = figures
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "performance.json").write_text(json.dumps(doc, indent=2) + "\n")
    (args.out / "performance.md").write_text(text + "\n")
    if "scaling" in doc:
        from nlp_calib.outputs.plots import scaling_png

        (args.out / "performance.png").write_bytes(scaling_png(doc["scaling"]["sizes"]))
    print(text)
    return 0


def measure(section: str, quick: bool, real: Path | None, repeats: int, tmp: Path) -> dict[str, Any]:
    """One section's measurements."""
    if section == "end_to_end":
        if quick or real is None:
            scenarios: list[tuple[str, list[str]]] = [("demo", [])]
        else:
            scenarios = [(n, ["--data", str(real)]) for n in ("real_tricycle", "real_tricycle_seed")]
            scenarios += [("demo", []), ("diff_drive_demo", []), ("camera_demo", [])]
        return end_to_end(scenarios, repeats, tmp, not quick)
    if section == "solvers":
        return solvers(solver_cases(real, quick), repeats, per_factor=not quick)
    if section == "ipopt_lag":
        return ipopt_lag(real, quick, repeats)
    if section == "scaling":
        return scaling([2_000, 8_000] if quick else [10_000, 100_000, 1_000_000], repeats, tmp, not quick)
    # A 10^6 run takes about a minute: 3 repeats. The smoke run measures these once (its
    # interleaving is the end-to-end and scaling sections').
    sized = 1 if quick else min(repeats, 3)
    if section == "horizon":
        return horizon([1_000, 2_000] if quick else [100_000, 1_000_000], sized, tmp, not quick)
    if section == "camera":
        return camera([1_000, 2_000] if quick else [100_000, 1_000_000], sized, tmp, not quick)
    if section == "simulate":
        return simulate_big(10_000 if quick else 1_000_000, 1 if quick else 3, tmp)
    if section == "reader":
        return reader(10_000 if quick else 1_000_000, repeats, tmp)
    if section == "gn_pass":
        return gn_pass(5_000 if quick else 100_000, repeats, tmp)
    # Logs of 5000 records (3.3 minutes of driving): a robot's daily log is rarely shorter.
    return batch(2 if quick else 20, 300 if quick else 5000, 1 if quick else repeats, tmp, not quick)


if __name__ == "__main__":
    raise SystemExit(main())
