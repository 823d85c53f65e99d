"""Files `rig process` writes: height/phase/mask arrays, a binary PLY, report.json, preview.png."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np

PREVIEW_BAR_PX = 90  # width of the scale bar panel at the right of the preview


def write_array(path: Path, array: np.ndarray) -> Path:
    """Save an array as .npy."""
    np.save(path, array)
    return path


def write_ply(path: Path, points: np.ndarray, colors: np.ndarray | None = None) -> Path:
    """Binary little-endian PLY of (N, 3) points in mm (float32), optional (N, 3) uint8 colours."""
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    header = ["ply", "format binary_little_endian 1.0", "comment fpp-rig point cloud, units mm", f"element vertex {len(pts)}",
              "property float x", "property float y", "property float z"]
    if colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
        header += ["property uchar red", "property uchar green", "property uchar blue"]
    header.append("end_header")
    record = np.empty(len(pts), dtype=fields)
    record["x"], record["y"], record["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    if colors is not None:
        rgb = np.asarray(colors, dtype=np.uint8).reshape(-1, 3)
        record["red"], record["green"], record["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    with open(path, "wb") as handle:
        handle.write(("\n".join(header) + "\n").encode("ascii"))
        handle.write(record.tobytes())
    return path


def read_ply_points(path: Path) -> np.ndarray:
    """Points (N, 3) of a PLY written by :func:`write_ply` (for checks and tests)."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    count = next(int(line.split()[2]) for line in header if line.startswith("element vertex"))
    names = [line.split()[2] for line in header if line.startswith("property")]
    fields = [(name, "<f4" if name in "xyz" else "u1") for name in names]
    record = np.frombuffer(data[end:], dtype=fields, count=count)
    return np.column_stack([record["x"], record["y"], record["z"]]).astype(np.float64)


def _nice_step(span: float, ticks: int = 5) -> float:
    raw = span / max(ticks, 1)
    if raw <= 0 or not np.isfinite(raw):
        return 1.0
    magnitude = 10.0 ** np.floor(np.log10(raw))
    for factor in (1.0, 2.0, 2.5, 5.0, 10.0):
        if raw <= factor * magnitude:
            return factor * magnitude
    return 10.0 * magnitude


def colour_map(values: np.ndarray, low: float, high: float, invalid_bgr: tuple[int, int, int] = (40, 40, 40)) -> np.ndarray:
    """BGR uint8 image of ``values`` mapped through the turbo colour map over [low, high]; NaN grey."""
    finite = np.isfinite(values)
    scale = 255.0 / (high - low) if high > low else 0.0
    levels = np.zeros(values.shape, dtype=np.uint8)
    levels[finite] = np.clip((values[finite] - low) * scale, 0, 255).astype(np.uint8)
    image = cv2.applyColorMap(levels, cv2.COLORMAP_TURBO)
    image[~finite] = invalid_bgr
    return image


def write_preview(path: Path, values: np.ndarray, unit: str, title: str = "") -> tuple[float, float]:
    """Colour-mapped preview of a map with a vertical scale bar labelled in ``unit``.

    The colour range is the 1st..99th percentile of the finite values, so a few outliers do not
    flatten the picture. Returns (low, high) of the colour range.
    """
    values = np.asarray(values, dtype=np.float64)
    finite = values[np.isfinite(values)]
    if finite.size:
        low, high = (float(v) for v in np.percentile(finite, [1.0, 99.0]))
        if high <= low:
            low, high = low - 0.5, high + 0.5
    else:
        low, high = 0.0, 1.0
    image = colour_map(values, low, high)
    rows = image.shape[0]
    panel = np.full((rows, PREVIEW_BAR_PX, 3), 255, dtype=np.uint8)
    top, bottom = 12, max(rows - 12, 13)
    ramp = np.linspace(high, low, bottom - top)[:, None].repeat(18, axis=1)
    panel[top:bottom, 8:26] = colour_map(ramp, low, high)
    font, font_scale = cv2.FONT_HERSHEY_SIMPLEX, 0.35 if rows < 300 else 0.45
    step = _nice_step(high - low)
    tick = np.ceil(low / step) * step
    while tick <= high + 1e-9 * step:
        y = int(round(top + (high - tick) / (high - low) * (bottom - top - 1)))
        cv2.line(panel, (26, y), (31, y), (0, 0, 0), 1)
        label = f"{tick + 0.0:g}"  # no "-0"
        cv2.putText(panel, label, (34, y + 4), font, font_scale, (0, 0, 0), 1, cv2.LINE_AA)
        tick += step
    cv2.putText(panel, unit, (8, min(rows - 2, bottom + 10)), font, font_scale, (0, 0, 0), 1, cv2.LINE_AA)
    out = np.concatenate([image, panel], axis=1)
    if title:
        cv2.putText(out, title, (6, 16), font, font_scale, (255, 255, 255), 1, cv2.LINE_AA)
    if not cv2.imwrite(str(path), out):
        raise OSError(f"{path}: cannot write PNG")
    return low, high


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def write_report(path: Path, report: Mapping[str, Any]) -> Path:
    """report.json, pretty-printed (numpy scalars and paths converted)."""
    text = json.dumps(report, indent=2, default=_json_default, ensure_ascii=False) + "\n"
    tmp = Path(f"{path}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path
