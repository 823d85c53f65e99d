"""Find the captures of an archive: every directory holding ``capture.json``, recursively.

A capture whose manifest says ``"complete": false`` (an interrupted scan), one whose name is a
staging name (``NAME.incomplete-*``) and a symbolic link to a folder (never followed) are listed
as skipped with the reason; one whose manifest cannot even be read is still listed, so that processing
reports exactly what ``rig process`` would say about it. Directories given to be left out (the
calibration with its reference capture, the batch's own output) are not descended into.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from rig.errors import ConfigError
from rig.store import files

MANIFEST = "capture.json"

INCOMPLETE_REASON = (
    "capture.json: complete: expected true, found false (interrupted or still being written; "
    "`rig process --salvage` reads what is there)"
)
STAGING_REASON = (
    "never committed: its name holds '.incomplete-' or '.replaced-', what an unfinished or interrupted "
    "write leaves (`rig process --salvage` reads what is there)"
)
LINK_REASON = (
    "a symbolic link to a folder: not followed (a batch reads the captures inside its archives; "
    "give the folder it leads to as an archive)"
)


@dataclass(frozen=True)
class FoundCapture:
    """A capture directory found in an archive.

    ``name`` is its path relative to the archive (prefixed with the archive's own name when
    several archives are given): the row name in ``index.csv`` and the output folder under OUT.
    ``skip_reason`` is set for a capture that will not be processed.
    """

    path: Path
    name: str
    skip_reason: str | None = None


def _is_incomplete(manifest_path: Path) -> bool:
    """True only when capture.json reads (through the safe file layer: a regular file within the
    manifest size limit) and says ``complete: false``; anything else is processed, and processing
    names what is wrong with it."""
    try:
        manifest = files.read_json(manifest_path, files.FileLayerError)
    except files.FileLayerError:
        return False
    return isinstance(manifest, dict) and manifest.get("complete") is False


def _skip_reason(directory: Path) -> str | None:
    """Why a directory found in an archive is listed but not processed (None: it is processed)."""
    if directory.is_symlink():
        return f"{LINK_REASON} (to {os.readlink(directory)})"
    if files.staging_mark(directory.name) is not None:
        return STAGING_REASON
    return INCOMPLETE_REASON if _is_incomplete(directory / MANIFEST) else None


def _walk(archive: Path, excluded: set[Path]) -> Iterable[Path]:
    """Capture directories under ``archive`` in sorted order, and links to directories (listed, not
    followed); not descending into a capture or an excluded tree."""
    for root, dirs, names in os.walk(archive):
        here = Path(root)
        if here.resolve() in excluded:
            dirs[:] = []
            continue
        if MANIFEST in names:
            dirs[:] = []  # a capture's own folders (frames/) hold no captures
            yield here
            continue
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for name in list(dirs):
            if (here / name).is_symlink():  # os.walk lists links to directories but never enters them
                dirs.remove(name)
                yield here / name


def discover(archives: Sequence[Path], exclude: Iterable[Path] = ()) -> list[FoundCapture]:
    """Captures under each archive, sorted by name; ConfigError for a missing archive or none found.

    With one archive, names are relative to it (``part-001/object``); with several, each name
    starts with its archive's directory name so that outputs of different archives cannot collide.
    """
    excluded = {Path(p).resolve() for p in exclude}
    if not archives:
        raise ConfigError("ARCHIVE: expected at least one archive directory, found none")
    labels = [Path(a).resolve().name or "archive" for a in archives]
    if len(archives) > 1 and len(set(labels)) != len(labels):
        raise ConfigError(
            f"ARCHIVE: expected archives with different directory names (outputs are named after them), found {labels}"
        )
    found: dict[Path, FoundCapture] = {}
    for archive, label in zip(archives, labels):
        archive = Path(archive)
        if not archive.exists():
            raise ConfigError(f"{archive}: archive directory not found")
        if not archive.is_dir():
            raise ConfigError(f"{archive}: expected an archive directory, found a file")
        seen = 0
        for directory in _walk(archive, excluded):
            seen += 1
            resolved = directory.absolute() if directory.is_symlink() else directory.resolve()
            if resolved in found:  # archives that overlap: one row per capture
                continue
            relative = PurePosixPath(directory.relative_to(archive).as_posix())
            if str(relative) == ".":
                relative = PurePosixPath(label)
            elif len(archives) > 1:
                relative = PurePosixPath(label) / relative
            found[resolved] = FoundCapture(path=resolved, name=str(relative), skip_reason=_skip_reason(directory))
        if not seen:
            raise ConfigError(f"{archive}: no capture found (no directory holding {MANIFEST} under it)")
    return sorted(found.values(), key=lambda c: c.name)
