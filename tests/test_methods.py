"""The dataclasses' methods kept between commands (``core/methods.py``): the same classes as Python
makes, compiled once, and a file no other user could have written."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from nlp_calib.core import methods

REPO = Path(__file__).resolve().parents[1]


def _classes() -> list[type]:
    """A few kinds of dataclass, made afresh at each call."""

    @dataclasses.dataclass(frozen=True)
    class Frozen:
        a: int
        b: float = 2.5
        c: list[int] = dataclasses.field(default_factory=list)

    @dataclasses.dataclass(order=True)
    class Ordered:
        x: str
        y: tuple[int, ...] = ()

        def __post_init__(self) -> None:
            self.y = tuple(self.y)

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Keywords:
        name: str
        size: int = 0

    return [Frozen, Ordered, Keywords]


def _methods(cls: type) -> dict[str, Any]:
    names = ("__init__", "__repr__", "__eq__", "__hash__", "__setattr__", "__delattr__", "__lt__")
    return {n: getattr(cls.__dict__[n], "__wrapped__", cls.__dict__[n]) for n in names if cls.__dict__.get(n)}


def _compiles(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    texts: list[str] = []
    real = compile

    def counted(source: Any, *args: Any, **kwargs: Any) -> Any:
        texts.append(source)
        return real(source, *args, **kwargs)

    monkeypatch.setattr(methods, "compile", counted, raising=False)
    return texts


def test_kept_methods_are_the_code_python_compiles(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    plain = [_methods(c) for c in _classes()]
    compiles = _compiles(monkeypatch)
    done = methods.kept(tmp_path)
    first = _classes()
    done()
    assert compiles and (tmp_path / methods.file_name()).is_file()
    compiles.clear()
    done = methods.kept(tmp_path)
    again = _classes()
    done()
    assert compiles == []  # every text read from the file
    assert not hasattr(dataclasses, "exec")
    for made in (first, again):
        for cls, expected in zip(made, plain):
            got = _methods(cls)
            assert got.keys() == expected.keys()
            for name, fn in got.items():
                assert fn.__code__ == expected[name].__code__, name
                assert fn.__annotations__ == expected[name].__annotations__, name
    Frozen, Ordered, Keywords = again
    assert Frozen(1) == Frozen(1, 2.5, []) and hash(Frozen(1, c=None)) == hash(Frozen(1, c=None))  # type: ignore[arg-type]
    with pytest.raises(dataclasses.FrozenInstanceError):
        Frozen(1).a = 2  # type: ignore[misc]
    assert Ordered("a", [1]) < Ordered("b") and Ordered("a", [1]).y == (1,)  # type: ignore[arg-type]
    assert repr(Keywords(name="n")).endswith("Keywords(name='n', size=0)")


@pytest.mark.parametrize("spoil", ["group_writable", "cut_short", "other_bytes", "folder_writable"])
def test_a_file_not_whole_or_that_another_user_could_write_is_never_read(
    spoil: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "cache"
    done = methods.kept(folder)
    _classes()
    done()
    path = folder / methods.file_name()
    data = path.read_bytes()
    if spoil == "group_writable":
        path.chmod(0o664)
    elif spoil == "cut_short":
        path.write_bytes(data[: len(data) // 2])
    elif spoil == "other_bytes":
        path.write_bytes(data[:100] + bytes([data[100] ^ 1]) + data[101:])
    else:
        folder.chmod(0o777)
    assert methods.read(path) == {}
    compiles = _compiles(monkeypatch)
    done = methods.kept(folder)
    _classes()
    done()
    assert compiles  # compiled again, and the command goes on


def test_the_file_is_written_readable_by_all_writable_by_its_owner(tmp_path: Path) -> None:
    old = os.umask(0o002)
    try:
        done = methods.kept(tmp_path)
        _classes()
        done()
    finally:
        os.umask(old)
    path = tmp_path / methods.file_name()
    assert path.stat().st_mode & 0o777 == 0o644
    assert methods.read(path)


def test_the_command_keeps_the_methods_in_the_compile_cache(tmp_path: Path) -> None:
    """The second command reads every method the first compiled: nothing new to write."""
    env = {**os.environ, "NLP_CALIB_CACHE": str(tmp_path), "PYTHONPATH": str(REPO)}
    path = tmp_path / methods.file_name()
    subprocess.run([sys.executable, "-m", "nlp_calib", "--help"], env=env, check=True, capture_output=True)
    first = path.stat().st_mtime_ns
    kept = methods.read(path)
    assert len(kept) > 100
    subprocess.run([sys.executable, "-m", "nlp_calib", "--help"], env=env, check=True, capture_output=True)
    assert path.stat().st_mtime_ns == first


def test_a_command_a_signal_ends_writes_nothing(tmp_path: Path) -> None:
    done = methods.kept(tmp_path)
    _classes()
    done(save=False)
    assert not hasattr(dataclasses, "exec")
    assert not (tmp_path / methods.file_name()).exists()
