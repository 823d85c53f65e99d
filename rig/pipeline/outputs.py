"""Files `rig process` writes: height/phase/mask arrays, a binary PLY, report.json, preview.png."""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from rig import __version__
from rig.errors import OutputError
from rig.store import files as safe_files

if TYPE_CHECKING:
    from rig.pipeline.run import ProcessResult
    from rig.pipeline.stages import SceneState

log = logging.getLogger(__name__)


PREVIEW_BAR_PX = 90  # width of the scale bar panel at the right of the preview


def write_array(path: Path, array: np.ndarray) -> Path:
    """Save an array as .npy."""
    np.save(path, array)
    return path


def write_ply(path: Path, points: np.ndarray, colors: np.ndarray | None = None) -> Path:
    """Binary little-endian PLY of (N, 3) points in mm (float32), optional (N, 3) uint8 colours (or (N,) grey)."""
    pts = np.asarray(points).reshape(-1, 3)
    fields: list[tuple[str, str, tuple[int, ...]]] = [("xyz", "<f4", (3,))]
    header = [
        "ply",
        "format binary_little_endian 1.0",
        "comment fpp-rig point cloud, units mm",
        f"element vertex {len(pts)}",
        "property float x",
        "property float y",
        "property float z",
    ]
    if colors is not None:
        fields.append(("rgb", "u1", (3,)))
        header += ["property uchar red", "property uchar green", "property uchar blue"]
    header.append("end_header")
    record = np.empty(len(pts), dtype=fields)  # packed: 12 (or 15) bytes per vertex, as the header says
    record["xyz"] = pts
    if colors is not None:
        rgb = np.asarray(colors, dtype=np.uint8)
        record["rgb"] = rgb[:, None] if rgb.ndim == 1 else rgb.reshape(-1, 3)
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
    tmp = Path(f"{path}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path


# --------------------------------------------------------------------------- outputs


def _texture(state: SceneState, mask: np.ndarray) -> np.ndarray | None:
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


def _wrapped_maps(state: SceneState) -> np.ndarray:
    """wrapped.npy: (F, H, W) float64 wrapped phase of each frequency in [-pi, pi)."""
    assert state.wrapped is not None
    maps = [m for m in state.wrapped.phase if m is not None]
    if not maps:
        return np.empty((0, *state.capture.shape))
    wrapped = np.stack(maps).astype(np.float64)
    wrapped[wrapped >= np.pi] -= 2.0 * np.pi  # the fused pass keeps [0, 2 pi)
    return wrapped


OUTPUT_FILES = ("height.npy", "phase.npy", "mask.npy", "wrapped.npy", "points.ply", "report.json", "preview.png")


def build_report(result: ProcessResult, staged_inputs: tuple[Path, Path] | None = None) -> dict[str, Any]:
    """The report of a processing run (report.json without its ``files`` and output timing).

    ``staged_inputs`` (staging, final): the inputs were written into a staging directory that is
    committed as ``final`` (``rig demo``); the report names them where they will be.
    """
    obj = result.object
    assert obj.unwrapped is not None and obj.wrapped is not None

    def where(path: Path | None) -> str | None:
        if path is None:
            return None
        return str(safe_files.committed_path(path, *staged_inputs) if staged_inputs else path)

    report: dict[str, Any] = {
        "program": f"fpp-rig {__version__}",
        "capture": where(obj.capture.path),
        "calibration": where(result.calibration.path if result.calibration is not None else None),
        "reference": where(result.reference.capture.path if result.reference is not None else None),
        "methods": {
            "wrapped_phase": "phase-shifting" if obj.groups.sinusoids else "single-shot",
            "unwrap": obj.unwrapped.method,
            "unwrap_requested": result.options.unwrap,
            "absolute_phase": obj.unwrapped.absolute,
            "denoise": result.options.denoise,
            "correction": result.options.correction,
            "undistorted": bool(obj.info.get("undistorted", False)),
            "fringe_axis": obj.axis,
            "frequencies": obj.wrapped.frequencies,
            "phase_frequency": obj.unwrapped.frequency,
            "min_modulation_ratio": result.options.min_modulation_ratio,
            "min_island_fraction": result.options.min_island_fraction,
            "params": result.options.params,
        },
        "image": {"width": obj.capture.width, "height": obj.capture.height},
        "valid_fraction": float(result.mask.mean()),
        "notes": list(result.notes),
    }
    if "unresolved" in obj.info.get("correction", {}):  # share of the valid pixels whose orders nothing settled
        report["unresolved_fraction"] = obj.info["correction"]["unresolved"]["fraction"]
    if result.height is None:
        report["wrapped_frequencies"] = obj.wrapped.frequencies
    else:
        assert result.calibration is not None
        valid_h = result.height[result.mask]
        valid_h = valid_h[np.isfinite(valid_h)]  # report.json is strict JSON: no NaN or Infinity
        report["height_mm"] = (
            {
                "min": float(np.min(valid_h)),
                "max": float(np.max(valid_h)),
                "median": float(np.median(valid_h)),
            }
            if valid_h.size
            else None
        )
        report["points"] = int(np.count_nonzero(result.mask))
        report["calibration_model"] = result.calibration.model
        # stereo without a plane gives distance from the camera, not height above a plane
        depth = result.calibration.model == "stereo" and result.calibration.to_dict().get("plane") is None
        report["quantity"] = "depth" if depth else "height"
    report["timings_s"] = dict(result.timings)
    report["stage_info"] = {"object": obj.info, **({"reference": result.reference.info} if result.reference else {})}
    report["versions"] = _versions()
    return report


def check_output_directory(out_dir: str | Path) -> None:
    """Before computing: ``out_dir`` can be written and is new, empty or an earlier output (OutputError if not)."""
    safe_files.check_writable(Path(out_dir), OUTPUT_KINDS, True, OutputError)


def write_outputs(
    result: ProcessResult,
    out_dir: str | Path,
    extra: Mapping[str, Any] | None = None,
    staged_inputs: tuple[Path, Path] | None = None,
) -> dict[str, Any]:
    """Write the outputs of capture-format.md as the directory ``out_dir``; returns the report (also in report.json).

    The files are written into a fresh temporary sibling and renamed into place, replacing an
    earlier output of this program (never anything else): after any interruption ``out_dir``
    holds the complete old or the complete new result. ``extra`` keys are added to report.json
    (``rig batch`` records its input fingerprint there, committed with the rest). ``staged_inputs``:
    see :func:`build_report`.
    """
    t0 = time.perf_counter()
    with safe_files.staged_directory(Path(out_dir), OUTPUT_KINDS, True, OutputError) as staging:
        report = _write_files(result, staging, t0, extra or {}, staged_inputs)
    return report


OUTPUT_KINDS = ("output",)


def _write_files(
    result: ProcessResult, out: Path, t0: float, extra: Mapping[str, Any], staged_inputs: tuple[Path, Path] | None
) -> dict[str, Any]:
    obj = result.object
    assert obj.unwrapped is not None and obj.wrapped is not None
    report = build_report(result, staged_inputs)
    files: dict[str, str] = {}
    phase = obj.unwrapped.phase.astype(np.float64)  # a copy: NaN outside the mask
    np.copyto(phase, np.nan, where=~result.mask)
    # The preview (colour map and PNG encoding, which release the GIL) is drawn on a thread while
    # the arrays and the point cloud are written.
    with ThreadPoolExecutor(1) as pool:
        if result.height is None:
            preview = pool.submit(
                write_preview,
                out / "preview.png",
                phase,
                "rad",
                "absolute phase" if obj.unwrapped.absolute else "phase",
            )
            shows, unit = "phase", "rad"
        else:
            shows, unit = report["quantity"], "mm"
            preview = pool.submit(write_preview, out / "preview.png", result.height, unit, shows)
        files["phase"] = write_array(out / "phase.npy", phase).name
        files["mask"] = write_array(out / "mask.npy", np.asarray(result.mask, dtype=bool)).name
        if result.height is None:
            files["wrapped"] = write_array(out / "wrapped.npy", _wrapped_maps(obj)).name
        else:
            files["height"] = write_array(out / "height.npy", np.asarray(result.height, dtype=np.float32)).name
            files["points"] = write_ply(out / "points.ply", result.valid_points(), _texture(obj, result.mask)).name
        low, high = preview.result()
    report["preview"] = {"shows": shows, "unit": unit, "range": [low, high]}
    files["preview"] = "preview.png"
    files["report"] = "report.json"
    report["files"] = files
    report["timings_s"]["outputs"] = time.perf_counter() - t0
    report.update(extra)
    write_report(out / "report.json", report)
    return report


def _versions() -> dict[str, str]:
    import platform

    import cv2
    import scipy

    return {
        "fpp-rig": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "opencv": cv2.__version__,
    }
