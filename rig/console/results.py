"""A processing result as the page shows it: colour-mapped map, raw values for the hover read-out,
a down-sampled surface for the 3-D view, the report's key figures, and differences of two results.

Built from an in-memory :class:`rig.pipeline.result.ProcessResult` right after a scan (so the result
is on screen before its files are written) or from a result directory read back through the result
store (:func:`rig.store.results.read_result`: regular files inside the directory only).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from rig.errors import RigError
from rig.store import results as store
from rig.store.result_files import colour_map

SURFACE_MAX_SIDE = 160  # samples along the longer side of the 3-D surface
CLOUD_MAX_POINTS = 1 << 18  # points sent for the 3-D view (every pixel up to 512x512, else a regular subset)
# the exposure map's colours, shortest exposure first (distinct for colour-blind readers: Okabe-Ito)
EXPOSURE_COLOURS = ("#0072b2", "#e69f00", "#009e73", "#cc79a7", "#56b4e9", "#d55e00", "#f0e442", "#000000")
PHASE_RELIEF = 0.25  # a phase map's drawn relief, as a fraction of its width (rad and pixels do not compare)


@dataclass
class ResultView:
    """One result's arrays and figures; ``values`` are heights in mm (or phase in rad without a calibration)."""

    name: str
    values: np.ndarray  # (H, W) float32, NaN where invalid
    unit: str  # "mm" or "rad"
    shows: str  # "height" or "phase"
    points: np.ndarray | None  # (H, W, 3) mm, NaN where invalid
    report: dict[str, Any]
    saved: bool = False
    exposure: np.ndarray | None = None  # (H, W) us, NaN where invalid: a capture at several exposures
    _png: bytes | None = field(default=None, repr=False)

    @classmethod
    def from_result(cls, name: str, result: Any) -> ResultView:
        """From a :class:`rig.pipeline.result.ProcessResult` (in memory)."""
        if result.height is not None:
            values, unit, shows = result.height, "mm", "height"
        else:
            values, unit, shows = np.where(result.mask, result.phase, np.nan), "rad", "phase"
        exposure = result.object.exposure_map
        if exposure is not None:
            exposure = np.where(result.mask, exposure, np.float32(np.nan)).astype(np.float32)
        return cls(
            name, np.asarray(values, dtype=np.float32), unit, shows, result.points, result.report, exposure=exposure
        )

    @classmethod
    def from_directory(cls, name: str, path: Path) -> ResultView:
        """From a result directory (report.json, height.npy or phase.npy, mask.npy, points.ply), read
        through the result store: a FIFO, a device or a link out of the directory is refused, not followed."""
        stored = store.read_result(path, where=f"results/{name}")
        return cls(name, stored.values, stored.unit, stored.shows, stored.points, stored.report, True, stored.exposure)

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.values.shape[0]), int(self.values.shape[1]))

    def value_range(self) -> tuple[float, float]:
        """Colour-scale range of the map and the 3-D view: the lowest and highest valid value (what the
        report's figures say), widened where they are equal."""
        return full_range(self.values)

    def png(self) -> bytes:
        """The colour-mapped map (turbo, invalid grey) as PNG."""
        if self._png is None:
            low, high = self.value_range()
            self._png = encode_png(colour_map(self.values, low, high))
        return self._png

    def exposures(self) -> list[dict[str, Any]]:
        """The exposure map's legend: each exposure (us), its share of the valid pixels and its colour."""
        if self.exposure is None:
            return []
        values = self.exposure[np.isfinite(self.exposure)]
        times, counts = np.unique(values, return_counts=True)
        total = max(int(values.size), 1)
        return [
            {
                "exposure_us": float(t),
                "share": round(int(c) / total, 4),
                "colour": EXPOSURE_COLOURS[i % len(EXPOSURE_COLOURS)],
            }
            for i, (t, c) in enumerate(zip(times, counts))
        ]

    def exposure_png(self) -> bytes:
        """The exposure map as PNG: one colour per exposure (the legend's), invalid pixels grey."""
        if self.exposure is None:
            raise RigError(f"results/{self.name}: not a capture at several exposures (no exposure map)")
        image = np.full((*self.shape, 3), 128, dtype=np.uint8)
        for entry in self.exposures():
            rgb = [int(entry["colour"][i : i + 2], 16) for i in (1, 3, 5)]
            image[self.exposure == np.float32(entry["exposure_us"])] = rgb[::-1]  # OpenCV writes BGR
        return encode_png(image)

    def surface(self, max_side: int = SURFACE_MAX_SIDE) -> dict[str, Any]:
        """Down-sampled grid for a 3-D surface: x, y (mm, or pixels without points), z; None where invalid."""
        h, w = self.shape
        step = max(1, int(np.ceil(max(h, w) / max_side)))
        z = self.values[::step, ::step]
        if self.points is not None and self.shows == "height":
            x, y = self.points[::step, ::step, 0], self.points[::step, ::step, 1]
            axis_unit = "mm"
        else:
            rows, cols = np.mgrid[0:h:step, 0:w:step]
            x, y, axis_unit = cols.astype(np.float32), rows.astype(np.float32), "px"
        valid = np.isfinite(z) & np.isfinite(x) & np.isfinite(y)
        return {
            "x": _nullable(x, valid),
            "y": _nullable(y, valid),
            "z": _nullable(z, valid),
            "unit": self.unit,
            "axis_unit": axis_unit,
            "step": step,
        }

    def cloud(self, max_points: int = CLOUD_MAX_POINTS) -> tuple[bytes, dict[str, str]]:
        """The valid pixels as a point cloud for a WebGL view, and its description (HTTP headers).

        Bytes: N float32 (x, y, z) triples, then N RGBA uint8 colours from the same colour map and
        range as :meth:`png`. x, y, z in mm with points; without them (a phase map) pixel columns and
        rows with the phase scaled to a relief of :data:`PHASE_RELIEF` of the width, so that the view
        is not edge-on. Every pixel up to ``max_points`` valid ones, else every ``step``-th row and column.
        """
        h, w = self.shape
        valid_all = np.isfinite(self.values)
        step = max(1, int(np.ceil(np.sqrt(np.count_nonzero(valid_all) / max_points))))
        values = self.values[::step, ::step]
        low, high = self.value_range()
        if self.points is not None and self.shows == "height":
            xyz = self.points[::step, ::step].astype(np.float32)
            axis_unit, z_scale = "mm", 1.0
        else:
            rows, cols = np.mgrid[0:h:step, 0:w:step].astype(np.float32)
            z_scale = PHASE_RELIEF * w / (high - low)
            xyz = np.stack([cols, rows, (values - np.float32(low)) * np.float32(z_scale)], axis=-1)
            axis_unit = "px"
        valid = np.isfinite(values) & np.isfinite(xyz).all(axis=-1)
        rgb = colour_map(values[valid][:, None], low, high).reshape(-1, 3)[:, ::-1]  # OpenCV's BGR to RGB
        rgba = np.concatenate([rgb, np.full((len(rgb), 1), 255, np.uint8)], axis=1)
        positions = np.ascontiguousarray(xyz[valid], dtype="<f4")
        headers = {
            "X-Points": str(len(positions)),
            "X-Step": str(step),
            "X-Range": f"{low},{high}",
            "X-Unit": self.unit,
            "X-Axis-Unit": axis_unit,
            "X-Z-Scale": str(z_scale),
        }
        return positions.tobytes() + np.ascontiguousarray(rgba).tobytes(), headers

    def summary(self) -> dict[str, Any]:
        """Key figures of the report, for the page and the API."""
        report = self.report
        low, high = self.value_range()
        return {
            "name": self.name,
            "shows": self.shows,
            "unit": self.unit,
            "width": self.shape[1],
            "height": self.shape[0],
            "range": [low, high],
            "valid_fraction": report.get("valid_fraction"),
            "height_mm": report.get("height_mm"),
            "methods": report.get("methods", {}),
            "timings_s": report.get("timings_s", {}),
            "capture": report.get("capture"),
            "calibration": report.get("calibration"),
            "notes": report.get("notes", []),
            "saved": self.saved,
            "exposures": self.exposures(),
        }


