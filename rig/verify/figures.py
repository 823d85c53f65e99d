"""Figures of a verification report, drawn with OpenCV like the study's: residual maps, positions, history."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np

from rig.study.figures import BLACK, FONT, GREY, PALETTE, colorize, line_plot, panel
from rig.verify.guideline import QUANTITIES, Placement, Volume
from rig.verify.measure import PositionResult

TILE_PX = 200


def residual_panel(results: Sequence[PositionResult], kind: str) -> np.ndarray | None:
    """Residual maps of every position of one artefact kind on a common colour scale (None: no position)."""
    chosen = [r for r in results if r.placement.kind == kind]
    if not chosen:
        return None
    maps = [m for r in chosen for m in r.maps]
    limit = max((float(np.nanmax(np.abs(m))) for m in maps if np.isfinite(m).any()), default=1e-3)
    tiles = []
    for r in chosen:
        value = ", ".join(f"{q} {v:+.3f}" for q, v in r.values.items())
        for i, m in enumerate(r.maps):
            label = r.placement.name + (f" ball {i + 1}" if len(r.maps) > 1 else "")
            tiles.append((f"{label}: {value}", colorize(m, -limit, limit, size=TILE_PX)))
    title = f"{kind}: signed residuals to the fitted element, blue -{limit:.3f} mm .. red +{limit:.3f} mm"
    return panel(tiles, columns=4, title=title)


def _view(
    volume: Volume, spots: Sequence[Placement], axis: int, title: str, plate_mm: float, size: int = 420
) -> np.ndarray:
    """One orthographic view of the volume (axis 1: top view x-y; axis 2: front view x-z)."""
    canvas = np.full((size, size, 3), 255, np.uint8)
    w = volume.width_mm
    lo, hi = (-volume.length_mm / 2, volume.length_mm / 2) if axis == 1 else (0.0, volume.depth_mm)
    scale = (size - 60) / max(w, hi - lo)

    def px(p: Any) -> tuple[int, int]:
        return int(30 + (p[0] + w / 2) * scale), int(size - 30 - (p[axis] - lo) * scale)

    cv2.rectangle(canvas, px((-w / 2, lo, lo)), px((w / 2, hi, hi)), GREY, 1)
    cv2.putText(canvas, title, (8, 16), FONT, 0.45, BLACK, 1, cv2.LINE_AA)
    kinds = {"sphere": PALETTE[1], "ball-bar": PALETTE[2], "plane": PALETTE[3]}
    for spot in spots:
        if len(spot.centres) < (2 if spot.kind == "ball-bar" else 1):
            continue  # captures taken outside a session: where they stood is not known
        colour = kinds.get(spot.kind, BLACK)
        if spot.kind == "plane":
            c = np.asarray(spot.centres[0])
            ends = [c - 0.5 * plate_mm * np.asarray(spot.along), c + 0.5 * plate_mm * np.asarray(spot.along)]
            cv2.line(canvas, px(ends[0]), px(ends[1]), colour, 2, cv2.LINE_AA)
            anchor = px(c)
        elif spot.kind == "ball-bar":
            a, b = spot.centres
            cv2.line(canvas, px(a), px(b), colour, 1, cv2.LINE_AA)
            for end in (a, b):
                cv2.circle(canvas, px(end), 4, colour, -1, cv2.LINE_AA)
            anchor = px(b)
        else:
            anchor = px(spot.centres[0])
            cv2.circle(canvas, anchor, 6, colour, 2, cv2.LINE_AA)
        cv2.putText(
            canvas,
            f"{spot.kind[0].upper()}{spot.index}",
            (anchor[0] + 6, anchor[1] - 4),
            FONT,
            0.35,
            colour,
            1,
            cv2.LINE_AA,
        )
    return canvas


def positions_sketch(volume: Volume, spots: Sequence[Placement], plate_mm: float) -> np.ndarray:
    """Top (x-y) and front (x-z) views of the measuring volume with every artefact position (plates ``plate_mm`` long)."""
    top = _view(volume, spots, 1, "top view (x right, y up): S sphere, B ball bar, P plane", plate_mm)
    front = _view(volume, spots, 2, f"front view (x right, z up), L0 = {volume.l0_mm:.0f} mm", plate_mm)
    return np.hstack([top, np.full((top.shape[0], 6, 3), 255, np.uint8), front])


def history_plot(entries: Sequence[Mapping[str, Any]]) -> np.ndarray:
    """Each quantity's worst value as a share of its MPE, run after run (1.0: the MPE)."""
    runs = np.arange(1, len(entries) + 1, dtype=np.float64)
    series = []
    for q in QUANTITIES:
        ratio = []
        for e in entries:
            worst, mpe = e["worst_mm"].get(q), e["mpe_mm"].get(q)
            ratio.append(np.nan if worst is None or not mpe else abs(float(worst)) / float(mpe))
        series.append((q, runs, np.asarray(ratio)))
    series.append(("MPE", runs, np.ones_like(runs)))
    return line_plot(series, "verification history: |worst| / MPE", "run", "share of the MPE", ylim=(0.0, 1.5))
