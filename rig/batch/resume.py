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
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rig import __version__
from rig.errors import RigError
from rig.pipeline.plan import ProcessOptions
from rig.store import results
from rig.store.files import INCOMPLETE_MARK, REPLACED_MARK
from rig.store.results import DEFAULT_FORMATS

BATCH_KEY = "batch"  # report.json key holding the batch's bookkeeping


def _canonical(obj: Any) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str).encode("utf-8")


def manifest_digest(capture_dir: Path) -> str | None:
    """sha256 of a capture's manifest content (None when it cannot be read: such a capture is always processed)."""
    try:
        manifest = json.loads((capture_dir / "capture.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return hashlib.sha256(_canonical(manifest)).hexdigest()


def calibration_digest(calibration_dir: Path | None) -> str:
    """sha256 of calibration.json's bytes and of its reference capture's manifest ("" without calibration)."""
    if calibration_dir is None:
        return ""
    digest = hashlib.sha256()
    path = calibration_dir / "calibration.json"
    try:
        data = path.read_bytes()
    except OSError:
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
    files = report.get("files")
    if not isinstance(files, dict) or not all(
        isinstance(f, str) and results.has_file(out_dir, f) for f in files.values()
    ):
        return None
    return report


def remove_stale(root: Path) -> int:
    """Remove what a killed run left under ``root``: staging (``NAME.incomplete-*``) and set-aside
    (``NAME.replaced-*``) output directories, temporary report and table files; returns how many.

    Only ever called on a batch's own output directory, where nothing else is written.
    """
    removed = 0
    if not root.is_dir():
        return 0
    for here, dirs, files in os.walk(root):
        for name in list(dirs):
            if INCOMPLETE_MARK in name or REPLACED_MARK in name:
                shutil.rmtree(Path(here) / name, ignore_errors=True)
                dirs.remove(name)
                removed += 1
        for name in files:
            if name.endswith(".tmp") and (name.startswith(".") or name == "report.json.tmp"):
                (Path(here) / name).unlink(missing_ok=True)
                removed += 1
    return removed
