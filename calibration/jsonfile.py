"""JSON and text files: read with one-line errors, write atomically.

Shared by the calibration store (calibration.json) and the capture store (capture.json, in
``rig``). It lives here because ``calibration`` is the lowest package that does file I/O
(``processing`` does none) and ``rig`` may import ``calibration``, not the other way round.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any


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


def write_text_atomic(path: Path, text: str, durable: bool = True, newline: str | None = None) -> None:
    """Write ``text`` (UTF-8) to a temporary sibling and rename it onto ``path``: readers see the old
    or the new file, never a partial one; ``durable`` fsyncs it first, ``newline`` is :func:`open`'s."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline=newline) as handle:
            handle.write(text)
            if durable:
                handle.flush()
                os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
