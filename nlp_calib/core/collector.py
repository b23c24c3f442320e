"""Python's cyclic garbage collector held off while a command loads its libraries and modules.

Loading makes objects that live as long as the process (modules, classes, functions): once the
modules a ``compare`` holds are imported the collector tracks about 41,800 objects, 25,000 of them
numpy's and CasADi's. Triggered by the count of objects made, it passed over them while they were
made (98 young passes, 9 middle ones and a full one) and freed a few dozen objects beyond what numpy
and CasADi alone leave (``benchmarks/import_modules.py collector``). So a command pauses the
collector before it imports (:func:`pause`) and, once its command's module is loaded, :func:`resume`
moves everything alive to the permanent generation (``gc.freeze``: never traversed again, never
freed, as modules are not) and turns the collector back on. Only what :func:`pause` paused is
resumed: a program or test that calls a command in its own process keeps its collector as it was.
"""

from __future__ import annotations

import gc

_paused: list[bool] = []  # one entry while this module holds the collector off


def pause() -> None:
    """Hold the collector off (if it runs) until :func:`resume`."""
    if gc.isenabled() and not _paused:
        gc.disable()
        _paused.append(True)


def resume() -> None:
    """Freeze what is alive and turn the collector back on, if :func:`pause` turned it off."""
    if _paused:
        _paused.clear()
        gc.freeze()
        gc.enable()
