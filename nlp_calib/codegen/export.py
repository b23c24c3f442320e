"""C export of the residual and its Jacobian (``nlp-calib codegen SCENARIO.yaml --out DIR``).

The exported Functions are the problem's own (:mod:`nlp_calib.problem.functions`), wrapped with a
plain signature for C callers: ``(params[n], u[n_in x H], z[3]) -> (e[3], J[3 x n])``, column-
major like all CasADi data. ``J`` is the Jacobian with respect to the manifold perturbation (the
sensor pose perturbed on the left: ``v2t(Δ)·T_base_sensor``). Both the single-step (H = 1) and
the scenario's horizon variant are written, with a header, an ``example.c`` that calls them and
a Makefile.

A 3-D sensor's problem exports ``(params[n], u[n_in x H], z[7]) -> (e[6], J[6 x m])``: ``z`` the
camera's motion ``(x, y, z, qx, qy, qz, qw)``, ``e`` its ``Log`` error and ``J`` the columns of the
parameters the problem estimates (``m = n − 1``: ``sensor_z`` never enters the residual), the
mount's rotation perturbed on SO(3) from the left (see :mod:`nlp_calib.sensors`).

When the scenario fits the tracker lag, ``tracker_lag`` closes ``params`` and the functions take a
fourth input, ``clock[2·n_in + 1]``: the inputs' rates at the window's first and last record (per
second; a level input: its value) and the lag the inputs were read at (s; 0 when read as
logged): the residual moves the window along the encoders' clock by the difference
(:mod:`nlp_calib.problem.clock`).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.version import __version__
from nlp_calib.models.base import KinematicModel
from nlp_calib.problem import ProblemFunctions, ProblemSpec, build

BASENAME = "nlp_calib_residual"
PREFIX = "nlp_calib_"


@dataclass(frozen=True)
class ExportedFunction:
    """A Function in the generated C, with what a C caller needs to know."""

    function: ca.Function
    horizon: int
    n_params: int
    n_inputs: int
    n_free: int
    error_rows: int
    z_rows: int


def export_functions(fns: ProblemFunctions) -> list[ExportedFunction]:
    """``residual`` and ``residual_jacobian`` of ``fns`` with a C-friendly signature."""
    if fns.spec.fixed:
        raise ProblemError("export a problem without fixed parameters (the C caller passes all of them)")
    H, n_in, n = fns.spec.horizon, fns.n_inputs, len(fns.names)
    params = ca.SX.sym("params", n)
    x, x_fixed = params, ca.SX(0, 1)
    if fns.fixed:  # held by the problem itself (a 3-D mount's sensor_z): passed, not differentiated
        x = ca.vertcat(*[params[fns.names.index(f)] for f in fns.free])
        x_fixed = ca.vertcat(*[params[fns.names.index(f)] for f in fns.fixed])
    if fns.spec.lags > 1:
        raise ProblemError("export a problem of one log (one tracker lag)")
    U = ca.SX.sym("u", n_in, H)
    z = ca.SX.sym("z", fns.sensor.z_rows)
    # With the lag a parameter: the inputs' rates at the window's ends and the lag the inputs were
    # read at (the one log's selector is 1).
    clock = ca.SX.sym("clock", 2 * n_in + 1 if fns.spec.lags else 0)
    data = ca.vertcat(ca.reshape(U, n_in * H, 1), z, clock, *([1.0] if fns.spec.lags else []), 1.0)
    e = fns.residual(x, x_fixed, data)
    e_j, J = fns.residual_jacobian(x, x_fixed, data)
    ins, in_names = [params, U, z, *([clock] if fns.spec.lags else [])], ["params", "u", "z", "clock"]
    suffix = f"_h{H}"
    sizes = (H, n, n_in, fns.n_free, fns.error_rows, fns.sensor.z_rows)
    return [
        ExportedFunction(
            ca.Function(f"{PREFIX}residual{suffix}", ins, [e], in_names[: len(ins)], ["e"]), *sizes
        ),
        ExportedFunction(
            ca.Function(
                f"{PREFIX}residual_jacobian{suffix}", ins, [e_j, J], in_names[: len(ins)], ["e", "J"]
            ),
            *sizes,
        ),
    ]


#: Characters written into a C string literal or comment as they are; every other one (quotes,
#: backslashes, ``?`` of a trigraph, ``%``, the ``*`` of a comment's end, control and non-ASCII
#: characters) is escaped: text from inputs (file and scenario names) never becomes code.
_PLAIN = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 ,.:;_-+=()[]<>#@!&|~^$'/")


def c_string(text: str) -> str:
    """``text`` as the body of a C string literal that prints it unchanged (with ``printf("%s")``
    or ``puts``): UTF-8 bytes (a name's undecodable bytes as they were) outside :data:`_PLAIN` as
    octal escapes, which no following character can extend."""
    raw = text.encode("utf-8", errors="surrogateescape")
    return "".join(chr(b) if chr(b) in _PLAIN else f"\\{b:03o}" for b in raw)


def c_comment(text: str) -> str:
    """``text`` safe inside a ``/* */`` comment: every character outside :data:`_PLAIN` becomes
    ``_`` (no ``*/`` can end the comment, no line splice or trigraph can form)."""
    return "".join(c if c in _PLAIN else "_" for c in text)


def _banner(what: str, origin: str) -> str:
    return (
        f"/* {what}\n"
        f" * Autogenerated by nlp_calib {__version__} from {c_comment(origin)}: do not edit.\n"
        " * Regenerate with `nlp-calib codegen SCENARIO.yaml --out DIR`. */\n"
    )


def _c_array(values: np.ndarray) -> str:
    return ", ".join(f"{v:.17g}" for v in np.ravel(values, order="F"))


@dataclass(frozen=True)
class Example:
    """What ``example.c`` evaluates: ``params`` (described by ``params_from``) on one window's
    data ``column`` (described by ``window``)."""

    params: np.ndarray
    params_from: str
    column: np.ndarray
    window: str


#: What ``z`` holds, by its rows (a planar or a 3-D sensor).
_MOTION = {
    3: "t2v(T(p_k)^-1 T(p_k+H)): x, y, theta",
    7: "T(p_k)^-1 T(p_k+H): x, y, z, qx, qy, qz, qw (the sensor's frame at k)",
}


def example_source(fns: ProblemFunctions, exported: ExportedFunction, example: Example, origin: str) -> str:
    """A C program that calls ``exported`` (a residual_jacobian) on one window, prints e and J, and
    compares them with the values Python computes for the same call."""
    f, name = exported.function, exported.function.name()
    n, n_in, H, zr = exported.n_params, exported.n_inputs, exported.horizon, exported.z_rows
    r, nj = exported.error_rows, exported.error_rows * exported.n_free
    params, column = example.params, example.column
    U, z = column[: n_in * H], column[n_in * H : n_in * H + zr]
    clock = column[n_in * H + zr : n_in * H + zr + 2 * n_in + 1] if fns.spec.lags else np.zeros(0)
    ins = [params, U.reshape(n_in, H, order="F"), z, *([clock] if fns.spec.lags else [])]
    e_py, J_py = (np.asarray(v) for v in f(*ins))
    names, inputs = ", ".join(fns.names), ", ".join(fns.model.input_names)
    return (
        _banner(f"Example: calling {name} from C.", origin)
        + f"""#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include "{BASENAME}.h"

int main(void) {{
  /* Parameters ({c_comment(example.params_from)}), in this order: {c_comment(names)}. */
  const casadi_real params[{n}] = {{{_c_array(params)}}};
  /* Model inputs of the {H} interval(s), interval after interval: {c_comment(inputs)}. */
  const casadi_real u[{n_in * H}] = {{{_c_array(U)}}};
  /* Measured sensor motion {_MOTION.get(zr, f"in {zr} rows, as sensor {fns.sensor.kind} lays out its z")}. */
  const casadi_real z[{zr}] = {{{_c_array(z)}}};
{_clock_lines(fns, clock)}  casadi_real e[{r}], J[{nj}]; /* J is column-major: J[i + {r}*j] = de_i/ddelta_j */

  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  {name}_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = malloc(sz_arg * sizeof(*arg));
  casadi_real** res = malloc(sz_res * sizeof(*res));
  casadi_int* iw = malloc((sz_iw > 0 ? sz_iw : 1) * sizeof(*iw));
  casadi_real* w = malloc((sz_w > 0 ? sz_w : 1) * sizeof(*w));
  arg[0] = params; arg[1] = u; arg[2] = z;{" arg[3] = clock;" if fns.spec.lags else ""}
  res[0] = e; res[1] = J;
  if ({name}(arg, res, iw, w, 0) != 0) {{ fprintf(stderr, "evaluation failed\\n"); return 1; }}

  /* What Python computes for the same call (nlp_calib, CasADi's interpreter). */
  const casadi_real e_python[{r}] = {{{_c_array(e_py)}}};
  const casadi_real J_python[{nj}] = {{{_c_array(J_py)}}};
  double de = 0.0, dJ = 0.0;
  printf("%s\\n", "{c_string("window: " + example.window)}");
  printf("%s\\n", "{c_string("parameters: " + example.params_from)}");
  for (int i = 0; i < {r}; ++i) {{
    printf("e %d %.17g\\n", i, e[i]);
    de = fmax(de, fabs(e[i] - e_python[i]));
  }}
  for (int k = 0; k < {nj}; ++k) {{
    printf("J %d %.17g\\n", k, J[k]);
    dJ = fmax(dJ, fabs(J[k] - J_python[k]));
  }}
  printf("largest difference from Python: e %.3g, J %.3g\\n", de, dJ);
  free(arg); free(res); free(iw); free(w);
  return 0;
}}
"""
    )


def _clock_lines(fns: ProblemFunctions, clock: np.ndarray) -> str:
    """The example's clock array (the lag a parameter), or nothing."""
    if not fns.spec.lags:
        return ""
    inputs = c_comment(", ".join(fns.model.input_names))
    return (
        f"  /* The clock: the inputs' rates at the window's first and last record (per second; a level "
        f"its value; {inputs}), then the lag (s) the inputs were read at. */\n"
        f"  const casadi_real clock[{clock.size}] = {{{_c_array(clock)}}};\n"
    )


MAKEFILE = """# Autogenerated by nlp_calib: do not edit.
CFLAGS ?= -O2
example: example.c {base}.c {base}.h
\t$(CC) $(CFLAGS) -o $@ example.c {base}.c -lm
lib{base}.so: {base}.c {base}.h
\t$(CC) $(CFLAGS) -fPIC -shared -o $@ {base}.c -lm
"""


def generate(
    fns_by_horizon: list[ProblemFunctions], out_dir: Path, example: Example, origin: str
) -> list[Path]:
    """Write ``nlp_calib_residual.{c,h}``, ``example.c`` and a Makefile into ``out_dir``."""
    exported = [e for fns in fns_by_horizon for e in export_functions(fns)]
    cg = ca.CodeGenerator(f"{BASENAME}.c", {"with_header": True})
    for e in exported:
        cg.add(e.function)
    written = []
    # CasADi writes into a private folder of its own: the output folder's path may hold the file's
    # name (CasADi asserts it does not) or a link where a scratch folder would go.
    with tempfile.TemporaryDirectory(prefix="codegen-") as scratch:
        cg.generate(str(scratch) + "/")
        for suffix, what in (
            (".c", "Residual and Jacobian of the calibration problem."),
            (".h", "Declarations."),
        ):
            text = (Path(scratch) / f"{BASENAME}{suffix}").read_text()
            path = out_dir / f"{BASENAME}{suffix}"
            atomic_write_text(path, _banner(what, origin) + text)
            written.append(path)
    last = fns_by_horizon[-1]
    jac = next(e for e in exported if e.horizon == last.spec.horizon and "jacobian" in e.function.name())
    program = out_dir / "example.c"
    atomic_write_text(program, example_source(last, jac, example, origin))
    makefile = out_dir / "Makefile"
    atomic_write_text(makefile, MAKEFILE.format(base=BASENAME))
    return [*written, program, makefile]


def build_for_export(
    model: KinematicModel,
    horizon: int,
    integration: str,
    sensor: str = "planar",
    scale: str = "fixed",
    lags: int = 0,
) -> list[ProblemFunctions]:
    """The single-step problem and, when different, the ``horizon`` one, without fixed parameters
    (beyond those the sensor always holds); with ``lags`` (0 or 1) the tracker lag a parameter."""
    return [
        build(model, ProblemSpec(horizon=H, integration=integration, sensor=sensor, scale=scale, lags=lags))
        for H in sorted({1, horizon})
    ]
