"""Fuzzing the command line's options and nested scenario blocks: only the package's own errors.

Option values come from numbers of every size and sign, NaN, infinities and garbage words; each is
either accepted inside the option's stated range or refused by a usage error that names the
option. Scenario files are written as YAML text, block by block, with keys drawn from each
block's own fields (and misspellings), values of every type, exponent-form numbers, duplicated
keys and aliases; whatever comes in, the result is a valid Scenario or a ScenarioError.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
import typing
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nlp_calib import cli
from nlp_calib.cli.parser import SIGMA, build_parser
from nlp_calib.core.config import MAX_YAML_VALUES, parse_yaml
from nlp_calib.core.errors import NlpCalibError, ScenarioError, UsageError
from nlp_calib.core.ranges import Range
from nlp_calib.pipeline.scenario import Scenario, load_scenario
from nlp_calib.pipeline.simconfig import CLI_LIMITS, simulation_options
from nlp_calib.problem.windows import HORIZON, STRIDE

FUZZ = settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

#: (subcommand, option, dest, range) of every numeric option.
NUMERIC_OPTIONS = [
    ("simulate", "--records", "records", CLI_LIMITS["records"]),
    ("simulate", "--seed", "seed", CLI_LIMITS["seed"]),
    ("simulate", "--noise-xy", "tracker_noise_xy", CLI_LIMITS["tracker_noise_xy"]),
    ("simulate", "--noise-theta", "tracker_noise_theta", CLI_LIMITS["tracker_noise_theta"]),
    ("simulate", "--outliers", "outlier_fraction", CLI_LIMITS["outlier_fraction"]),
    ("simulate", "--latency", "latency_s", CLI_LIMITS["latency_s"]),
    ("odometry", "--sigma", "sigma", SIGMA),
]

WORDS = [
    "nan",
    "NaN",
    "-nan",
    "inf",
    "-inf",
    "1e400",
    "-0",
    "0x10",
    "1_000",
    "",
    " ",
    "abc",
    "1e-2",
    "٣",
    "--",
]
_number_text = st.one_of(
    st.sampled_from(WORDS),
    st.integers(min_value=-(2**70), max_value=2**70).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(min_value=-2, max_value=2).map(repr),
    st.integers(min_value=-3, max_value=60_000).map(str),
    st.text(max_size=5),
)


def _in_range(value: Any, limit: Range) -> bool:
    return limit.problem(value) is None


@FUZZ
@given(option=st.sampled_from(NUMERIC_OPTIONS), text=_number_text)
def test_numeric_options_are_in_range_or_refused_naming_the_option(
    option: tuple[str, str, str, Range], text: str
) -> None:
    command, flag, dest, limit = option
    argv = [command, "--out", "x", f"{flag}={text}"] if command == "simulate" else [command, "s.yaml"]
    if command != "simulate":
        argv += [f"{flag}={text}"]
    try:
        args = build_parser().parse_args(argv)
    except UsageError as exc:
        message = str(exc)
        assert f"argument {flag}" in message and limit.describe() in message, message
        assert "\n" not in message
        return
    value = getattr(args, dest)
    assert _in_range(value, limit), (text, value)
    if command == "simulate":
        opts = simulation_options(None, {dest: value})
        assert opts.flat()[dest] == value


_sim_flags = st.lists(
    st.tuples(
        st.sampled_from([o for o in NUMERIC_OPTIONS if o[0] == "simulate" and o[1] != "--records"]),
        _number_text,
    ),
    max_size=3,
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    flags=_sim_flags,
    records=st.integers(min_value=-5, max_value=80),
    config=st.sampled_from(["", "x", "bad"]),
)
def test_simulate_writes_both_files_or_nothing(
    flags: list[tuple[tuple[str, str, str, Range], str]], records: int, config: str
) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        argv = ["simulate", "--out", str(folder / "log.txt"), "--records", str(records)]
        argv += [f"{flag}={text}" for (_, flag, _, _), text in flags]
        if config:
            (folder / "sim.yaml").write_text("jitter_s: 1e-3\n" if config == "x" else "jitter_s: [1\n")
            argv += ["--config", str(folder / "sim.yaml")]
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli.main(argv)
        written = sorted(p.name for p in folder.iterdir() if p.name != "sim.yaml")
        if code == 0:
            assert written == ["log.truth.json", "log.txt"]
            assert json.loads((folder / "log.truth.json").read_text())["records"] == records
        else:
            assert code == 2, err.getvalue()
            assert written == []
            lines = err.getvalue().strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("error: ") and "internal error" not in lines[0]


# ---------------------------------------------------------------------------- nested scenario blocks


def _block_fields(tp: Any) -> list[str]:
    import dataclasses

    return [f.name for f in dataclasses.fields(tp)] if dataclasses.is_dataclass(tp) else []


_HINTS = typing.get_type_hints(Scenario)
#: Each nested block with its own keys; the solver blocks from the registry.
BLOCKS: dict[str, list[str]] = {
    name: _block_fields(tp) for name, tp in _HINTS.items() if _block_fields(tp) and name != "path"
}
BLOCKS["gauss_newton"] = ["max_iterations", "initial_damping", "function_tolerance", "step_tolerance"]
BLOCKS["ipopt"] = [
    "huber_formulation",
    "hessian",
    "max_iter",
    "tol",
    "linear_solver",
    "print_level",
    "options",
]
BLOCKS["bounds"] = ["axis_length", "k_steer", "sensor_x", "bogus"]
BLOCKS["initial_guess"] = ["axis_length", "k_traction", "steer_offset", "bogus"]
BLOCKS["priors"] = ["axis_length", "sensor_theta"]
BLOCKS["encoder_noise"] = ["steering", "traction_wheel", "left"]

SCALARS = [
    "1", "0", "-1", "10", "200", "201", "1e-2", "1E3", "-1e-2", "5e-1", ".5", "1.0e-2", ".nan", ".inf",
    "-.inf", "nan", "1e400", "9" * 40, "true", "null", "~", "''", "huber", "auto", "exact", "mumps",
    "ma57", "direct", "[]", "[1, 2]", "[0.5, 3.0]", "[-0.2, 0.2]", "{}", "{mean: 1.5, std: 0.02}",
    "{mean: 1, std: 0}", "{a: 1}", "2024-01-01", "0x1F", "1_000", "'1e-2'", "[gauss_newton]",
]  # fmt: skip
_scalar = st.sampled_from(SCALARS)


@st.composite
def _scenario_text(draw: st.DrawFn) -> str:
    lines = ["dataset: log.txt"]
    anchors: list[str] = []
    blocks = draw(st.lists(st.sampled_from(sorted(BLOCKS)), max_size=5, unique=True))
    if blocks and draw(st.sampled_from([False] * 9 + [True])):  # now and then a block given twice
        blocks.append(blocks[0])
    for block in blocks:
        names = st.one_of(st.sampled_from(BLOCKS[block]), st.sampled_from(["x", "horizn", "1"]))
        keys = draw(st.lists(names, max_size=4, unique=True))
        items = []
        for key in keys:
            value = draw(_scalar)
            if anchors and draw(st.booleans()):
                value = f"*{draw(st.sampled_from(anchors))}"
            items.append(f"{key}: {value}")
        anchor = ""
        if draw(st.booleans()):
            anchor = f"&a{len(anchors)} "
            anchors.append(f"a{len(anchors)}")
        lines.append(f"{block}: {anchor}{{{', '.join(items)}}}")
    for key in draw(
        st.lists(
            st.sampled_from(["name", "model", "solvers", "fixed", "strict", "backend"]),
            max_size=2,
            unique=True,
        )
    ):
        lines.append(f"{key}: {draw(_scalar)}")
    return "\n".join(lines) + "\n"


@FUZZ
@given(text=_scenario_text())
def test_nested_scenario_blocks_load_or_raise_a_scenario_error(text: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scenario.yaml"
        path.write_text(text)
        try:
            sc = load_scenario(path)
        except ScenarioError as exc:
            assert "\n" not in str(exc)
            return
    # What a loaded scenario promises whatever the file said.
    assert (
        HORIZON.problem(sc.objective.residual.horizon) is None
        and STRIDE.problem(sc.objective.residual.stride) is None
    )
    assert sc.objective.robust.delta > 0 and math.isfinite(sc.objective.robust.delta)
    for lo, hi in sc.parameters.bounds.values():
        assert lo < hi
    for value in (
        sc.parameters.initial_guess.values() if isinstance(sc.parameters.initial_guess, dict) else []
    ):
        assert math.isfinite(value)
    for options in sc.solver_options.values():
        for value in getattr(options, "options", {}).values():
            assert isinstance(value, (bool, int, float, str)) and (
                not isinstance(value, float) or math.isfinite(value)
            )


@FUZZ
@given(fanout=st.integers(1, 12), depth=st.integers(1, 9), where=st.sampled_from(["top", "ipopt", "list"]))
def test_aliases_are_refused_exactly_when_they_expand_beyond_the_limit(
    fanout: int, depth: int, where: str
) -> None:
    lines = ["a0: &a0 [" + ", ".join(["1"] * fanout) + "]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * fanout) + "]" for i in range(1, depth)]
    doc = "\n".join(lines) + "\n"
    if where == "ipopt":
        doc = "ipopt:\n  options:\n" + "".join(f"    {ln}\n" for ln in lines)
    elif where == "list":
        doc += f"x: [*a{depth - 1}, *a{depth - 1}]\n"
    # Values once expanded, counted independently: block a_i holds fanout copies of a_{i-1}.
    sizes = [1 + fanout]
    for _ in range(1, depth):
        sizes.append(1 + fanout * sizes[-1])
    total = 1 + sum(1 + s for s in sizes)  # the root mapping, each key and each block
    if where == "ipopt":
        total += 4  # ipopt, options and their mappings
    elif where == "list":
        total += 2 + 2 * sizes[-1]
    try:
        parse_yaml(doc, "fuzz.yaml")
    except NlpCalibError as exc:
        assert "values" in str(exc)
        assert total > MAX_YAML_VALUES, (total, str(exc))
        return
    assert total <= MAX_YAML_VALUES
