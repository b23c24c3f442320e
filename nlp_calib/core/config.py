"""Validation of YAML mappings against frozen dataclasses (scenarios, simulation options).

A dataclass's fields and type annotations are the schema: unknown keys, wrong types and the
dataclass's own ``__post_init__`` checks (in neutral words) become :class:`ConfigError` naming
the key's place, so each message says where in the file to fix it.
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Union

import yaml

from nlp_calib.core.errors import ConfigError, FieldError, NlpCalibError
from nlp_calib.core.files import SpecialFileError, open_regular
from nlp_calib.core.ranges import shown
from nlp_calib.core.text import escaped, unprintable

show = shown


def key_name(key: Any) -> str:
    """A mapping key as it appears in a message's place (``residual.horizon``)."""
    return key if isinstance(key, str) and len(key) <= 60 and key.isprintable() else show(key)


def fail(where: str, msg: str) -> typing.NoReturn:
    raise ConfigError(f"{where}: {msg}")


def _shape_fits(value: Any, tp: Any) -> bool:
    """Whether ``value`` is the kind of YAML node ``tp`` reads: a mapping, a list or a scalar."""
    origin = typing.get_origin(tp)
    if origin in (Mapping, dict) or tp is Mapping or dataclasses.is_dataclass(tp):
        return isinstance(value, Mapping)
    if origin is tuple:
        return isinstance(value, (list, tuple))
    return not isinstance(value, (Mapping, list, tuple))


def _union(value: Any, tp: Any, where: str) -> Any:
    args = typing.get_args(tp)
    if value is None and type(None) in args:
        return None
    choices = [a for a in args if a is not type(None)]
    # A mapping where a name or a mapping may stand is judged as a mapping only: its own error
    # (e.g. a NaN inside it) is the one that says what to fix.
    fitting = [a for a in choices if _shape_fits(value, a)]
    if len(fitting) == 1:
        return coerce(value, fitting[0], where)
    errors = []
    for arg in fitting or choices:
        try:
            return coerce(value, arg, where)
        except ConfigError as exc:
            errors.append(str(exc).split(": ", 1)[-1])
    fail(where, " or ".join(errors))


def _scalar(value: Any, tp: Any, where: str) -> Any:
    """A YAML scalar as ``bool``, ``int``, ``float``, ``str`` or ``Path``."""
    if tp is bool and not isinstance(value, bool):
        fail(where, f"expected true or false, got {show(value)}")
    if tp is int and (isinstance(value, bool) or not isinstance(value, int)):
        fail(where, f"expected an integer, got {show(value)}")
    if tp is float:
        # A YAML integer beyond float range would overflow float(): no usable number either.
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or (isinstance(value, int) and abs(value) > 1e308)
            or not math.isfinite(value)
        ):
            fail(where, f"expected a finite number, got {show(value)}")
        return float(value)
    if tp is str and not isinstance(value, str):
        fail(where, f"expected a string, got {show(value)}")
    if tp is Path:
        if not isinstance(value, str) or not value:
            fail(where, f"expected a file path, got {show(value)}")
        return Path(value)
    return value


