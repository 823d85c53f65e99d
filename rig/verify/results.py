"""From per-position results to the verdict: each quantity's values, worst value, MPE and pass.

``report.json`` (the public record of one verification) holds, for each of PF, PS, SD and F:
``positions`` (one value per position in mm, with where it was), ``worst_mm`` (PF and F: the
largest, positive; PS and SD: the value of largest magnitude, signed), ``mpe_mm`` and ``pass``;
a top-level ``pass``; the measuring ``volume`` with ``L0_mm``; and the ``calibration`` verified.
A position whose artefact was not found has the value null and fails: the verdict never rests
on positions that were left out silently.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rig.verify.guideline import QUANTITIES, Placement
from rig.verify.measure import PositionResult

if TYPE_CHECKING:
    from rig.verify.history import Drift

REPORT_FORMAT = "fpp-verification"
REPORT_VERSION = 1
# Which artefact gives each quantity.
SOURCE = {"PF": "sphere", "PS": "sphere", "SD": "ball-bar", "F": "plane"}
SIGNED = ("PS", "SD")


@dataclass(frozen=True)
class Failed:
    """A position that gave no value (artefact not found, processing refused), and why."""

    placement: Placement
    reason: str


@dataclass
class Verification:
    """One verification's outcome: report.json's content, per-position results, and the drift."""

    report: dict[str, Any]
    results: list[PositionResult]
    failed: list[Failed]
    drift: Drift | None = None
    directory: Path | None = None


def parse_mpe(text: str) -> dict[str, float]:
    """``"0.3,0.2,0.3,0.3"`` -> MPE of PF, PS, SD, F in mm; ValueError naming what is wrong."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != len(QUANTITIES):
        raise ValueError(f"expected four values PF,PS,SD,F in mm, found {text!r}")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"expected four numbers PF,PS,SD,F in mm, found {text!r}") from None
    if not all(math.isfinite(v) and v > 0 for v in values):
        raise ValueError(f"expected four positive MPE values in mm, found {text!r}")
    return dict(zip(QUANTITIES, values))


def _worst(name: str, values: Sequence[float]) -> float | None:
    finite = [v for v in values if math.isfinite(v)]
    if not finite:
        return None
    return max(finite, key=abs) if name in SIGNED else max(finite)


def quantity_summary(
    name: str, results: Sequence[PositionResult], failed: Sequence[Failed], mpe_mm: float
) -> dict[str, Any]:
    """One quantity's entry of report.json."""
    positions: list[dict[str, Any]] = []
    for r in results:
        if name in r.values:
            value = float(r.values[name])
            positions.append(
                {
                    "position": r.placement.name,
                    "where": r.placement.where,
                    "value_mm": value,
                    "pass": abs(value) <= mpe_mm,
                }
            )
    for f in failed:
        if f.placement.kind == SOURCE[name]:
            positions.append(
                {
                    "position": f.placement.name,
                    "where": f.placement.where,
                    "value_mm": None,
                    "pass": False,
                    "why": f.reason,
                }
            )
    positions.sort(key=lambda p: p["position"])
    worst = _worst(name, [p["value_mm"] for p in positions if p["value_mm"] is not None])
    passed = bool(positions) and all(p["pass"] for p in positions)
    return {"positions": positions, "worst_mm": worst, "mpe_mm": mpe_mm, "pass": passed}


def summarise(
    results: Sequence[PositionResult], failed: Sequence[Failed], mpe_mm: Mapping[str, float]
) -> dict[str, Any]:
    """The four quantities and the top-level ``pass`` (every quantity measured and within its MPE)."""
    out: dict[str, Any] = {q: quantity_summary(q, results, failed, mpe_mm[q]) for q in QUANTITIES}
    out["pass"] = all(out[q]["pass"] for q in QUANTITIES)
    return out


def summary_line(report: Mapping[str, Any]) -> str:
    """``PASS  PF 0.254  PS +0.021  SD -0.043  F 0.180 mm`` (the worst values), for the terminal."""
    parts = []
    for q in QUANTITIES:
        worst = report[q]["worst_mm"]
        if worst is None:
            parts.append(f"{q} n/a")
        else:
            flag = "" if report[q]["pass"] else "!"
            parts.append(f"{q} {worst:+.3f}{flag}" if q in SIGNED else f"{q} {worst:.3f}{flag}")
    return ("PASS" if report["pass"] else "FAIL") + "  " + "  ".join(parts) + " mm"


def failures(report: Mapping[str, Any]) -> list[str]:
    """Which quantities fail and by how much (worst beyond the MPE), one line each."""
    lines = []
    for q in QUANTITIES:
        entry = report[q]
        if entry["pass"]:
            continue
        worst, mpe = entry["worst_mm"], entry["mpe_mm"]
        missing = [p["position"] for p in entry["positions"] if p["value_mm"] is None]
        if worst is not None and abs(worst) > mpe:
            bad = [p["position"] for p in entry["positions"] if p["value_mm"] is not None and not p["pass"]]
            lines.append(
                f"{q} fails: worst {worst:+.3f} mm exceeds the MPE {mpe:g} mm by {abs(worst) - mpe:.3f} mm "
                f"({len(bad)} of {len(entry['positions'])} positions: {', '.join(bad)})"
            )
        if missing:
            lines.append(f"{q} fails: no value at {', '.join(missing)}")
        if not entry["positions"]:
            lines.append(f"{q} fails: no position measured")
    return lines
