"""Opening a ROS bag with ``rosbags``, and reading its messages, with every failure one line.

Nothing but a regular file, or a folder of regular files (a ROS 2 bag), is opened: a FIFO, a socket
or a device is refused before it can block. The bag and its files are noted as inputs of the run
(:func:`nlp_calib.core.files.note_input`), so that no output can be written over them. A bag that
cannot be opened, or read past some message (damaged in the middle), is a :class:`BagError` naming
it and how to repair it.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

from nlp_calib.core.errors import DatasetError
from nlp_calib.core.files import kind_of, note_input

#: Files that belong to a ROS 2 bag folder (the folder holds ``metadata.yaml`` beside them).
_ROS2_FILES = (".db3", ".mcap")
#: Entries of a folder looked at for special files before it is opened as a ROS 2 bag.
_MAX_FOLDER_ENTRIES = 10_000
#: How to fix a bag that cannot be read.
DAMAGED = "the file is damaged: copy it again, or repair it (rosbag reindex, ros2 bag reindex)"
_HOW_TO_OPEN = "a ROS 1 bag is a .bag file, a ROS 2 bag a folder with metadata.yaml or its .db3 or .mcap file"
_INSTALL = "reading bags needs rosbags: install the ros extra: pip install 'nlp_calib[ros]'"


class BagError(DatasetError):
    """A bag that cannot be opened or lacks what the import needs; the message lists what it has."""

    def __init__(self, path: Path | str, problem: str) -> None:
        # Names and types come from the bag: a damaged one can hold any character.
        one_line = "".join(c if c.isprintable() else repr(c)[1:-1] for c in problem)
        super().__init__(str(path), None, one_line)


def is_bag(path: Path) -> bool:
    """Whether ``path`` names a bag rather than a text log (by its name, or a ROS 2 bag folder)."""
    try:
        return path.suffix in (".bag", *_ROS2_FILES) or (path / "metadata.yaml").is_file()
    except OSError:  # a name too long, say: whatever it is, it cannot be opened as a bag folder
        return False


def _rosbags(path: Path) -> tuple[Any, Any]:
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise BagError(path, _INSTALL) from None
    # Old ROS 2 bags carry no message definitions; the standard messages read them.
    return AnyReader, get_typestore(Stores.LATEST)


def bag_root(path: Path) -> Path:
    """The path rosbags opens: a ROS 2 bag's folder also when its .db3 or .mcap file is named.
    Anything but regular files and folders is refused before it is opened (a FIFO would block);
    the bag (its folder and files) is noted as an input, so that no output can replace it."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise BagError(path, "no such file") from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL in the path
        raise BagError(path, f"cannot read the bag ({getattr(exc, 'strerror', None) or exc})") from None
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise BagError(path, f"is {kind_of(mode)}, not a bag; {_HOW_TO_OPEN}")
    root = path
    if path.suffix in _ROS2_FILES and (path.parent / "metadata.yaml").exists():
        root = path.parent
    if root.is_dir():
        _check_folder(path, root)
    note_input(root)
    return root


def _check_folder(path: Path, root: Path) -> None:
    """A ROS 2 bag folder holds regular files (and folders) only, metadata.yaml among them."""
    try:
        with os.scandir(root) as entries:
            for k, entry in enumerate(entries):
                if k >= _MAX_FOLDER_ENTRIES:
                    raise BagError(
                        path, f"{root} holds over {_MAX_FOLDER_ENTRIES} entries; is it a bag folder?"
                    )
                mode = entry.stat().st_mode
                if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
                    raise BagError(
                        path, f"{entry.path} is {kind_of(mode)}; a bag folder holds regular files only"
                    )
                if stat.S_ISREG(mode):
                    note_input(Path(entry.path))
    except OSError as exc:
        raise BagError(path, f"cannot read the bag folder ({exc.strerror or exc})") from None
    if not (root / "metadata.yaml").is_file():
        raise BagError(path, f"a folder without metadata.yaml is not a ROS 2 bag ({_HOW_TO_OPEN})")


@contextmanager
def opened(path: Path) -> Iterator[Any]:
    """An open ``rosbags`` reader of the bag at ``path``; any failure to open it is a :class:`BagError`."""
    reader_type, typestore = _rosbags(path)
    root = bag_root(path)
    try:
        reader = reader_type([root], default_typestore=typestore)
        reader.open()
    except Exception as exc:  # rosbags raises many kinds on a file that is not a bag
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise BagError(
            path, f"cannot open the bag ({first}); {_HOW_TO_OPEN}; if it is one, {DAMAGED}"
        ) from None
    try:
        yield reader
    finally:
        with suppress(Exception):  # a damaged bag may fail to close too; its error is the one to show
            reader.close()


def messages(reader: Any, p: Path, topics: Sequence[str]) -> Iterator[tuple[Any, int, Any]]:
    """The messages on ``topics``, decoded, with their connections and record times; a bag that
    cannot be read on (damaged in the middle) is a :class:`BagError`."""
    n = 0
    try:
        stream = reader.messages(connections=[c for c in reader.connections if c.topic in topics])
    except Exception as exc:
        raise BagError(p, f"cannot read the bag's messages ({why(exc)}); {DAMAGED}") from None
    while True:
        try:
            conn, recorded, raw = next(stream)
        except StopIteration:
            return
        except Exception as exc:  # rosbags' ReaderError, or a struct or zlib error on damaged bytes
            raise BagError(
                p,
                f"cannot read the bag past message {n} of {', '.join(map(repr, topics))} ({why(exc)}); "
                f"{DAMAGED}",
            ) from None
        n += 1
        yield conn, recorded, _decoded(reader, p, conn, raw)


def why(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0][:200]}" if text else type(exc).__name__


def _decoded(reader: Any, p: Path, conn: Any, raw: bytes) -> Any:
    try:
        return reader.deserialize(raw, conn.msgtype)
    except Exception as exc:  # rosbags' own error, or a struct error on a truncated message
        raise BagError(p, f"a message on {conn.topic!r} cannot be decoded ({why(exc)}); {DAMAGED}") from None
