"""Python's cyclic garbage collector held off while a command loads its libraries and modules.

Loading makes objects that live as long as the process (modules, classes, functions, their code):
about 40,000 for a ``compare``, after numpy and CasADi. The collector, triggered by the count of
objects made, passed over them again and again while they were made (about 110 young passes, ten
middle ones and a full one while ``compare`` imported), and a full pass later in the command
traversed them once more: none of it ever found garbage worth the time. So a command pauses the
collector before it imports (:func:`pause`) and, once its command's module is loaded,
:func:`resume` moves everything alive to the permanent generation (``gc.freeze``: never traversed
again, never freed, as modules are not) and turns the collector back on. Only what :func:`pause`
paused is resumed: a program or test that calls a command in its own process keeps its collector.
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
