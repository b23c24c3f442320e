"""Block kinds beyond the model's, the mount's and the clock's: one registry line each.

A block kind brings its parameters' definitions (keys, units, one copy per log or one shared,
defaults, which are held) and how they act on a window: a transform of the base motion ``M`` the
model predicts from the encoders, before the sensor sees it (a per-log scale of the wheels, a
bias). The problem lays its parameters out after the built-in blocks (:func:`~nlp_calib.problem.
functions.problem_layout`), starts them at their defaults and picks each window's log's own copy
by the window's one-hot log rows, so that every stage (solvers, uncertainty, folds, outputs)
reads them from the layout like any other.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import casadi as ca

from nlp_calib.models.base import KinematicModel
from nlp_calib.results.layout import BlockSpec


@dataclass(frozen=True)
class BlockKind:
    """A kind of parameter block: its parameters (``keys``, ``units``, ``defaults``, ``per_log``),
    those held at their default (``held``; ``held_first``: only the first log's copy, the
    others then stated against it), whether a problem has it (``applies``: the model and the
    number of logs) and what it does to a window's base motion (``transform``: ``M`` and the
    window's values by key to the motion the sensor sees)."""

    keys: tuple[str, ...]
    transform: Callable[[ca.SX, Mapping[str, ca.SX]], ca.SX]
    applies: Callable[[KinematicModel, int], bool]
    units: Mapping[str, str] = field(default_factory=dict)
    defaults: Mapping[str, float] = field(default_factory=dict)
    per_log: bool = False
    held: tuple[str, ...] = ()
    held_first: tuple[str, ...] = ()

    def spec(self, kind: str) -> BlockSpec:
        """Its block to lay out, under its registry name ``kind``."""
        return BlockSpec(kind, self.keys, self.units, self.per_log, defaults=self.defaults)


#: The block kinds a problem may have beyond the built-in ones, by name (none ship yet: a per-log
#: wheel scale is added in a test alone).
BLOCK_KINDS: dict[str, BlockKind] = {}


def by_definition(block: str, key: str, log: int | None) -> bool:
    """Whether a registered block kind holds its parameter ``key`` (of ``log``) by definition: its
    ``held``, or the first log's ``held_first`` that the others are stated against. Such a value is
    no measurement that could be off: moving it re-states the others, it changes no prediction."""
    kind = BLOCK_KINDS.get(block)
    return kind is not None and (key in kind.held or (log == 0 and key in kind.held_first))


def kinds_for(model: KinematicModel, n_logs: int) -> tuple[str, ...]:
    """The registered block kinds a problem of ``model`` over ``n_logs`` logs has."""
    return tuple(name for name, kind in BLOCK_KINDS.items() if kind.applies(model, n_logs))


def per_log_kinds(model: KinematicModel, n_logs: int) -> bool:
    """Whether such a problem has a registered block with one copy per log (its windows then say
    their log)."""
    return n_logs > 1 and any(BLOCK_KINDS[k].per_log for k in kinds_for(model, n_logs))
