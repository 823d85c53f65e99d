"""JSON and text files: read with one-line errors, write atomically.

Shared by the calibration store (calibration.json) and the capture store (capture.json, in
``rig``). It lives here because ``calibration`` is the lowest package that does file I/O
(``processing`` does none) and ``rig`` may import ``calibration``, not the other way round.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

# Names the atomic directory commit of rig.store.files reserves (defined here, the lowest package
# that reads files, because the calibration store must recognise them too):
INCOMPLETE_MARK = ".incomplete-"  # NAME.incomplete-XXXXXXXX: a directory still being written
REPLACED_MARK = ".replaced-"  # NAME.replaced-XXXXXXXX: the previous version, set aside while replacing
RESERVED_MARKS = (INCOMPLETE_MARK, REPLACED_MARK)


def staging_mark(name: str) -> str | None:
    """The reserved mark a file name holds (``.incomplete-`` or ``.replaced-``), or None.

    Such a name belongs to an unfinished or interrupted commit: it is never an output's name and
    never read as a finished input.
    """
    return next((mark for mark in RESERVED_MARKS if mark in name), None)


def check_committed_input(path: Path, what: str, error: Callable[[str], Exception], hint: str = "") -> None:
    """Refuse to read a staging folder (``NAME.incomplete-*``, ``NAME.replaced-*``) as a finished ``what``.

    The name is checked after resolving links, so a link with an ordinary name does not hide one;
    ``hint`` ends the message of a never-committed name (default: not read as ``what``).
    """
    try:
        name = Path(path).resolve().name
    except (OSError, RuntimeError):
        name = Path(path).name
    mark = staging_mark(name)
    if mark == INCOMPLETE_MARK:
        raise error(
            f"{path}: never committed (its name says the write did not finish, whatever its files say); "
            + (hint or f"not read as a {what}")
        )
    if mark == REPLACED_MARK:
        raise error(
            f"{path}: a previous version set aside by an interrupted replacement; rename it to read it as a {what}"
        )


def read_json(file: Path, error: type[Exception], missing: str) -> Any:
    """Parse ``file``; every failure is ``error`` with a one-line message naming the file.

    ``missing`` completes the message when the file does not exist, e.g.
    ``"missing (not a capture directory?)"``.
    """
    try:
        text = file.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{file}: {missing}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{file}: cannot read: {exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{file}: not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None


def write_json_atomic(path: Path, obj: Any, durable: bool = True) -> None:
    """Write JSON through a temporary file in the same directory and rename it into place.

    Readers see the old or the new file, never a partial one. ``durable`` fsyncs the new file
    before the rename (needed to survive a power loss, not a crash of the program).
    """
    write_text_atomic(Path(path), json.dumps(obj, indent=2, ensure_ascii=False) + "\n", durable)


@contextlib.contextmanager
def naming_errors(path: Path) -> Iterator[None]:
    """An OSError raised inside without a file name (a full disk, a failing write) names ``path``,
    so that the one line a user reads says which file could not be written."""
    try:
        yield
    except OSError as exc:
        if exc.filename is not None or exc.errno is None:
            raise
        raise OSError(exc.errno, exc.strerror, str(path)) from exc


def write_bytes_durable(path: Path, data: bytes) -> None:
    """Write a file and fsync it; an error names the file."""
    with naming_errors(path), open(path, "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())


def write_text_atomic(path: Path, text: str, durable: bool = True, newline: str | None = None) -> None:
    """Write ``text`` (UTF-8) to a temporary sibling and rename it onto ``path``: readers see the old
    or the new file, never a partial one; ``durable`` fsyncs it first, ``newline`` is :func:`open`'s.
    An error names ``path``."""
    with naming_errors(path):
        _write_atomic(path, "w", text, durable, encoding="utf-8", newline=newline)


def write_bytes_atomic(path: Path, data: bytes, durable: bool = True) -> None:
    """:func:`write_text_atomic` for bytes: readers see the old or the new file, never a partial one."""
    with naming_errors(path):
        _write_atomic(path, "wb", data, durable)


def _write_atomic(path: Path, mode: str, data: str | bytes, durable: bool, **open_args: Any) -> None:
    """Write ``data`` to a temporary sibling (fsynced when ``durable``) and rename it onto ``path``."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **open_args) as handle:
            handle.write(data)
            if durable:
                handle.flush()
                os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