def full_range(values: np.ndarray) -> tuple[float, float]:
    """Lowest and highest finite value ((0, 1) when there are none; widened by 0.5 when equal)."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return 0.0, 1.0
    low, high = float(finite.min()), float(finite.max())
    return (low, high) if high > low else (low - 0.5, high + 0.5)


def encode_png(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise RigError("could not encode an image as PNG")
    return data.tobytes()


def _nullable(values: np.ndarray, valid: np.ndarray) -> list[list[float | None]]:
    rounded = np.round(values.astype(np.float64), 3)
    return [[float(v) if ok else None for v, ok in zip(row, ok_row)] for row, ok_row in zip(rounded, valid)]


def difference(a: ResultView, b: ResultView) -> tuple[np.ndarray, dict[str, Any]]:
    """``a - b`` where both are valid (NaN elsewhere) and its figures; the two must be the same size and unit."""
    if a.shape != b.shape:
        raise RigError(
            f"compare: {a.name} is {a.shape[1]}x{a.shape[0]}, {b.name} is {b.shape[1]}x{b.shape[0]}; expected the same size"
        )
    if a.unit != b.unit:
        raise RigError(
            f"compare: {a.name} shows {a.shows} ({a.unit}), {b.name} shows {b.shows} ({b.unit}); expected the same"
        )
    diff = a.values - b.values
    both = np.isfinite(diff)
    bound = symmetric_bound(diff)
    figures: dict[str, Any] = {
        "a": a.name,
        "b": b.name,
        "unit": a.unit,
        "valid_fraction": float(both.mean()),
        "scale": [-bound, bound],  # the difference map's colour range
    }
    if both.any():
        d = diff[both].astype(np.float64)
        figures.update(mean=float(d.mean()), rms=float(np.sqrt(np.mean(d**2))), max_abs=float(np.max(np.abs(d))))
    return diff, figures


def symmetric_bound(diff: np.ndarray) -> float:
    """The difference map's colour scale is -bound .. +bound: the 99.5th percentile of |diff| (1 when none)."""
    finite = np.abs(diff[np.isfinite(diff)])
    bound = float(np.percentile(finite, 99.5)) if finite.size else 1.0
    return bound if bound > 0 else 1.0


def difference_png(diff: np.ndarray) -> tuple[bytes, float]:
    """The difference map on its symmetric colour scale (:func:`symmetric_bound`) and that bound."""
    bound = symmetric_bound(diff)
    return encode_png(colour_map(diff, -bound, bound)), bound


def colour_bar_png(height: int = 256, width: int = 16) -> bytes:
    """The colour scale of the maps (turbo), top = high, as PNG."""
    ramp = np.linspace(1.0, 0.0, height, dtype=np.float32)[:, None].repeat(width, axis=1)
    return encode_png(colour_map(ramp, 0.0, 1.0))
