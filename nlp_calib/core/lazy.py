"""A package's re-exports imported when first used (PEP 562), not with the package.

Importing one module of a package runs the package's ``__init__`` first: where it imported every
module it re-exports, a command that needed one of them loaded them all (the command line's parser
loaded the whole pipeline to read one option table). A package lists its public names and the
module each comes from; its ``if TYPE_CHECKING:`` imports of the same names give the type checker
and the import-linter contracts the static picture.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


def exports(package: str, table: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``: each name of ``table`` read from its module at
    its first use and kept in the package's namespace.

    No name may also be one of the package's modules: importing that module sets the package's
    attribute to it, and the name would then read the module (tested)."""
    namespace = vars(sys.modules[package])

    def attribute(name: str) -> Any:
        module = table.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def listing() -> list[str]:
        return sorted({*namespace, *table})

    return attribute, listing
