"""``python -m nlp_calib``: the same as the ``nlp-calib`` command."""

from __future__ import annotations

from nlp_calib.core import collector, interrupts, memory, methods
from nlp_calib.core.files import cache_dir


def run() -> int:
    """The command. A signal while its libraries load (numpy, CasADi) ends it quietly with
    ``128 + signal``, like a signal later does, even if a library swallowed the exception."""
    collector.pause()  # until the command's modules are loaded (cli/commands.py)
    interrupts.install()
    memory.fit_to_limit()
    # The dataclasses' methods compiled by an earlier command: most of the package's import.
    kept = methods.kept(cache_dir())
    try:
        from nlp_calib.cli import main

        return main()
    except BaseException as exc:
        code = interrupts.exit_code()
        if code is not None:
            return code
        if isinstance(exc, MemoryError):  # the libraries did not fit (ulimit -v): one line, exit 1
            raise SystemExit(f"error: {memory.OUT_OF_MEMORY}") from None
        raise
    finally:
        collector.resume()  # a command that never loaded its module (--help, a usage error)
        kept(save=interrupts.exit_code() is None)  # a signal ends the command without writing


if __name__ == "__main__":
    raise SystemExit(run())
