"""A calibration's parameters in named blocks: the one layout every stage and every file shares.

A block is a group of parameters of one kind: the kinematic model's (``model``), the sensor's
mount (``mount``: one shared by every log, or one per log), the reference clock's offset
(``clock``: one per log), and any other a sensor or a source brings. Each parameter carries its
name in the problem and in every file (``sensor_x_2``), the key a scenario and a one-log fit call
it by (``sensor_x``), its block, the log it belongs to (None: shared by every log), its unit and
whether it is free, held or known. What a parameter is, is read here, never from its name's
spelling.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

#: The blocks every calibration may have.
MODEL = "model"
MOUNT = "mount"
CLOCK = "clock"
#: A parameter's status: estimated, held at its start because the data cannot determine it, or
#: given by the user (a scenario's ``fixed``).
FREE = "free"
HELD = "held"
KNOWN = "known"
#: Blocks that describe a recording, not the robot (refitted on every log; a drift check does
#: not judge them): the clock's offset.
RECORDING_BLOCKS = frozenset({CLOCK})
#: The stored form's version (calibration.yaml's ``layout.version``).
LAYOUT_VERSION = 1


@dataclass(frozen=True)
class Parameter:
    """One parameter of a calibration (see the module's docstring)."""

    name: str
    key: str
    block: str
    log: int | None = None
    unit: str = ""
    status: str = FREE
    #: What a robot of its kind can have (a stored value outside is refused).
    range: tuple[float, float] = (-math.inf, math.inf)
    #: The precision a useful calibration must reach: a fraction of its value (``relative``) or an
    #: amount in its unit (``absolute``).
    precision: tuple[str, float] = ("relative", 0.01)
    #: Where the fit started (a held or known parameter: its value).
    start: float = math.nan

    def needed(self, value: float) -> float:
        """The precision a useful calibration needs at ``value``, in the parameter's unit."""
        kind, amount = self.precision
        return amount * max(abs(value), 1e-9) if kind == "relative" else amount


@dataclass(frozen=True)
class BlockSpec:
    """A block to lay out: its ``kind``, its parameters' keys and units, and whether each log has
    its own (``per_log``)."""

    kind: str
    keys: tuple[str, ...]
    units: Mapping[str, str] = field(default_factory=dict)
    per_log: bool = False
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    precision: Mapping[str, tuple[str, float]] = field(default_factory=dict)
    #: Where its parameters start (none: where the run's start puts them).
    defaults: Mapping[str, float] = field(default_factory=dict)

    def parameter(self, key: str, log: int | None, n_logs: int) -> Parameter:
        """The parameter ``key`` of log ``log``'s copy (None: the shared one)."""
        name = key if log is None else own_name(key, log, n_logs)
        limits = self.ranges.get(key, (-math.inf, math.inf))
        needed = self.precision.get(key, ("relative", 0.01))
        start = self.defaults.get(key, math.nan)
        return Parameter(name, key, self.kind, log, self.units.get(key, ""), FREE, limits, needed, start)


def own_name(key: str, log: int, n_logs: int) -> str:
    """The name of log ``log``'s own ``key`` in a calibration of ``n_logs`` logs (``sensor_x_2``);
    with one log, the key itself. The one place the names of per-log parameters are made."""
    return key if n_logs <= 1 else f"{key}_{log + 1}"


@dataclass(frozen=True)
class Layout:
    """Every parameter of a calibration, block after block, in the problem's order."""

    parameters: tuple[Parameter, ...]
    n_logs: int = 1
    #: The kinematic parameters a one-line summary shows.
    headline: tuple[str, ...] = ()

    @classmethod
    def of(cls, blocks: Sequence[BlockSpec], n_logs: int = 1, headline: Sequence[str] = ()) -> Layout:
        """The layout of ``blocks`` over ``n_logs`` logs (a per-log block: one copy per log, log
        after log; a per-log block of one log is its plain keys)."""
        out: list[Parameter] = []
        for b in blocks:
            copies = range(n_logs) if b.per_log and n_logs > 1 else [None]
            for log in copies:
                out += [b.parameter(k, log, n_logs) for k in b.keys]
        return cls(tuple(out), n_logs, tuple(headline))

    # --- what a parameter is -------------------------------------------------------------------

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def units(self) -> dict[str, str]:
        return {p.name: p.unit for p in self.parameters}

    def __contains__(self, name: object) -> bool:
        return any(p.name == name for p in self.parameters)

    def param(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"{name!r} is not a parameter of this calibration ({', '.join(self.names)})")

    def named(self, keys: Iterable[str]) -> tuple[str, ...]:
        """Every name whose key is one of ``keys`` (a key of a per-log block: each log's own), and
        each of ``keys`` not laid out as it is (for the problem to refuse)."""
        keys = tuple(dict.fromkeys(keys))
        laid = [p.name for k in keys for p in self.parameters if p.key == k]
        return tuple(
            dict.fromkeys([*laid, *(k for k in keys if not any(p.key == k for p in self.parameters))])
        )

    def key(self, name: str) -> str:
        """What a scenario's keys call ``name`` (a name not laid out is its own key)."""
        return self.param(name).key if name in self else name

    def keys(self, names: Iterable[str]) -> tuple[str, ...]:
        """:meth:`key` of each of ``names``."""
        return tuple(self.key(n) for n in names)

    def block_of(self, name: str) -> str:
        return self.param(name).block

    def in_block(self, name: str, kind: str) -> bool:
        return name in self and self.param(name).block == kind

    def block(self, kind: str, log: int | None = None) -> tuple[str, ...]:
        """The names of block ``kind`` (``log``: only that log's own and the shared ones)."""
        return tuple(
            p.name
            for p in self.parameters
            if p.block == kind and (log is None or p.log is None or p.log == log)
        )

    def blocks(self) -> tuple[str, ...]:
        """The block kinds, in order."""
        return tuple(dict.fromkeys(p.block for p in self.parameters))

    def per_log(self, kind: str) -> bool:
        """Whether each log has its own parameters of block ``kind``."""
        return any(p.log is not None for p in self.parameters if p.block == kind)

    def copies(self, kind: str) -> int:
        """How many copies of block ``kind`` there are (one per log, or one; 0: none)."""
        logs = {p.log for p in self.parameters if p.block == kind}
        return len(logs)

    def own(self, name: str, log: int) -> str:
        """What log ``log``'s own fit calls the calibration's ``name`` (its key), or "" when that
        log has no such parameter (another log's own)."""
        p = self.param(name)
        return p.key if p.log is None or p.log == log else ""

    def owned(self, log: int) -> tuple[str, ...]:
        """The names of log ``log``'s own parameters (its clock offset, its own mount)."""
        return tuple(p.name for p in self.parameters if p.log == log)

    def view(self, log: int) -> tuple[str, ...]:
        """The names log ``log`` sees: the shared parameters and its own, in order."""
        return tuple(p.name for p in self.parameters if p.log is None or p.log == log)

    def robot(self) -> tuple[str, ...]:
        """The parameters that describe the robot (not a recording: no clock offset)."""
        return tuple(p.name for p in self.parameters if p.block not in RECORDING_BLOCKS)

    # --- status --------------------------------------------------------------------------------

    def needed(self, values: Mapping[str, float]) -> dict[str, float]:
        """The precision each of ``values``' parameters needs at its value (its unit)."""
        return {n: self.param(n).needed(v) for n, v in values.items()}

    def with_status(self, status: Mapping[str, str]) -> Layout:
        """The layout with the statuses ``status`` (by name) set."""
        ps = tuple(replace(p, status=status.get(p.name, p.status)) for p in self.parameters)
        return replace(self, parameters=ps)

    def with_start(self, values: Mapping[str, float]) -> Layout:
        """The layout with each parameter's start from ``values`` (by name)."""
        ps = tuple(replace(p, start=float(values.get(p.name, p.start))) for p in self.parameters)
        return replace(self, parameters=ps)

    @property
    def starts(self) -> dict[str, float]:
        """Each parameter's start, by name."""
        return {p.name: p.start for p in self.parameters}

    def status(self, kind: str) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters if p.status == kind)

    def only(self, names: Iterable[str]) -> Layout:
        """The layout of ``names`` alone (in the layout's order)."""
        keep = set(names)
        return replace(self, parameters=tuple(p for p in self.parameters if p.name in keep))
