"""Encoders of the files in a result directory: .npy arrays, binary PLY (points and meshes),
binary STL, OBJ, E57, the colour-mapped preview PNG and report.json.

Each takes arrays and a path and writes one file; which files a result directory holds, and
their names, are :mod:`rig.store.results`' business.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from calibration.jsonfile import write_text_atomic

if TYPE_CHECKING:
    from rig.pipeline.state import SceneState


PREVIEW_BAR_PX = 90  # width of the scale bar panel at the right of the preview


def write_array(path: Path, array: np.ndarray) -> Path:
    """Save an array as .npy."""
    np.save(path, array)
    return path


def write_ply(
    path: Path,
    points: np.ndarray,
    colors: np.ndarray | None = None,
    faces: np.ndarray | None = None,
    sigma: np.ndarray | None = None,
) -> Path:
    """Binary little-endian PLY of (N, 3) points in mm (float32), optional (N, 3) uint8 colours (or (N,)
    grey), an optional (N,) float ``sigma`` (predicted standard deviation, mm) and optional (M, 3)
    triangles (vertex indices, each face a ``uchar`` count and three ``int``)."""
    pts = np.asarray(points).reshape(-1, 3)
    fields: list[tuple[str, str, tuple[int, ...]]] = [("xyz", "<f4", (3,))]
    kind = "point cloud" if faces is None else "triangle mesh"
    header = [
        "ply",
        "format binary_little_endian 1.0",
        f"comment fpp-rig {kind}, units mm",
        f"element vertex {len(pts)}",
        "property float x",
        "property float y",
        "property float z",
    ]
    if colors is not None:
        fields.append(("rgb", "u1", (3,)))
        header += ["property uchar red", "property uchar green", "property uchar blue"]
    if sigma is not None:
        fields.append(("sigma", "<f4", ()))
        header.append("property float sigma")
    if faces is not None:
        header += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    header.append("end_header")
    record = np.empty(len(pts), dtype=fields)  # packed: 12 (or 15) bytes per vertex, as the header says
    record["xyz"] = pts
    if colors is not None:
        rgb = np.asarray(colors, dtype=np.uint8)
        record["rgb"] = rgb[:, None] if rgb.ndim == 1 else rgb.reshape(-1, 3)
    if sigma is not None:
        record["sigma"] = np.asarray(sigma, dtype=np.float32).ravel()
    with open(path, "wb") as handle:
        handle.write(("\n".join(header) + "\n").encode("ascii"))
        handle.write(record.tobytes())
        if faces is not None:
            face_record = np.empty(len(faces), dtype=[("count", "u1"), ("vertices", "<i4", (3,))])
            face_record["count"] = 3
            face_record["vertices"] = faces
            handle.write(face_record.tobytes())
    return path


def parse_ply_points(data: bytes) -> np.ndarray:
    """Points (N, 3) of a PLY written by :func:`write_ply` (ValueError if it is not one)."""
    marker = b"end_header\n"
    end = data.index(marker) + len(marker)
    header = data[:end].decode("ascii").splitlines()
    count = next(int(line.split()[2]) for line in header if line.startswith("element vertex"))
    names = [line.split()[2] for line in header if line.startswith("property") and "list" not in line]
    fields = [(name, "<f4" if name in ("x", "y", "z", "sigma") else "u1") for name in names]
    record = np.frombuffer(data[end:], dtype=fields, count=count)
    return np.column_stack([record["x"], record["y"], record["z"]]).astype(np.float64)


def read_ply_points(path: Path) -> np.ndarray:
    """Points (N, 3) of a PLY written by :func:`write_ply` (for checks and tests)."""
    return parse_ply_points(Path(path).read_bytes())


def write_stl(path: Path, points: np.ndarray, faces: np.ndarray) -> Path:
    """Binary STL of the triangles ``faces`` (M, 3) over ``points`` (N, 3) mm: float32 normals and corners."""
    corners = np.asarray(points, dtype=np.float64)[faces]  # (M, 3, 3)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    np.divide(normals, length, out=normals, where=length > 0)
    record = np.zeros(len(faces), dtype=[("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    record["normal"] = normals
    record["corners"] = corners
    title = b"fpp-rig triangle mesh, units mm"
    with open(path, "wb") as handle:
        handle.write(title.ljust(80, b" "))
        handle.write(np.uint32(len(faces)).astype("<u4").tobytes())
        handle.write(record.tobytes())
    return path


def write_obj(path: Path, points: np.ndarray, faces: np.ndarray) -> Path:
    """Wavefront OBJ text: ``v x y z`` (mm, float32 precision) per point, ``f i j k`` (1-based) per triangle."""
    pts = np.asarray(points, dtype=np.float32).astype(np.float64)
    vertex_lines = ("v %.9g %.9g %.9g\n" * len(pts)) % tuple(pts.ravel())
    face_lines = ("f %d %d %d\n" * len(faces)) % tuple((np.asarray(faces, dtype=np.int64) + 1).ravel())
    with open(path, "w", encoding="ascii") as handle:
        handle.write("# fpp-rig triangle mesh, units mm\n")
        handle.write(vertex_lines)
        handle.write(face_lines)
    return path


def write_e57(path: Path, points: np.ndarray, grey: np.ndarray | None = None) -> Path:
    """ASTM E57 point cloud of (N, 3) points in mm (with 0..255 intensity), through the ``pye57`` library."""
    import pye57  # the optional extra fpp-rig[e57]; checked by the result store before any work

    pts = np.asarray(points, dtype=np.float64)
    data: dict[str, np.ndarray] = {
        "cartesianX": np.ascontiguousarray(pts[:, 0]),
        "cartesianY": np.ascontiguousarray(pts[:, 1]),
        "cartesianZ": np.ascontiguousarray(pts[:, 2]),
    }
    if grey is not None:
        data["intensity"] = np.asarray(grey, dtype=np.float64) / 255.0
    e57 = pye57.E57(str(path), mode="w")
    try:
        e57.write_scan_raw(data, name="fpp-rig point cloud (mm)")
    finally:
        e57.close()
    return path


def _nice_step(span: float, ticks: int = 5) -> float:
    raw = span / max(ticks, 1)
    if raw <= 0 or not np.isfinite(raw):
        return 1.0
    magnitude = 10.0 ** np.floor(np.log10(raw))
    for factor in (1.0, 2.0, 2.5, 5.0, 10.0):
        if raw <= factor * magnitude:
            return factor * magnitude
    return 10.0 * magnitude


def colour_map(
    values: np.ndarray, low: float, high: float, invalid_bgr: tuple[int, int, int] = (40, 40, 40)
) -> np.ndarray:
    """BGR uint8 image of ``values`` mapped through the turbo colour map over [low, high]; NaN grey."""
    values = np.asarray(values)
    scale = 255.0 / (high - low) if high > low else 0.0
    work = values.dtype if values.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    levels = values.astype(work)  # a copy, scaled in place
    invalid = ~np.isfinite(levels)
    with np.errstate(over="ignore", invalid="ignore"):  # values far outside [low, high] clip to the ends
        levels -= work.type(low)
        levels *= work.type(scale)
    np.clip(levels, 0, 255, out=levels)
    np.nan_to_num(levels, copy=False, nan=0.0)  # invalid inputs (coloured below), or inf * 0 for an empty range
    image = cv2.applyColorMap(levels.astype(np.uint8), cv2.COLORMAP_TURBO)
    image[invalid] = invalid_bgr
    return image


# Largest magnitude of a colour range end: the span of two such ends is still a finite float.
_RANGE_LIMIT = float(np.finfo(np.float64).max) / 4
_MAX_TICKS = 12


def preview_range(values: np.ndarray) -> tuple[float, float]:
    """Colour range (low < high, both finite, high - low finite and resolvable) of a map's finite values.

    The 1st..99th percentile, so that a few outliers do not flatten the picture; a constant map,
    one without a finite value, or values so large that their span overflows or so close that
    floats cannot tell them apart still give a usable range instead of a division by zero.
    """
    finite = values[np.isfinite(values)]
    if not finite.size:
        return 0.0, 1.0
    low, high = (min(max(float(v), -_RANGE_LIMIT), _RANGE_LIMIT) for v in np.percentile(finite, [1.0, 99.0]))
    magnitude = max(abs(low), abs(high))
    if high - low <= 16 * float(np.spacing(magnitude)):  # constant to within float resolution: widen
        pad = max(0.5, 1e-6 * magnitude)  # half a unit, or enough that ticks and colours can be told apart
        low, high = low - pad, high + pad
    return low, high


def _ticks(low: float, high: float) -> tuple[np.ndarray, str]:
    """Tick values in [low, high] at a round step (at most a dozen) and a format that tells them apart."""
    step = _nice_step(high - low)
    first = np.ceil(low / step)
    count = int(min(np.floor(high / step) - first + 1, _MAX_TICKS)) if np.isfinite(first) else 0
    ticks = np.unique((first + np.arange(max(count, 0))) * step)
    ticks = ticks[np.isfinite(ticks) & (ticks >= low) & (ticks <= high)]
    digits = int(np.clip(np.ceil(np.log10(max(abs(low), abs(high), step) / step)) + 2, 6, 17))  # 6: plain "%g"
    return ticks, f"{{:.{digits}g}}"


def write_preview(path: Path, values: np.ndarray, unit: str, title: str = "") -> tuple[float, float]:
    """Colour-mapped preview of a map with a vertical scale bar labelled in ``unit``.

    The colour range is :func:`preview_range`; any map of finite, infinite or NaN values, also an
    empty one, gives a picture. Returns (low, high) of the colour range.
    """
    values = np.asarray(values)
    if values.dtype not in (np.float32, np.float64):
        values = values.astype(np.float64)
    if values.ndim != 2 or not values.size:
        values = np.full((1, 1), np.nan)
    low, high = preview_range(values)
    image = colour_map(values, low, high)
    rows = image.shape[0]
    panel = np.full((rows, PREVIEW_BAR_PX, 3), 255, dtype=np.uint8)
    top, bottom = 12, max(rows - 12, 13)
    ramp = np.linspace(high, low, bottom - top)[:, None].repeat(18, axis=1)
    panel[top:bottom, 8:26] = colour_map(ramp, low, high)
    font, font_scale = cv2.FONT_HERSHEY_SIMPLEX, 0.35 if rows < 300 else 0.45
    ticks, label_format = _ticks(low, high)
    for tick in ticks:
        y = int(round(top + (high - tick) / (high - low) * (bottom - top - 1)))
        cv2.line(panel, (26, y), (31, y), (0, 0, 0), 1)
        label = label_format.format(tick + 0.0)  # no "-0"
        cv2.putText(panel, label, (34, y + 4), font, font_scale, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(panel, unit, (8, min(rows - 2, bottom + 10)), font, font_scale, (0, 0, 0), 1, cv2.LINE_AA)
    if not np.isfinite(values).all():  # legend entry for the colour of invalid pixels
        grey = tuple(int(v) for v in colour_map(np.full((1, 1), np.nan), low, high)[0, 0])
        y = min(rows - 14, bottom + 14)
        cv2.rectangle(panel, (8, y), (18, y + 8), grey, -1)
        cv2.rectangle(panel, (8, y), (18, y + 8), (0, 0, 0), 1)
        cv2.putText(panel, "invalid", (21, y + 8), font, font_scale * 0.8, (0, 0, 0), 1, cv2.LINE_AA)
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
    write_text_atomic(path, text, durable=False)  # inside a staging directory renamed whole
    return path


# --------------------------------------------------------------------------- arrays of a scene


def texture(state: SceneState, mask: np.ndarray) -> np.ndarray | None:
    """Grey level (N,) of the valid pixels: A + B of the highest frequency, 255 at its 99.5th percentile."""
    wrapped = state.wrapped
    if wrapped is None:
        return None
    bright = wrapped.brightness[-1] if wrapped.brightness else None
    if bright is None:  # the stage-by-stage path keeps A and B apart
        background = wrapped.background[-1] if wrapped.background else None
        modulation = wrapped.modulation[-1] if wrapped.modulation else None
        if background is None or modulation is None:
            return None
        bright = background + modulation
    top = float(np.percentile(bright[::4, ::4], 99.5)) or 1.0  # a display scale: a 1/16 subsample is plenty
    grey = bright[mask]
    grey *= 255.0 / top
    return np.clip(grey, 0, 255, out=grey).astype(np.uint8)


def wrapped_maps(state: SceneState) -> np.ndarray:
    """wrapped.npy: (F, H, W) float64 wrapped phase of each frequency in [-pi, pi)."""
    assert state.wrapped is not None
    maps = [m for m in state.wrapped.phase if m is not None]
    if not maps:
        return np.empty((0, *state.capture.shape))
    wrapped = np.stack(maps).astype(np.float64)
    wrapped[wrapped >= np.pi] -= 2.0 * np.pi  # the fused pass keeps [0, 2 pi)
    return wrapped
