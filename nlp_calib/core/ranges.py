"""Accepted ranges of numeric options, stated once and checked wherever a value comes in.

The same :class:`Range` checks a dataclass field on construction and a command-line option when
it is parsed, and describes itself in the error (``[0, 1)``), so the message names the range the
check uses.
"""

from __future__ import annotations

import math
import re
import reprlib
from collections.abc import Iterable
from dataclasses import dataclass

from nlp_calib.core.errors import FieldError


class _Short(reprlib.Repr):
    """``reprlib`` with integers shown by magnitude once they have more than 30 digits."""

    def repr_int(self, x: int, level: int) -> str:
        # repr() of an integer of more than 4300 digits raises; a message needs the magnitude only.
        if abs(x) < 10**30:
            return repr(x)
        return f"{'-' if x < 0 else ''}~1e{int(x.bit_length() * math.log10(2))}"


_short = _Short()
_short.maxstring, _short.maxother, _short.maxlist, _short.maxdict, _short.maxlevel = 60, 60, 6, 6, 3


def shown(value: object) -> str:
    """``value`` as a short one-line ``repr`` for a message: long strings, containers and numbers cut."""
    return _short.repr(value)


@dataclass(frozen=True)
class Range:
    """Values ``lo ≤ v ≤ hi`` (``<`` on an open end); ``integer`` admits whole numbers only."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False

    def describe(self) -> str:
        def fmt(v: float) -> str:
            return f"{int(v):d}" if self.integer and math.isfinite(v) else f"{v:g}"

        kind = "a whole number" if self.integer else "a number"
        left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
        return f"{kind} in {left}{fmt(self.lo)}, {fmt(self.hi)}{right}"

    def problem(self, value: object) -> str | None:
        """Why ``value`` is not accepted (None when it is)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"must be {self.describe()}, got {shown(value)}"
        if self.integer and not isinstance(value, int):
            return f"must be {self.describe()}, got {shown(value)}"
        v = float(value) if abs(value) < 1e300 else (math.inf if value > 0 else -math.inf)
        ok = (
            math.isfinite(v)
            and (v > self.lo if self.lo_open else v >= self.lo)
            and (v < self.hi if self.hi_open else v <= self.hi)
        )
        return None if ok else f"must be {self.describe()}, got {shown(value)}"

    def parse(self, text: str) -> int | float:
        """``text`` as a number in the range; :class:`ValueError` with the reason otherwise."""
        try:
            value: int | float = int(text) if self.integer else float(text)
        except ValueError:
            raise ValueError(f"must be {self.describe()}, got {text!r}") from None
        if self.problem(value) is not None:
            raise ValueError(f"must be {self.describe()}, got {text!r}")
        return value


#: A parameter, a guess or a sensor coordinate beyond this is a typo: the squares of such numbers
#: still fit a float with room to spare, so the cost, its weights and the covariance cannot
#: overflow (silently, or as a NaN result).
MAGNITUDE = Range(-1e6, 1e6)


def check_range(field: str, value: object, limit: Range) -> None:
    """Raise :class:`FieldError` naming ``field`` when ``value`` lies outside ``limit``."""
    reason = limit.problem(value)
    if reason is not None:
        raise FieldError(field, reason)


def check_choice(field: str, value: object, choices: Iterable[str]) -> None:
    """Raise :class:`FieldError` naming ``field`` when ``value`` is not one of ``choices``."""
    choices = tuple(choices)
    if value not in choices:
        raise FieldError(field, f"{shown(value)} is not one of {', '.join(choices)}")


#: A ROS 2 node name (a ros2_control controller's): letters, digits and underscores, not starting
#: with a digit; it becomes a YAML key, so nothing else is accepted.
_ROS_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,254}")


def check_ros_name(field: str, value: object) -> None:
    """Raise :class:`FieldError` naming ``field`` when ``value`` is not a ROS 2 node name."""
    if not isinstance(value, str) or _ROS_NAME.fullmatch(value) is None:
        raise FieldError(
            field,
            f"{shown(value)} is not a ROS 2 node name (letters, digits and underscores, not starting with "
            "a digit, e.g. diffbot_base_controller)",
        )
