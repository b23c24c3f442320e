"""Fuzzing the reader and the scenario loader: only the package's own errors may escape.

Inputs are mutated from a small simulated log, from the real log's lines (read at test time,
when it is present) and from the demo scenario: characters deleted, tokens swapped, NaN and
garbage inserted, lines truncated, duplicated, reordered; scenario keys given random values of
random types. Whatever comes in, the result is a usable Log / Scenario or an
:class:`NlpCalibError` (which the command line turns into one line and an exit code).
"""

from __future__ import annotations

import contextlib
import copy
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from conftest import REAL_LOG, SCENARIOS, parse_lines
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nlp_calib.core.errors import NlpCalibError
from nlp_calib.logs import Log
from nlp_calib.pipeline.scenario import Scenario, load_scenario, scenario_from_mapping
from nlp_calib.simulation import SimulationOptions, simulate
from nlp_calib.sources import load_log

FUZZ = settings(
    max_examples=200,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

_SIM_LINES = simulate(SimulationOptions.of(records=40, seed=11)).text().splitlines()


def _real_lines() -> list[str]:
    """The real log's header and first records (read at test time, never stored), if present."""
    if not REAL_LOG.is_file():
        return []
    with REAL_LOG.open(encoding="utf-8") as fh:
        return [line.rstrip("\n") for _, line in zip(range(48), fh)]


_BASES = [_SIM_LINES] + ([_real_lines()] if REAL_LOG.is_file() else [])

#: Tokens a broken logger or a careless edit might leave in a line.
GARBAGE = [
    "nan", "NaN", "inf", "-inf", "1e400", "-0", "", "abc", "0x1F", "1_000", "²", "٣", "\x00", "time:",
    "ticks:", "tracker_pose:", "model_pose:", "#", ":", "[", "]", ",", "99999999999999999999999",
    "4294967296", "-1", "1.5.5", "--1", "+1", ".5", "5.", "  ", "\t", "1e-320", "9" * 5000,
]  # fmt: skip

_token = st.one_of(
    st.sampled_from(GARBAGE),
    st.sampled_from(GARBAGE),  # twice: the hand-picked tokens find most problems
    st.integers(min_value=-(2**70), max_value=2**70).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(max_size=6),
)


def _mutate(lines: list[str], op: str, a: int, b: int, token: str) -> list[str]:
    out = list(lines)
    if not out:
        return [token]
    i, j = a % len(out), b % len(out)
    line = out[i]
    tokens = line.split(" ")
    if op == "delete_char" and line:
        k = b % len(line)
        out[i] = line[:k] + line[k + 1 :]
    elif op == "truncate":
        out[i] = line[: b % (len(line) + 1)]
    elif op == "replace_token":
        tokens[b % len(tokens)] = token
        out[i] = " ".join(tokens)
    elif op == "insert_token":
        tokens.insert(b % (len(tokens) + 1), token)
        out[i] = " ".join(tokens)
    elif op == "swap_tokens":
        k = b % len(tokens)
        tokens[0], tokens[k] = tokens[k], tokens[0]
        out[i] = " ".join(tokens)
    elif op == "duplicate_line":
        out.insert(j, line)
    elif op == "swap_lines":
        out[i], out[j] = out[j], out[i]
    elif op == "delete_line":
        del out[i]
    elif op == "insert_line":
        out.insert(j, token)
    elif op == "cut_file":
        out = out[: max(a % (len(out) + 1), 0)]
    return out


_OPS = st.sampled_from(
    [
        "delete_char",
        "truncate",
        "replace_token",
        "insert_token",
        "swap_tokens",
        "duplicate_line",
        "swap_lines",
        "delete_line",
        "insert_line",
        "cut_file",
    ]
)
_mutations = st.lists(
    st.tuples(_OPS, st.integers(0, 10_000), st.integers(0, 10_000), _token), min_size=1, max_size=8
)
_N_HEADER = 8  # the '#' lines of the simulated log


def _check_dataset(ds: Log) -> None:
    """What a returned Log promises: enough records, finite poses, increasing time."""
    assert ds.n_records >= 2
    assert np.all(np.isfinite(ds.T_world_sensor)) and np.all(np.isfinite(ds.model_pose))
    assert np.all(np.diff(ds.time_s) > 0)
    assert ds.ticks.shape == (ds.n_records, len(ds.header.encoder_names))


@FUZZ
@given(base=st.sampled_from(range(len(_BASES))), mutations=_mutations, strict=st.booleans())
def test_mutated_logs_raise_only_package_errors(base: int, mutations: list[Any], strict: bool) -> None:
    lines = _BASES[base]
    for op, a, b, token in mutations:
        lines = _mutate(lines, op, a, b, token)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ds = parse_lines(lines, "fuzz.txt", strict=strict)
        except NlpCalibError:
            return
    _check_dataset(ds)


@FUZZ
@given(
    edits=st.lists(
        st.tuples(
            st.integers(0, _N_HEADER - 1),
            st.sampled_from(
                ["replace_token", "insert_token", "delete_char", "truncate", "delete_line", "swap_tokens"]
            ),
            st.integers(0, 100),
            _token,
        ),
        min_size=1,
        max_size=3,
    ),
    strict=st.booleans(),
)
def test_mutated_headers_raise_only_package_errors(edits: list[Any], strict: bool) -> None:
    header, records = _SIM_LINES[:_N_HEADER], _SIM_LINES[_N_HEADER:]
    for i, op, b, token in edits:
        header = _mutate(header, op, i, b, token)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ds = parse_lines(header + records, "fuzz.txt", strict=strict)
        except NlpCalibError:
            return
    _check_dataset(ds)


@FUZZ
@given(text=st.text(max_size=400), strict=st.booleans())
def test_arbitrary_text_files_raise_only_package_errors(text: str, strict: bool) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.txt"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with contextlib.suppress(NlpCalibError):
                _check_dataset(load_log(path, strict=strict))


_DEMO = yaml.safe_load((SCENARIOS / "demo.yaml").read_text())
#: Every scenario section with its keys, so that mutations reach nested options too.
_FULL = {
    **_DEMO,
    "samples": {"start": 0, "stop": None, "drop_stationary": False},
    "bounds": {"axis_length": [0.5, 3.0]},
    "information": {"translation": 1.0, "rotation": 1.0},
    "gauss_newton": {"max_iterations": 100, "initial_damping": 1e-3},
    "ipopt": {"huber_formulation": "direct", "max_iter": 500, "options": {}},
    "validation": {"holdout_fraction": None, "rpe_window": 25},
    "alignment": {"tracker_lag": 0.0, "search": [-0.2, 0.2], "step": 0.01},
    "fixed": [],
    "priors": {"axis_length": {"mean": 1.5, "std": 0.02}},
    "strict": True,
    "backend": "interpreted",
}

_EXTREMES = [10**400, -(10**400), 2**63, float("nan"), -0.0, 1e-320, "a\x00b", "../up", "/", "."]
_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**1100), max_value=2**1100),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.sampled_from(["huber", "auto", "from_file", "gauss_newton", "ipopt", "exact", "axis_length", ""]),
    st.sampled_from(_EXTREMES),
)
_values = st.one_of(
    st.sampled_from(_EXTREMES),
    st.recursive(
        _scalars,
        lambda children: st.one_of(
            st.lists(children, max_size=3),
            st.dictionaries(st.one_of(st.text(max_size=8), st.integers(), st.none()), children, max_size=3),
        ),
        max_leaves=8,
    ),
)


