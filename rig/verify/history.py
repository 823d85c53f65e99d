"""``CAL/verification-history.jsonl``: one line per verification of a calibration, and its drift.

Each run appends its date, verdict, worst values and MPEs. The trend since calibration is the
change of each quantity's worst value from the first verification of that calibration; a change
of more than half the MPE, or a failing quantity, gives a warning whose advice is to recalibrate.
A recalibration writes a new calibration directory, so the history starts again with it.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rig.errors import OutputError
from rig.store import files
from rig.verify.guideline import QUANTITIES

HISTORY_FILE = "verification-history.jsonl"
DRIFT_SHARE = 0.5  # of the MPE


def history_entry(report: Mapping[str, Any]) -> dict[str, Any]:
    """The line a report adds to the history (what the trend and the console's plot need)."""
    return {
        "created": report["created"],
        "report": report.get("report_path"),
        "calibration_sha256": report["calibration"]["sha256"],
        "pass": report["pass"],
        "worst_mm": {q: report[q]["worst_mm"] for q in QUANTITIES},
        "mpe_mm": {q: report[q]["mpe_mm"] for q in QUANTITIES},
    }


def append_history(calibration_dir: Path, report: Mapping[str, Any]) -> Path:
    """Append ``report``'s entry to the calibration's history file (through the safe file layer)."""
    path = Path(calibration_dir) / HISTORY_FILE
    files.append_line(path, json.dumps(history_entry(report), sort_keys=True), OutputError)
    return path


def read_history(calibration_dir: Path) -> list[dict[str, Any]]:
    """Every well-formed entry of the calibration's history, oldest first (none when there is no file).

    A line that is not a history entry (a torn write, an edit) is skipped, not fatal: the
    history advises, the report of each run is the record.
    """
    path = Path(calibration_dir) / HISTORY_FILE
    if not path.exists():
        return []
    text = files.read_regular(path, str(path), OutputError).decode("utf-8", errors="replace")
    entries = []
    for line in text.splitlines():
        try:
            entry = json.loads(line)
        except ValueError:
            continue
        if isinstance(entry, dict) and isinstance(entry.get("worst_mm"), dict) and "created" in entry:
            entries.append(entry)
    return sorted(entries, key=lambda e: str(e["created"]))


@dataclass(frozen=True)
class Drift:
    """How far each quantity's worst value moved since the first verification of this calibration."""

    runs: int
    change_mm: dict[str, float | None]
    warnings: list[str]

    @property
    def recalibrate(self) -> bool:
        return bool(self.warnings)

    def as_dict(self) -> dict[str, Any]:
        advice = "recalibrate" if self.warnings else "none"
        return {"runs": self.runs, "change_mm": self.change_mm, "warnings": self.warnings, "advice": advice}


def drift(history: Sequence[Mapping[str, Any]], report: Mapping[str, Any]) -> Drift:
    """The trend of ``report`` against the first entry of ``history`` with the same calibration."""
    same = [e for e in history if e.get("calibration_sha256") == report["calibration"]["sha256"]]
    first = same[0] if same else None
    change: dict[str, float | None] = {}
    warnings = []
    for q in QUANTITIES:
        now, mpe = report[q]["worst_mm"], report[q]["mpe_mm"]
        before = None if first is None else first["worst_mm"].get(q)
        moved = None if now is None or before is None else float(now) - float(before)
        change[q] = moved
        if not report[q]["pass"]:
            warnings.append(f"{q} fails its MPE {mpe:g} mm: recalibrate")
        elif moved is not None and abs(moved) > DRIFT_SHARE * mpe:
            warnings.append(
                f"{q} moved by {moved:+.3f} mm since the first verification of this calibration "
                f"({first['created'] if first else ''}), more than half its MPE {mpe:g} mm: recalibrate"
            )
    return Drift(len(same) + 1, change, warnings)


def history_series(history: Sequence[Mapping[str, Any]]) -> dict[str, list[tuple[str, float | None]]]:
    """Per quantity, the (date, worst value) of each run: what a plot of the history draws."""
    return {q: [(str(e["created"]), e["worst_mm"].get(q)) for e in history] for q in QUANTITIES}
