"""The documentation: the README's example runs, and every link between pages resolves."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from conftest import REPO

PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def test_readme_example_runs_and_prints_both_solvers() -> None:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    code = re.search(r"## Example\n\n```python\n(.*?)```", text, re.S)
    assert code is not None
    proc = subprocess.run(
        [sys.executable, "-c", code.group(1)], cwd=REPO, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    assert "gauss_newton True" in proc.stdout and "ipopt True" in proc.stdout
    assert "k_traction" in proc.stdout and "ATE" in proc.stdout


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_relative_link_resolves(page: object) -> None:
    assert hasattr(page, "read_text")
    text = page.read_text(encoding="utf-8")  # type: ignore[attr-defined]
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
        if "://" in target:
            continue
        assert (page.parent / target).exists(), f"{page.name}: broken link {target}"  # type: ignore[attr-defined]


def test_readme_is_short() -> None:
    assert len((REPO / "README.md").read_text(encoding="utf-8").splitlines()) <= 200


def test_the_repository_cites_no_document_outside_it() -> None:
    tracked = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True).stdout.split()
    for name in tracked:
        if name == "tests/test_docs.py":  # this file names what it looks for
            continue
        path = REPO / name
        if path.suffix in {".py", ".md", ".yaml", ".toml"} or name == ".ci/run":
            text = path.read_text(encoding="utf-8")
            assert "SPEC" not in text, name
            assert "shared/notes" not in text and "shared/reference" not in text, name
