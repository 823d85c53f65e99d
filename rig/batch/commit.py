"""Put a finished output directory in place in one rename, so that an output is whole or absent.

A task writes into a hidden staging sibling (``.NAME.rig-batch-new-XXXX``) and renames it onto
``NAME``. An earlier output there is first renamed aside (``.NAME.rig-batch-old-XXXX``) and removed
after; a kill between the two renames leaves ``NAME`` missing (processed again on the rerun), never
half-written. Leftover staging directories of a killed run are removed by :func:`remove_stale`.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import uuid
from collections.abc import Collection
from pathlib import Path

from rig.errors import ProcessingError

_STALE = re.compile(r"^\..+\.rig-batch-(new|old)-[0-9a-z_]+$")


def _fsync(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) if path.is_dir() else os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems cannot sync directories
        pass
    finally:
        os.close(fd)


def staging_dir(target: Path) -> Path:
    """A new empty hidden sibling of ``target`` to write its content into."""
    target.parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=f".{target.name}.rig-batch-new-", dir=target.parent))


def check_replaceable(target: Path, allowed: Collection[str]) -> None:
    """ProcessingError if ``target`` holds anything but files named in ``allowed`` (never delete a user's files)."""
    if not target.exists():
        return
    if not target.is_dir():
        raise ProcessingError(f"{target}: expected an output directory, found a file; move it or choose another -o")
    foreign = sorted(p.name for p in target.iterdir() if p.name not in allowed)
    if foreign:
        raise ProcessingError(
            f"{target}: holds files `rig process` does not write ({', '.join(foreign[:3])}"
            f"{', ...' if len(foreign) > 3 else ''}); move them or choose another -o"
        )


def commit_dir(staging: Path, target: Path, allowed: Collection[str]) -> None:
    """Rename ``staging`` onto ``target`` (replacing an earlier output made only of ``allowed`` files)."""
    for item in staging.iterdir():
        _fsync(item)
    _fsync(staging)
    for _attempt in range(3):
        if target.exists():
            check_replaceable(target, allowed)
            aside = target.parent / f".{target.name}.rig-batch-old-{uuid.uuid4().hex}"
            try:
                os.rename(target, aside)
            except FileNotFoundError:  # another process moved it first
                continue
            os.rename(staging, target)
            shutil.rmtree(aside, ignore_errors=True)
            break
        try:
            os.rename(staging, target)
            break
        except OSError:  # appeared meanwhile (a worker of a killed run finishing late): replace it
            continue
    else:
        shutil.rmtree(staging, ignore_errors=True)
        raise ProcessingError(f"{target}: could not be replaced (changed by another process while committing)")
    _fsync(target.parent)


def remove_stale(root: Path) -> int:
    """Remove staging and set-aside directories a killed run left under ``root``; returns how many."""
    removed = 0
    if not root.is_dir():
        return 0
    for here, dirs, _files in os.walk(root):
        for name in list(dirs):
            if _STALE.match(name):
                shutil.rmtree(Path(here) / name, ignore_errors=True)
                dirs.remove(name)
                removed += 1
    return removed
