"""Deleting, restoring and renaming what the data directory holds, without ever losing it.

Delete moves ``DATA/KIND/NAME`` to ``DATA/trash/KIND/NAME@YYYYmmdd-HHMMSS-ffffff`` (one rename
on the same file system: nothing is copied or removed; ``@`` is never part of a name, so the
original name is read back from the entry's own name). Restore moves an entry back under its
name, refused while that name is taken. The trash is emptied by hand only. Rename moves
``DATA/KIND/OLD`` to ``DATA/KIND/NEW``, refused while NEW is taken.

Entries being written (a scan's or a result's staging folder) or used by a running job are
refused with one line: the move would pull the folder from under the writer.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any

from rig.console.datadir import NAME, TRASH, DataDir
from rig.console.session import Conflict
from rig.errors import RigError

MANAGED = ("captures", "results", "calibrations")
STAMP = "%Y%m%d-%H%M%S-%f"
SEPARATOR = "@"


class TrashError(RigError):
    """A delete, restore or rename that cannot be done as asked."""


class NameTaken(TrashError, Conflict):
    """The target name exists already (the console answers 409)."""


@dataclass(frozen=True)
class Entry:
    """One thing in the trash: what it was and when it was moved there."""

    kind: str
    name: str
    entry: str  # the folder's name in DATA/trash/KIND
    trashed_utc: str

    def as_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "name": self.name, "entry": self.entry, "trashed_utc": self.trashed_utc}


def _kind(kind: str) -> str:
    if kind not in MANAGED:
        raise TrashError(f"kind: expected one of {', '.join(MANAGED)}, found {kind!r}")
    return kind


def _parse(kind: str, entry: str) -> Entry | None:
    name, sep, stamp = entry.rpartition(SEPARATOR)
    if not sep or not NAME.fullmatch(name):
        return None
    try:
        when = datetime.strptime(stamp, STAMP).replace(tzinfo=timezone.utc)
    except ValueError:
        return None
    return Entry(kind, name, entry, when.isoformat(timespec="seconds"))


class Trash:
    """Delete to DATA/trash, restore and rename for one data directory; ``busy(kind, name)`` says
    whether a running job uses an entry."""

    def __init__(self, data: DataDir) -> None:
        self.data = data

    def _check_idle(self, kind: str, name: str, busy: bool) -> None:
        if busy or self.data.staged(kind, name):
            raise TrashError(f"{kind}/{name}: in use by a running job; wait for it to end or stop it")

    def delete(self, kind: str, name: str, busy: bool = False) -> Entry:
        """Move DATA/KIND/NAME into the trash; the entry that restores it."""
        source = self.data.existing(_kind(kind), name)
        self._check_idle(kind, name, busy)
        folder = self.data.root / TRASH / kind
        folder.mkdir(parents=True, exist_ok=True)
        stamp = datetime.now(timezone.utc).strftime(STAMP)
        entry = f"{name}{SEPARATOR}{stamp}"
        os.rename(source, folder / entry)
        parsed = _parse(kind, entry)
        assert parsed is not None  # made above from a checked name and the stamp's own format
        return parsed

    def entries(self) -> list[Entry]:
        """What the trash holds of the managed kinds, newest first."""
        found = []
        for kind in MANAGED:
            folder = self.data.root / TRASH / kind
            if not folder.is_dir():
                continue
            for child in folder.iterdir():
                parsed = _parse(kind, child.name)
                if parsed is not None and child.is_dir() and not child.is_symlink():
                    found.append(parsed)
        return sorted(found, key=lambda e: e.trashed_utc + e.entry, reverse=True)

    def restore(self, kind: str, entry: str) -> str:
        """Move a trash entry back to DATA/KIND/NAME; its name there. NameTaken while NAME exists."""
        parsed = next((e for e in self.entries() if e.kind == _kind(kind) and e.entry == entry), None)
        if parsed is None:
            raise FileNotFoundError(f"{TRASH}/{kind}/{entry}: not in the trash")
        target = self.data.path(kind, parsed.name)
        if os.path.lexists(target) or self.data.staged(kind, parsed.name):
            raise NameTaken(f"{kind}/{parsed.name}: the name is taken again; rename that one first, then restore")
        os.rename(self.data.root / TRASH / kind / entry, target)
        return parsed.name

    def rename(self, kind: str, name: str, new: str, busy: bool = False) -> str:
        """Rename DATA/KIND/NAME to NEW; NameTaken while NEW exists."""
        source = self.data.existing(_kind(kind), name)
        target = self.data.path(kind, new)  # refuses a name that is not plain
        self._check_idle(kind, name, busy)
        if os.path.lexists(target) or self.data.staged(kind, new):
            raise NameTaken(f"{kind}/{new}: the name is taken; choose another")
        os.rename(source, target)
        return new
