"""Every warning a result holds reaches the terminal (issue #43 item 6: "only 39 of 579 windows lie
within the robust threshold" was in result.json and never printed): over every list a result.json
keeps its warnings in (any key naming warnings, at any depth, and the verdict's reasons), for each
command that writes one."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import cli, write_sim


def _warnings(doc: Any, path: str = "") -> Iterator[tuple[str, str]]:
    """Each warning string of a result document, with where it is kept."""
    if isinstance(doc, dict):
        for key, value in doc.items():
            if "warning" in key or path + "/" + key == "/verdict/reasons":
                for w in value if isinstance(value, list) else [value]:
                    if isinstance(w, str):
                        yield f"{path}/{key}", w
            yield from _warnings(value, f"{path}/{key}")
    elif isinstance(doc, list):
        for i, value in enumerate(doc):
            yield from _warnings(value, f"{path}[{i}]")


@pytest.fixture(scope="module")
def straight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A straight drive (nothing turning is observable), a robust threshold most windows exceed and
    a lag no fit converges at: warnings from the observability, the kernel and the alignment."""
    folder = tmp_path_factory.mktemp("warned")
    log = write_sim(folder, model="diff_drive", trajectory="straight", records=800, seed=3)
    scenario = folder / "s.yaml"
    scenario.write_text(
        f"dataset: {log.name}\nmodel: diff_drive\nsolvers: [gauss_newton]\n"
        "robust: {kernel: huber, delta: 0.0005}\nvalidation: {blocks: 0}\n"
    )
    return scenario


@pytest.mark.parametrize("command", ["run", "odometry"])
def test_every_warning_a_result_holds_reaches_the_terminal(straight: Path, command: str) -> None:
    out = straight.parent / command
    proc = cli(command, str(straight), "--out", str(out), "--skip-preflight")
    assert proc.returncode == 0, proc.stderr
    found = list(_warnings(json.loads((out / "result.json").read_text())))
    kept = {where.split("/")[1] for where, _ in found}
    assert {"warnings", "observability", "verdict"} <= kept, kept
    assert any("robust threshold" in w for _, w in found)  # the kernel's, never printed before
    missing = [(where, w) for where, w in found if w not in proc.stdout]
    assert not missing, missing