def _paths(doc: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix] if prefix else []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, (*prefix, k))
    return out


_PATHS = _paths(_FULL)


@FUZZ
@given(
    edits=st.lists(
        st.tuples(st.sampled_from(_PATHS), st.sampled_from(["set", "delete", "add"]), _values),
        min_size=1,
        max_size=3,
    ),
    extra_key=st.one_of(st.none(), st.text(max_size=8)),
)
def test_mutated_scenario_mappings_raise_only_package_errors(edits: list[Any], extra_key: str | None) -> None:
    doc: Any = copy.deepcopy(_FULL)
    for path, action, value in edits:
        parent = doc
        for key in path[:-1]:
            parent = parent.get(key) if isinstance(parent, dict) else None
        if not isinstance(parent, dict):
            continue
        if action == "set":
            parent[path[-1]] = value
        elif action == "delete":
            parent.pop(path[-1], None)
        else:
            parent[f"{path[-1]}_extra"] = value
    if extra_key is not None:
        doc[extra_key] = 1
    try:
        sc = scenario_from_mapping(doc, "fuzz.yaml", Path("/nonexistent"))
    except NlpCalibError:
        return
    assert isinstance(sc, Scenario)


_DEMO_TEXT = (SCENARIOS / "demo.yaml").read_text()


@FUZZ
@given(
    text=st.one_of(
        st.text(max_size=300),
        st.lists(
            st.tuples(st.integers(0, len(_DEMO_TEXT)), st.integers(0, 6), st.text(max_size=6)),
            min_size=1,
            max_size=5,
        ).map(
            lambda edits: _splice(_DEMO_TEXT, edits),
        ),
    )
)
def test_arbitrary_scenario_text_raises_only_package_errors(text: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scenario.yaml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        with contextlib.suppress(NlpCalibError):
            load_scenario(path)


def _splice(text: str, edits: list[tuple[int, int, str]]) -> str:
    for pos, cut, insert in edits:
        pos = min(pos, len(text))
        text = text[:pos] + insert + text[pos + cut :]
    return text
