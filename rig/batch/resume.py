"""What makes a finished output reusable: a fingerprint of everything that decides its content.

The fingerprint hashes the capture's manifest (its frames' sha256 checksums, patterns, camera),
the calibration's ``calibration.json`` and its reference capture's manifest, the processing
options, the corrections compared and the program version. Each output's ``report.json`` carries
it under ``batch.fingerprint``; a rerun keeps an output whose fingerprint matches and whose files
are all there, and processes everything else again.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import shutil
import stat
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from rig import __version__
from rig.errors import RigError
from rig.pipeline.plan import ProcessOptions
from rig.store import files, results
from rig.store.files import INCOMPLETE_MARK, KINDS, REPLACED_MARK
from rig.store.results import DEFAULT_FORMATS

BATCH_KEY = "batch"  # report.json key holding the batch's bookkeeping


def _canonical(obj: Any) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str).encode("utf-8")


def manifest_digest(capture_dir: Path) -> str | None:
    """sha256 of a capture's manifest content (None when it cannot be read: such a capture is always processed)."""
    try:
        manifest = files.read_json(capture_dir / "capture.json", files.FileLayerError)
    except files.FileLayerError:
        return None
    return hashlib.sha256(_canonical(manifest)).hexdigest()


def calibration_digest(calibration_dir: Path | None) -> str:
    """sha256 of calibration.json's bytes and of its reference capture's manifest ("" without calibration)."""
    if calibration_dir is None:
        return ""
    digest = hashlib.sha256()
    path = calibration_dir / "calibration.json"
    try:
        data = files.read_regular(path, str(path), files.FileLayerError, files.limits().max_manifest_bytes)
    except files.FileLayerError:
        return "unreadable"  # processing reports the error itself
    digest.update(data)
    try:
        reference = json.loads(data).get("reference")
    except (UnicodeDecodeError, json.JSONDecodeError, AttributeError):
        reference = None
    if isinstance(reference, str):
        ref_dir = Path(reference) if Path(reference).is_absolute() else calibration_dir / reference
        digest.update((manifest_digest(ref_dir) or "").encode("ascii"))
    return digest.hexdigest()


def options_key(options: ProcessOptions, compare: Sequence[str], formats: Sequence[str] = DEFAULT_FORMATS) -> str:
    """The options, compared corrections and output formats as canonical text (part of every fingerprint).

    The default formats are left out, so outputs of runs from before ``--format`` stay reusable.
    """
    key: dict[str, Any] = {"options": dataclasses.asdict(options), "compare": list(compare), "program": __version__}
    if tuple(formats) != DEFAULT_FORMATS:
        key["formats"] = list(formats)
    return _canonical(key).decode()


def fingerprint(capture_dir: Path, calibration: str, options: str) -> str | None:
    """Fingerprint of one capture's inputs; None when its manifest is unreadable (never reused)."""
    manifest = manifest_digest(capture_dir)
    if manifest is None:
        return None
    return hashlib.sha256(_canonical([manifest, calibration, options])).hexdigest()


def reusable_report(out_dir: Path, expected: str | None) -> dict[str, Any] | None:
    """The report of a finished output whose fingerprint is ``expected`` and whose files all exist, else None."""
    if expected is None or not results.is_result(out_dir):
        return None
    try:
        report = results.read_report(out_dir)
    except RigError:
        return None
    if not isinstance(report.get(BATCH_KEY), dict) or report[BATCH_KEY].get("fingerprint") != expected:
        return None
    listed = report.get("files")
    if not isinstance(listed, dict) or not all(
        isinstance(f, str) and results.has_file(out_dir, f) for f in listed.values()
    ):
        return None
    return report


# What a killed run can leave beside the outputs it writes, by exact name: the staging and set-aside
# folders of an output's commit (the output's name, the mark, ``tempfile.mkdtemp``'s 8 characters)
# and the temporaries of its tables (``.index.csv.XXXXXXXX.tmp``).
_LEFTOVER = re.compile(rf"(.+)(?:{re.escape(INCOMPLETE_MARK)}|{re.escape(REPLACED_MARK)})[a-z0-9_]{{8}}")
_TABLE_TEMPORARY = re.compile(r"\.(.+)\.[a-z0-9_]{8}\.tmp")
_OUTPUT_MARKER = KINDS["output"][0]  # report.json: a whole output's staging folder holds it
# Marker files of what this program writes other than a processing output: never in an output's
# leftovers. A verification's marker is report.json too: its content tells them apart.
_FOREIGN_MARKERS = frozenset(marker for kind, (marker, _, _) in KINDS.items() if kind != "output") - {_OUTPUT_MARKER}
_SHARED_MARKER_KINDS = [
    (key, values) for kind, (marker, key, values) in KINDS.items() if kind != "output" and marker == _OUTPUT_MARKER
]


def _is_output_leftover(path: Path) -> bool:
    """Whether ``path`` is a flat folder of regular files holding no other kind's marker (what an
    output's commit leaves); a capture kept for ``--salvage`` has frames/ and capture.json."""
    try:
        if not stat.S_ISDIR(os.lstat(path).st_mode):
            return False
        entries = list(os.scandir(path))
    except OSError:
        return False
    flat = all(e.is_file(follow_symlinks=False) and e.name not in _FOREIGN_MARKERS for e in entries)
    return flat and not _is_foreign_report(path / _OUTPUT_MARKER)


def _is_foreign_report(report: Path) -> bool:
    """Whether ``report`` is another kind's report.json (a verification's), not an output's."""
    try:
        data = files.read_json(report, files.FileLayerError, strict=False)
    except files.FileLayerError:
        return False  # none, or cut short by the kill: an output's
    return isinstance(data, dict) and any(
        key in data and any(str(data[key]) == v or str(data[key]).startswith(v + " ") for v in values)
        for key, values in _SHARED_MARKER_KINDS
    )


def _entries(directory: Path) -> list[os.DirEntry[str]]:
    try:
        return list(os.scandir(directory))
    except OSError:
        return []


def remove_stale(root: Path, outputs: Iterable[str], tables: Iterable[str]) -> int:
    """Remove what a killed run left beside the ``outputs`` (names relative to ``root``) and the
    ``tables`` (file names in ``root``) a batch writes; returns how many.

    Only exact names are removed: ``NAME.incomplete-XXXXXXXX`` and ``NAME.replaced-XXXXXXXX``
    beside an output ``NAME`` (and only when :func:`_is_output_leftover`), ``.TABLE.XXXXXXXX.tmp``
    beside a table. Nothing is walked: an archive's interrupted capture or a user's folder that
    lies under ``root`` is never touched.
    """
    by_parent: dict[Path, set[str]] = {}
    for name in outputs:
        output = root / name
        by_parent.setdefault(output.parent, set()).add(output.name)
    removed = 0
    for parent, names in by_parent.items():
        for entry in _entries(parent):
            match = _LEFTOVER.fullmatch(entry.name)
            if match and match.group(1) in names and _is_output_leftover(Path(entry.path)):
                shutil.rmtree(entry.path, ignore_errors=True)
                removed += 1
    table_names = set(tables)
    for entry in _entries(root):
        match = _TABLE_TEMPORARY.fullmatch(entry.name)
        if match and match.group(1) in table_names and entry.is_file(follow_symlinks=False):
            Path(entry.path).unlink(missing_ok=True)
            removed += 1
    return removed