def _sequence(value: Any, tp: Any, where: str) -> tuple[Any, ...]:
    args = typing.get_args(tp)
    if not isinstance(value, (list, tuple)):
        fail(where, f"expected a list, got {show(value)}")
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(coerce(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
    if len(value) != len(args):
        fail(where, f"expected a list of {len(args)} values, got {show(value)}")
    return tuple(coerce(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))


def coerce(value: Any, tp: Any, where: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and convert it (YAML ints to floats...)."""
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        return _union(value, tp, where)
    if tp is Any:
        return value
    if tp in (bool, int, float, str, Path):
        return _scalar(value, tp, where)
    if origin is tuple:
        return _sequence(value, tp, where)
    if origin in (Mapping, dict) or tp is Mapping:
        k_tp, v_tp = typing.get_args(tp)
        if not isinstance(value, Mapping):
            fail(where, f"expected a mapping, got {show(value)}")
        return {coerce(k, k_tp, where): coerce(v, v_tp, f"{where}.{key_name(k)}") for k, v in value.items()}
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return from_mapping(tp, value, where)
    raise TypeError(f"unsupported annotation {tp!r} at {where}")  # programming error


def from_mapping(cls: type, value: Any, where: str) -> Any:
    if value is None:
        value = {}
    if not isinstance(value, Mapping):
        fail(where, f"expected a mapping of {keys_of(cls)}, got {show(value)}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    for key in value:
        if key not in names:
            fail(f"{where}.{key_name(key)}", f"unknown key; valid keys are {', '.join(names)}")
    kwargs = {k: coerce(v, hints[k], f"{where}.{k}") for k, v in value.items()}
    try:
        return cls(**kwargs)
    except FieldError as exc:
        fail(f"{where}.{exc.field}", exc.reason)
    except (ValueError, TypeError, NlpCalibError) as exc:
        fail(where, str(exc))


def keys_of(cls: type) -> str:
    return ", ".join(f.name for f in dataclasses.fields(cls))


#: A scenario or simulation config is a page of YAML; a larger file is not one.
MAX_YAML_BYTES = 64 * 1024
#: Values a document may hold once its aliases are expanded: ``*alias`` repeats a whole block, so
#: a few lines can stand for billions of values ("billion laughs"); a scenario has a few hundred.
MAX_YAML_VALUES = 20_000
#: Levels of collections nested in one another: a scenario has a few; the parser composes a
#: document recursively (libyaml's in C, where a deep enough one ends the process).
MAX_YAML_DEPTH = 64

# YAML 1.2's core schema. PyYAML follows YAML 1.1, where "010" is octal (8), "1:30" sexagesimal
# (90), "1_000" a thousand, "yes"/"on" booleans and "1e-2" a string.
_INT = re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$")
_FLOAT = re.compile(
    r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"
)
_INT_TAG, _FLOAT_TAG = "tag:yaml.org,2002:int", "tag:yaml.org,2002:float"
#: The tag of a plain scalar that YAML 1.1 and YAML 1.2 read as different values.
_AMBIGUOUS_TAG = "tag:nlp_calib,2024:ambiguous"
_STR_TAG = "tag:yaml.org,2002:str"
_YAML11 = yaml.resolver.Resolver()
_VALUES = yaml.constructor.SafeConstructor()


def _yaml12_int(text: str) -> int:
    body = text.lstrip("+-")
    sign = -1 if text.startswith("-") else 1
    if body.startswith(("0o", "0x")):
        return int(body[2:], 8 if body[1] == "o" else 16)
    return sign * int(body)


def _yaml12_value(text: str, tag: str) -> Any:
    if tag == _INT_TAG:
        return _yaml12_int(text)
    if tag == _FLOAT_TAG:
        return _VALUES.construct_yaml_float(yaml.ScalarNode(tag, text))
    return text if tag == _STR_TAG else None


def _yaml11_reading(text: str, tag12: str) -> float | None:
    """The number YAML 1.1 reads the plain scalar ``text`` as, when YAML 1.2 reads it otherwise
    (None when both agree, or 1.1 reads no number)."""
    tag11 = _YAML11.resolve(yaml.ScalarNode, text, (True, False))
    if tag11 not in (_INT_TAG, _FLOAT_TAG) or tag12 not in (_INT_TAG, _FLOAT_TAG, _STR_TAG):
        return None
    try:
        node = yaml.ScalarNode(tag11, text)
        v11 = _VALUES.construct_yaml_int(node) if tag11 == _INT_TAG else _VALUES.construct_yaml_float(node)
        v12 = _yaml12_value(text, tag12)
    except ValueError:  # thousands of digits: the int constructor says so
        return None
    same = v11 == v12 or (isinstance(v12, float) and math.isnan(v11) and math.isnan(v12))
    return None if same else v11


class _AmbiguousScalar(yaml.constructor.ConstructorError):
    """A plain scalar that YAML 1.1 and YAML 1.2 read differently."""


class _Loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """Safe YAML read as YAML 1.2 (core schema), with the forms YAML 1.1 reads as another number
    refused; a key given twice in one mapping is an error (YAML would silently keep the last).
    Parsed by libyaml where PyYAML was built with it (a calibration.yaml in a tenth of the time)."""

    def resolve(self, kind: Any, value: Any, implicit: Any) -> Any:
        tag = super().resolve(kind, value, implicit)
        if kind is yaml.ScalarNode and implicit[0] and _yaml11_reading(value, tag) is not None:
            return _AMBIGUOUS_TAG
        return tag

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        first_line: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            line = key_node.start_mark.line + 1
            try:
                first = first_line.setdefault(key, -1)
            except TypeError:  # an unhashable key: the base class reports it
                continue
            if first != -1:
                raise yaml.constructor.ConstructorError(
                    problem=f"duplicate key {key!r} at lines {first} and {line}; "
                    "YAML would keep only the last, so remove one",
                    problem_mark=key_node.start_mark,
                )
            first_line[key] = line
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
        try:
            return _yaml12_int(str(self.construct_scalar(node)))
        except ValueError:  # Python refuses to convert more than 4300 digits
            raise yaml.constructor.ConstructorError(
                problem="a number with thousands of digits", problem_mark=node.start_mark
            ) from None

    def construct_yaml_str(self, node: yaml.ScalarNode) -> str:
        text = str(super().construct_yaml_str(node))
        if (bad := unprintable(text)) is not None:
            raise _AmbiguousScalar(
                problem=f"the text {escaped(shown(text))} holds {bad}, a line break or control character; "
                "a name, a path or a topic is one line of printable text",
                problem_mark=node.start_mark,
            )
        return text

    def construct_ambiguous(self, node: yaml.ScalarNode) -> Any:
        text = str(node.value)
        tag12 = super().resolve(yaml.ScalarNode, text, (True, False))
        v12 = _yaml12_value(text, tag12)
        reads = f"the text {text!r}" if isinstance(v12, str) else f"{v12!r}"
        raise _AmbiguousScalar(
            problem=f"{text} is {_yaml11_reading(text, tag12)!r} in YAML 1.1 but {reads} in YAML 1.2; "
            "write the number you mean in plain decimal, or quote it if it is text",
            problem_mark=node.start_mark,
        )


# YAML 1.2's resolvers only: none of the YAML 1.1 ones SafeLoader would otherwise inherit.
_Loader.yaml_implicit_resolvers = {}
for _tag, _pattern, _first in [
    ("tag:yaml.org,2002:bool", r"^(?:true|True|TRUE|false|False|FALSE)$", "tTfF"),
    ("tag:yaml.org,2002:null", r"^(?:~|null|Null|NULL|)$", ["~", "n", "N", ""]),
    (_INT_TAG, _INT.pattern, "-+0123456789"),
    (_FLOAT_TAG, _FLOAT.pattern, "-+0123456789."),
    ("tag:yaml.org,2002:merge", r"^(?:<<)$", "<"),
]:
    _Loader.add_implicit_resolver(_tag, re.compile(_pattern), list(_first))
_Loader.add_constructor(_INT_TAG, _Loader.construct_yaml_int)
_Loader.add_constructor(_STR_TAG, _Loader.construct_yaml_str)
_Loader.add_constructor(_AMBIGUOUS_TAG, _Loader.construct_ambiguous)


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def _too_deep(text: str) -> bool:
    """Whether the document nests collections over :data:`MAX_YAML_DEPTH` levels, counted on the
    parser's events (a flat stream: nothing composed yet); a syntax error is raised here."""
    depth = 0
    for event in yaml.parse(text, Loader=_Loader):
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_YAML_DEPTH:
                return True
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1
    return False


def _check_expanded_size(root: yaml.Node) -> str | None:
    """Why the document is too large once aliases are expanded (None if it is not), without
    expanding it: each node's size is counted once and shared by every alias to it."""
    size: dict[int, int] = {}
    entered: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            size[key] = min(1 + sum(size[id(c)] for c in _children(node)), MAX_YAML_VALUES + 1)
            continue
        if key in size:
            continue
        if key in entered:  # an alias inside the block it names
            return "an alias refers to a block that contains it"
        entered.add(key)
        stack.append((node, True))
        stack.extend((c, False) for c in _children(node) if id(c) not in size)
    if size[id(root)] > MAX_YAML_VALUES:
        return (
            f"more than {MAX_YAML_VALUES:,} values, counting an aliased block (*name) each time "
            "it is used; a scenario needs a few hundred"
        )
    return None


def _read_bounded(path: Path, what: str) -> str:
    """The text of a regular file of at most :data:`MAX_YAML_BYTES`, without blocking on a FIFO."""
    try:
        with open_regular(path) as fh:
            data = fh.read(MAX_YAML_BYTES + 1)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such {what} file") from None
    except SpecialFileError as exc:
        shown_kind = "it is a folder" if exc.kind == "a folder" else f"not a regular file: {exc.kind}"
        raise ConfigError(f"{path}: cannot read the {what} file ({shown_kind})") from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL in the path
        raise ConfigError(
            f"{path}: cannot read the {what} file ({getattr(exc, 'strerror', None) or exc})"
        ) from None
    if len(data) > MAX_YAML_BYTES:
        raise ConfigError(
            f"{path}: the {what} file is larger than {MAX_YAML_BYTES // 1024} KiB; is it the right file?"
        )
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: cannot read the {what} file (not UTF-8 text: {exc.reason} at byte {exc.start})"
        ) from None


def parse_yaml(text: str, source: str) -> Any:
    """Parse YAML text (see :class:`_Loader`) with its expanded size bounded; errors name ``source``."""
    loader: _Loader | None = None
    try:
        if _too_deep(text):
            raise ConfigError(
                f"{source}: not a usable YAML document (nested too deeply: over {MAX_YAML_DEPTH} "
                "levels of lists and mappings; a scenario has a few)"
            )
        loader = _Loader(text)  # checks the characters at once
        node = loader.get_single_node()
        if node is None:
            return None
        problem = _check_expanded_size(node)
        if problem is not None:
            raise ConfigError(f"{source}: not a usable YAML document ({problem})")
        return loader.construct_document(node)
    except _AmbiguousScalar as exc:
        line = f":{exc.problem_mark.line + 1}" if exc.problem_mark is not None else ""
        problem = exc.problem or ""
        said = problem if problem.startswith("the text") else f"ambiguous YAML ({problem})"
        raise ConfigError(f"{source}{line}: {said}") from None
    except yaml.reader.ReaderError as exc:  # a character YAML does not allow: says where, not which
        row = text[: exc.position].count("\n") + 1
        bad = escaped(chr(exc.character)) if isinstance(exc.character, int) else "a character"
        raise ConfigError(
            f"{source}:{row}: holds {bad}, a control character YAML does not allow; remove it"
        ) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark is not None else source
        problem = getattr(exc, "problem", None) or "invalid YAML"
        if "nesting depth" in problem:  # PyYAML ≥ 6.0.4 bounds the depth itself, before our loader
            raise ConfigError(f"{where}: not a usable YAML document (nested too deeply: {problem})") from None
        raise ConfigError(f"{where}: not valid YAML ({problem})") from None
    except RecursionError:
        raise ConfigError(f"{source}: not a usable YAML document (nested too deeply)") from None
    finally:
        if loader is not None:
            loader.dispose()


def read_yaml(path: Path, what: str) -> Any:
    """Parse a YAML file; unreadable, special or oversized files, syntax errors, duplicate keys and
    alias bombs become one-line errors."""
    return parse_yaml(_read_bounded(Path(path), what), str(path))
