"""The console's data directory: where captures, results and calibrations live, and the one gate
every name the API receives goes through so that no request reaches a path outside it.

Layout::

    DATA/captures/NAME/        captures (capture.json + frames), scans made from the console
    DATA/results/NAME/         outputs of processing a capture (report.json, height.npy, points.ply, ...)
    DATA/calibrations/NAME/    calibrations (calibration.json); scans are processed with the chosen one
    DATA/verifications/NAME/   verifications of a calibration (report.json, report.md, figures/, captures/)
    DATA/artefacts.toml        the calibrated artefacts a verification uses (default: the simulated rig's)
    DATA/trash/KIND/NAME/      what the operator discarded (an interrupted scan), kept until removed by hand
    DATA/trash/KIND/NAME@TIME/ a capture, result or calibration deleted from the page (restorable:
                               rig.console.trash)

Staging folders the file layer writes into (``NAME.incomplete-XXXX``, ``NAME.replaced-XXXX``) are
never names: a kill between writing and renaming leaves one behind, and it must not pass for a
capture, a result or a calibration. If the directory (or one of its folders) is removed while the
console runs, the layout is made again on the next use; if that fails, the error says so.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from rig.errors import RigError
from rig.store.files import INCOMPLETE_MARK, REPLACED_MARK
from rig.store.results import REPORT, default_name, is_staging_name

KINDS = ("captures", "results", "calibrations", "verifications")
TRASH = "trash"  # what the operator discarded, moved rather than deleted
MARKERS = {
    "captures": "capture.json",
    "results": REPORT,
    "calibrations": "calibration.json",
    "verifications": REPORT,
}
NAME_LENGTH = 100
NAME = re.compile(rf"[A-Za-z0-9][A-Za-z0-9._-]{{0,{NAME_LENGTH - 1}}}")


class OutsideDataError(RigError):
    """A name the API received is not a plain name inside the data directory."""


class DataDir:
    """The data directory of one console; created if missing (and again if removed meanwhile)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root).resolve()
        self.ensure()

    def ensure(self) -> None:
        """Make DATA and its folders if any is missing; a RigError naming the folder if it cannot."""
        for kind in KINDS:
            folder = self.root / kind
            if folder.is_dir():
                continue
            try:
                folder.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise RigError(f"data directory {folder}: cannot be made again: {exc.strerror or exc}") from None

    def path(self, kind: str, name: str) -> Path:
        """``DATA/kind/name``, refused unless ``name`` is a plain name that stays inside DATA.

        Plain: letters, digits, ``.``, ``_``, ``-``, starting with a letter or digit (no ``/``, no
        ``..``); and it must not resolve (through a symbolic link) outside the data directory.
        """
        if kind not in KINDS:
            raise OutsideDataError(f"kind: expected one of {', '.join(KINDS)}, found {kind!r}")
        if not isinstance(name, str) or not NAME.fullmatch(name) or ".." in name:
            raise OutsideDataError(
                f"{kind} name: expected a plain name (letters, digits, '.', '_', '-'; no '/' or '..'), found {name!r}"
            )
        if is_staging_name(name):
            raise OutsideDataError(
                f"{kind} name {name!r}: {INCOMPLETE_MARK!r} and {REPLACED_MARK!r} mark unfinished writes, not names"
            )
        self.ensure()
        path = self.root / kind / name
        if not path.resolve().is_relative_to(self.root):
            raise OutsideDataError(f"{kind} name {name!r}: leads outside the data directory")
        return path

    def existing(self, kind: str, name: str) -> Path:
        """Like :meth:`path`, but the entry must exist (its marker file present)."""
        path = self.path(kind, name)
        if not (path / MARKERS[kind]).is_file():
            raise FileNotFoundError(f"{kind}/{name}: not found in the data directory")
        return path

    def names(self, kind: str) -> list[str]:
        """Complete entries of ``kind``, newest first (by the marker file's modification time)."""
        self.ensure()
        folder = self.root / kind
        entries = []
        for child in folder.iterdir():
            marker = child / MARKERS[kind]
            if not NAME.fullmatch(child.name) or is_staging_name(child.name):
                continue
            if marker.is_file() and child.resolve().is_relative_to(self.root):
                entries.append((marker.stat().st_mtime, child.name))
        return [name for _, name in sorted(entries, reverse=True)]

    def new_name(self, kind: str, prefix: str) -> str:
        """A name not yet used in ``kind``: ``prefix-YYYYmmdd-HHMMSS`` (``-2``, ``-3`` ... if taken).

        A prefix too long for a name (a long capture's name) is cut short with a hash of it, so that
        the name is always one :meth:`path` accepts.
        """
        self.ensure()
        stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
        base = default_name(prefix, f"-{stamp}", limit=NAME_LENGTH - len("-999"))
        name, n = base, 1
        while any(p.name == name or p.name.startswith(name + ".incomplete") for p in (self.root / kind).iterdir()):
            n += 1
            name = f"{base}-{n}"
        return name

    def interrupted_names(self, kind: str) -> list[str]:
        """Staging folders of ``kind`` left by an interrupted write (a stopped scan), newest first.

        Listed so that the operator can salvage or discard them; :meth:`path` never accepts them.
        """
        self.ensure()
        entries = []
        for child in (self.root / kind).iterdir():
            if INCOMPLETE_MARK in child.name and child.is_dir() and not child.is_symlink():
                entries.append((child.stat().st_mtime, child.name))
        return [name for _, name in sorted(entries, reverse=True)]

    def interrupted(self, kind: str, name: str) -> Path:
        """DATA/kind/NAME for an interrupted write's folder listed by :meth:`interrupted_names`."""
        if not isinstance(name, str) or name not in self.interrupted_names(kind):
            raise FileNotFoundError(f"{kind}/{name}: no interrupted write of that name in the data directory")
        return self.root / kind / name

    def to_trash(self, kind: str, name: str) -> str:
        """Move the interrupted write ``kind``/``name`` to DATA/trash/kind/NAME (renamed, never deleted)."""
        source = self.interrupted(kind, name)
        trash = self.root / TRASH / kind
        trash.mkdir(parents=True, exist_ok=True)
        target = trash / name
        if target.exists():
            raise RigError(f"{TRASH}/{kind}/{name}: already in the trash; remove it there first")
        source.rename(target)
        return f"{TRASH}/{kind}/{name}"

    def staged(self, kind: str, name: str) -> bool:
        """Whether a write of ``kind``/``name`` is under way (a staging folder of that name exists)."""
        folder = self.root / kind
        return any(p.name.startswith(name + INCOMPLETE_MARK) for p in folder.iterdir())

    def describe(self) -> dict[str, Any]:
        return {"root": str(self.root), **{kind: len(self.names(kind)) for kind in KINDS}}
