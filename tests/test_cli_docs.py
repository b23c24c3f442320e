"""docs/cli.md's synopsis lists every option of every subcommand, as the parser has them."""

from __future__ import annotations

import argparse
import re

from conftest import REPO

from nlp_calib.cli.parser import build_parser


def _synopsis() -> dict[str, set[str]]:
    """Each subcommand's options as the synopsis block at the top of docs/cli.md lists them (a
    command's lines: its own and the indented ones after it; a command may have several)."""
    text = (REPO / "docs" / "cli.md").read_text()
    block = text.split("```")[1]
    found: dict[str, set[str]] = {}
    command = None
    for line in block.splitlines():
        head = re.match(r"nlp-calib ([a-z-]+)", line)
        if head:
            command = head.group(1)
        elif not line.startswith(" "):
            command = None
        if command is not None:
            found.setdefault(command, set()).update(re.findall(r"(?<![\w-])--[a-z][a-z-]*", line))
    return found


def _parser_options() -> dict[str, set[str]]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {
        name: {o for a in p._actions for o in a.option_strings if o.startswith("--") and o != "--help"}
        for name, p in sub.choices.items()
    }


def test_the_synopsis_names_every_subcommand_and_every_option_of_each() -> None:
    documented, parsed = _synopsis(), _parser_options()
    assert set(documented) == set(parsed)
    missing = {c: sorted(parsed[c] - documented[c]) for c in parsed if parsed[c] - documented[c]}
    unknown = {c: sorted(documented[c] - parsed[c]) for c in parsed if documented[c] - parsed[c]}
    assert missing == {} and unknown == {}, (missing, unknown)
