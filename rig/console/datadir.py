"""The console's data directory: where captures, results and calibrations live, and the one gate
every name the API receives goes through so that no request reaches a path outside it.

Layout::

    DATA/captures/NAME/        captures (capture.json + frames), scans made from the console
    DATA/results/NAME/         outputs of processing a capture (report.json, height.npy, points.ply, ...)
    DATA/calibrations/NAME/    calibrations (calibration.json); scans are processed with the chosen one
"""

from __future__ import annotations

import re
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from rig.errors import RigError
from rig.store.results import REPORT, default_name, is_staging_name

KINDS = ("captures", "results", "calibrations")
MARKERS = {"captures": "capture.json", "results": REPORT, "calibrations": "calibration.json"}
NAME_LENGTH = 100
NAME = re.compile(rf"[A-Za-z0-9][A-Za-z0-9._-]{{0,{NAME_LENGTH - 1}}}")


class OutsideDataError(RigError):
    """A name the API received is not a plain name inside the data directory."""


class DataDir:
    """The data directory of one console; created if missing."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root).resolve()
        for kind in KINDS:
            (self.root / kind).mkdir(parents=True, exist_ok=True)

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
        if kind == "results" and is_staging_name(name):
            raise OutsideDataError(f"{kind} name {name!r}: a staging name of an interrupted write, never a result")
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
        folder = self.root / kind
        entries = []
        for child in folder.iterdir():
            marker = child / MARKERS[kind]
            if (
                NAME.fullmatch(child.name)
                and not (kind == "results" and is_staging_name(child.name))
                and marker.is_file()
                and child.resolve().is_relative_to(self.root)
            ):
                entries.append((marker.stat().st_mtime, child.name))
        return [name for _, name in sorted(entries, reverse=True)]

    def new_name(self, kind: str, prefix: str) -> str:
        """A name not yet used in ``kind``: ``prefix-YYYYmmdd-HHMMSS`` (``-2``, ``-3`` ... if taken).

        A prefix too long for a name (a long capture's name) is cut short with a hash of it, so that
        the name is always one :meth:`path` accepts.
        """
        stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
        base = default_name(prefix, f"-{stamp}", limit=NAME_LENGTH - len("-999"))
        name, n = base, 1
        while any(p.name == name or p.name.startswith(name + ".incomplete") for p in (self.root / kind).iterdir()):
            n += 1
            name = f"{base}-{n}"
        return name

    def describe(self) -> dict[str, Any]:
        return {"root": str(self.root), **{kind: len(self.names(kind)) for kind in KINDS}}
