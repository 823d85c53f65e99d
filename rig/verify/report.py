"""The verification's outputs: report.json, report.md and its figures, written atomically.

``report.json`` is described in :mod:`rig.verify.results`; ``report.md`` gives the verdict, what
fails and by how much, the trend since calibration with its advice, the per-position table, and
links the figures: ``figures/positions.png`` (where each artefact stood), ``figures/residuals-
<kind>.png`` (the residual map on each artefact) and ``figures/history.png``.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2

from rig import __version__
from rig.errors import OutputError
from rig.store import files
from rig.verify import guideline
from rig.verify.artefacts import Artefacts
from rig.verify.guideline import QUANTITIES, Placement, Volume
from rig.verify.history import Drift, drift, history_entry, read_history
from rig.verify.measure import PositionResult
from rig.verify.plan import VerificationPlan, size_notes
from rig.verify.results import (
    REPORT_FORMAT,
    REPORT_VERSION,
    Failed,
    Verification,
    failures,
    summarise,
    summary_line,
)

REPORT_FILE = "report.json"
MARKDOWN_FILE = "report.md"
FIGURES_DIR = "figures"


def calibration_record(calibration_dir: Path) -> dict[str, Any]:
    """What report.json says about the calibration it verified (its file's SHA-256 identifies it)."""
    from calibration.store import FILENAME, read_calibration

    cal = read_calibration(calibration_dir)
    raw = files.read_regular(Path(calibration_dir) / FILENAME, str(calibration_dir), OutputError)
    return {
        "path": str(calibration_dir),
        "sha256": hashlib.sha256(raw).hexdigest(),
        "model": cal.model,
        "l0_mm": cal.l0_mm,
        "d0_mm": cal.d0_mm,
        "f0_per_mm": cal.f0_per_mm,
        "pixel_mm": cal.pixel_mm,
    }


def build_report(
    results: Sequence[PositionResult],
    failed: Sequence[Failed],
    plan: VerificationPlan,
    artefacts: Artefacts,
    volume: Volume,
    calibration_dir: Path,
) -> dict[str, Any]:
    """report.json's content (without the drift, which needs the history)."""
    report: dict[str, Any] = {
        "format": REPORT_FORMAT,
        "version": REPORT_VERSION,
        "software": f"fpp-rig {__version__}",
        "guideline": "VDI/VDE 2634 Part 2 (as read in docs/verification.md)",
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        **summarise(results, failed, plan.mpe_mm),
        "volume": volume.as_dict(),
        "L0_mm": volume.l0_mm,
        "calibration": calibration_record(calibration_dir),
        "artefacts": artefacts.as_dict(),
        "positions": [r.as_dict() for r in results]
        + [{"name": f.placement.name, "where": f.placement.where, "failed": f.reason} for f in failed],
        "notes": plan.notes() + size_notes(volume, artefacts),
    }
    report["failures"] = failures(report)
    report["summary"] = summary_line(report)
    return report


def _png(image: Any) -> bytes:
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise OutputError("could not encode a report figure as PNG")
    return encoded.tobytes()


def _write_outputs(
    directory: Path, report: dict[str, Any], results: Sequence[PositionResult], spots: Sequence[Placement],
    volume: Volume, history: list[dict[str, Any]], plate_mm: float,
) -> None:  # fmt: skip
    from rig.verify.figures import history_plot, positions_sketch, residual_panel

    (directory / FIGURES_DIR).mkdir(exist_ok=True)
    figures = {"positions.png": positions_sketch(volume, spots, plate_mm)}
    for kind in guideline.KINDS:
        image = residual_panel(results, kind)
        if image is not None:
            figures[f"residuals-{kind}.png"] = image
    figures["history.png"] = history_plot([*history, history_entry(report)])
    for name, image in figures.items():
        files.write_bytes_atomic(directory / FIGURES_DIR / name, _png(image))
    files.write_bytes_atomic(directory / MARKDOWN_FILE, markdown(report, history, sorted(figures)).encode("utf-8"))
    files.write_bytes_atomic(
        directory / REPORT_FILE, (json.dumps(report, indent=2) + "\n").encode("utf-8")
    )  # last: the marker


def _complete(
    directory: Path, output: Path, results: Sequence[PositionResult], failed: Sequence[Failed],
    plan: VerificationPlan, artefacts: Artefacts, volume: Volume, calibration_dir: Path, captures: str,
) -> Verification:  # fmt: skip
    report = build_report(results, failed, plan, artefacts, volume, calibration_dir)
    report["report_path"] = str(output)
    report["captures"] = captures
    history = read_history(calibration_dir)
    trend: Drift = drift(history, report)
    report["drift"] = trend.as_dict()
    spots = [r.placement for r in results] + [f.placement for f in failed]
    spots = sorted(spots, key=lambda p: p.name)
    _write_outputs(directory, report, results, spots, volume, history, artefacts.plane_length_mm)
    return Verification(report, list(results), list(failed), trend, output)


def finish(
    staging: Path, output: Path, results: Sequence[PositionResult], failed: Sequence[Failed],
    plan: VerificationPlan, artefacts: Artefacts, volume: Volume, calibration_dir: Path, captures: str,
) -> Verification:  # fmt: skip
    """Write the report of a new verification into its staging directory (committed as ``output``).

    ``captures``: where its captures are, as report.json records it.
    """
    return _complete(staging, output, results, failed, plan, artefacts, volume, calibration_dir, captures)


def write_in_place(
    directory: Path, results: Sequence[PositionResult], failed: Sequence[Failed], plan: VerificationPlan,
    artefacts: Artefacts, volume: Volume, calibration_dir: Path, captures: str,
) -> Verification:  # fmt: skip
    """Rewrite the report of stored captures beside them (each file replaced atomically, report.json last)."""
    files.check_writable_directory(directory, OutputError)
    return _complete(directory, directory, results, failed, plan, artefacts, volume, calibration_dir, captures)


def _value(q: str, value: float | None) -> str:
    if value is None:
        return "n/a"
    return f"{value:+.4f}" if q in ("PS", "SD") else f"{value:.4f}"


def markdown(report: dict[str, Any], history: list[dict[str, Any]], figures: Sequence[str]) -> str:
    """The human report."""
    cal = report["calibration"]
    lines = [
        "# Verification (VDI/VDE 2634 Part 2)",
        "",
        f"**{report['summary']}**",
        "",
        f"Calibration `{cal['path']}` (sha256 {cal['sha256'][:12]}), created {report['created']}.",
        f"Measuring volume {report['volume']['width_mm']:.1f} x {report['volume']['length_mm']:.1f} x "
        f"{report['volume']['depth_mm']:.1f} mm, L0 = {report['L0_mm']:.1f} mm.",
        "",
    ]
    lines += [f"- {line}" for line in report["failures"] + report["drift"]["warnings"] + report["notes"]]
    lines += ["", "| quantity | worst (mm) | MPE (mm) | result |", "| --- | --- | --- | --- |"]
    for q in QUANTITIES:
        e = report[q]
        lines.append(f"| {q} | {_value(q, e['worst_mm'])} | {e['mpe_mm']:g} | {'pass' if e['pass'] else 'FAIL'} |")
    lines += [
        "",
        "## Per position",
        "",
        "| position | where | quantity | value (mm) | result |",
        "| --- | --- | --- | --- | --- |",
    ]
    for q in QUANTITIES:
        for p in report[q]["positions"]:
            why = f" ({p['why']})" if "why" in p else ""
            lines.append(
                f"| {p['position']} | {p['where']} | {q} | {_value(q, p['value_mm'])}{why} | {'pass' if p['pass'] else 'FAIL'} |"
            )
    lines += _trend_lines(report, history)
    lines += ["", "## Figures", ""] + [f"![{name}]({FIGURES_DIR}/{name})" for name in figures]
    return "\n".join(lines) + "\n"


def _trend_lines(report: dict[str, Any], history: list[dict[str, Any]]) -> list[str]:
    runs = [e for e in history if e.get("calibration_sha256") == report["calibration"]["sha256"]]
    lines = ["", "## Trend since calibration", ""]
    if not runs:
        return lines + ["The first verification of this calibration: the reference for later runs."]
    lines += ["| run | result | " + " | ".join(QUANTITIES) + " |", "| --- | --- |" + " --- |" * len(QUANTITIES)]
    for e in [*runs, history_entry(report)]:
        values = " | ".join(_value(q, e["worst_mm"].get(q)) for q in QUANTITIES)
        lines.append(f"| {e['created']} | {'pass' if e['pass'] else 'FAIL'} | {values} |")
    changes = ", ".join(f"{q} {_value('PS', v)}" for q, v in report["drift"]["change_mm"].items() if v is not None)
    lines += ["", f"Change since the first run: {changes} mm; advice: {report['drift']['advice']}."]
    return lines


def read_report(directory: Path) -> dict[str, Any]:
    """A verification's report.json (for a front-end that shows it)."""
    data = files.read_json(Path(directory) / REPORT_FILE, OutputError, "missing (not a verification report?)")
    if not isinstance(data, dict) or data.get("format") != REPORT_FORMAT:
        raise OutputError(f"{Path(directory) / REPORT_FILE}: format: expected {REPORT_FORMAT!r}")
    return data
