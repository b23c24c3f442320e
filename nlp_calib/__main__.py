"""``python -m nlp_calib``: the same as the ``nlp-calib`` command."""

from __future__ import annotations

import signal
from types import FrameType


def _quit(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(128 + signum)


def run() -> int:
    """The command, with a signal while its libraries load (numpy, CasADi) ending it quietly like a
    signal later does; the command line installs its own handlers once it runs."""
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, _quit)
    from nlp_calib.cli import main

    return main()


if __name__ == "__main__":
    raise SystemExit(run())
