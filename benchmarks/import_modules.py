"""What a command imports (for ``benchmarks/import_cpu.sh`` and ``benchmarks/compare_cpu.sh``).

``held FILE ARGS...``: runs ``nlp-calib ARGS`` in this process and, at its exit, writes FILE, a script
importing numpy, CasADi and every module of the package the command holds, as the command imports
them; prints how many modules it holds (all, the package's) and the garbage collector's passes over
each generation while the command ran. ``dataclasses FILE``: runs such a script and prints the CPU
it took and the share of it the standard library's ``dataclasses`` took generating the classes'
methods. ``collector FILE``: runs such a script and prints the collector's passes and the objects
it tracks at the end (frozen ones too).
"""

from __future__ import annotations

import atexit
import dataclasses
import gc
import runpy
import sys
import time
from pathlib import Path
from typing import Any

#: The script's start: numpy and CasADi, then the package as the command imports it (with the
#: dataclasses' compiled methods it keeps, where the checkout has them: ``core/methods.py``; and
#: the garbage collector paused until the command's modules are loaded: ``core/collector.py``).
AS_THE_COMMAND = """try:
    from nlp_calib.core import collector
except ImportError:  # a checkout from before core/collector.py
    resume = lambda: None
else:
    collector.pause()
    resume = collector.resume
import numpy, casadi
try:
    from nlp_calib.core import methods
    from nlp_calib.core.files import cache_dir
except ImportError:  # a checkout from before core/methods.py
    kept = lambda: None
else:
    kept = methods.kept(cache_dir())
"""


def _count_passes() -> list[int]:
    """How many passes Python's garbage collector makes of each generation from now on."""
    passes = [0, 0, 0]

    def count(phase: str, info: dict[str, int]) -> None:
        if phase == "stop":
            passes[info["generation"]] += 1

    gc.callbacks.append(count)
    return passes


def held(script: Path, args: list[str]) -> None:
    passes = _count_passes()

    def write() -> None:
        package = sorted(m for m in sys.modules if m.split(".")[0] == "nlp_calib")
        script.write_text(AS_THE_COMMAND + "".join(f"import {m}\n" for m in package) + "resume()\nkept()\n")
        print(f"modules {' '.join(args[:1])} {len(sys.modules)} {len(package)}", file=sys.__stderr__)
        print(f"collector passes (young, middle, full) {passes}", file=sys.__stderr__)

    atexit.register(write)
    sys.argv = ["nlp-calib", *args]
    runpy.run_module("nlp_calib", run_name="__main__", alter_sys=True)


def dataclass_share(script: Path) -> None:
    import casadi  # noqa: F401  # the floor, before the clock starts
    import numpy  # noqa: F401

    process = dataclasses._process_class  # type: ignore[attr-defined]
    spent = [0.0, 0]

    def timed(*args: Any, **kwargs: Any) -> Any:
        t0 = time.process_time()
        try:
            return process(*args, **kwargs)
        finally:
            spent[0] += time.process_time() - t0
            spent[1] += 1

    dataclasses._process_class = timed  # type: ignore[attr-defined]
    t0 = time.process_time()
    exec(compile(script.read_text(), str(script), "exec"), {})
    total = time.process_time() - t0
    print(f"dataclasses {total:.3f} s importing the package, {spent[0]:.3f} s making {spent[1]} dataclasses")


def collector(script: Path) -> None:
    """The collector's passes while ``script`` runs, and the objects it tracks at its end."""
    passes = _count_passes()
    exec(compile(script.read_text(), str(script), "exec"), {})
    tracked = len(gc.get_objects()) + gc.get_freeze_count()
    print(f"collector passes (young, middle, full) {passes}, tracked at the end {tracked}")


if __name__ == "__main__":
    if sys.argv[1] == "held":
        held(Path(sys.argv[2]), sys.argv[3:])
    elif sys.argv[1] == "collector":
        collector(Path(sys.argv[2]))
    else:
        dataclass_share(Path(sys.argv[2]))
