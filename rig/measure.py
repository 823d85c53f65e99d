"""Measuring on a result map: line profile, point-to-point distance, plane fit (flatness and the
height above the plane), height histogram and the statistics of a region of interest.

Every tool works on a :class:`Surface`: the result's map (heights in mm, or phase in rad without a
calibration), NaN where invalid, and its 3-D points when it has them. Positions are pixels of the
map (column ``x``, row ``y``), as the page picks them. Lateral sizes are in mm when the result has
points (from the points themselves, or for a profile's distance axis from the map's least-squares
pixel-to-mm mapping), else in pixels; each figure says its unit. A tool that cannot decide (a point
off the surface, a region without valid pixels, too few points for a plane) raises
:class:`MeasureError` with one line instead of guessing. Each figure set renders itself as CSV.

All of it is whole-array numpy: no loop over pixels.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rig.errors import RigError

MIN_PLANE_POINTS = 3
FIT_SAMPLES = 20000  # valid pixels used for the pixel-to-mm mapping (evenly strided)


class MeasureError(RigError):
    """A measurement cannot be made where asked (off the map, no valid pixel, too few points)."""


@dataclass(frozen=True)
class Surface:
    """A result map to measure on: ``values`` (H, W) NaN where invalid, in ``unit``; ``points``
    (H, W, 3) in mm or None (a phase result, or one without a calibration)."""

    values: np.ndarray
    unit: str
    points: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.values.ndim != 2:
            raise MeasureError(f"map: expected a 2-D array, found shape {self.values.shape}")
        if self.points is not None and self.points.shape != (*self.values.shape, 3):
            raise MeasureError(f"points: expected shape {(*self.values.shape, 3)}, found {self.points.shape}")

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.values.shape[0]), int(self.values.shape[1]))

    @property
    def lateral_unit(self) -> str:
        """mm when the result has 3-D points, else px."""
        return "mm" if self.points is not None else "px"

    def lateral_at(self, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """(N, 2) lateral positions of pixels: the points' x, y (NaN where invalid), or the pixel itself."""
        if self.points is None:
            return np.stack([cols, rows], axis=-1).astype(np.float64)
        return self.points[rows, cols, :2].astype(np.float64)

    def pixel_to_lateral(self) -> np.ndarray:
        """The 2x3 affine map ``[x, y] = A @ [col, row, 1]`` fitted to the valid points (identity in px).

        Fitted on an even sub-grid of about :data:`FIT_SAMPLES` pixels (the map is smooth in x, y).
        """
        if self.points is None:
            return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        h, w = self.shape
        step = max(1, int(np.sqrt(h * w / FIT_SAMPLES)))
        xy = self.points[::step, ::step, :2].astype(np.float64)
        rows, cols = np.mgrid[0:h:step, 0:w:step]
        valid = np.isfinite(xy).all(axis=-1) & np.isfinite(self.values[::step, ::step])
        if int(valid.sum()) < MIN_PLANE_POINTS:
            raise MeasureError("map: fewer than 3 valid points; no pixel size can be derived")
        design = np.stack([cols[valid], rows[valid], np.ones(int(valid.sum()))], axis=1).astype(np.float64)
        solution, *_ = np.linalg.lstsq(design, xy[valid], rcond=None)
        return np.asarray(solution.T)


@dataclass(frozen=True)
class Region:
    """A rectangle of map pixels, both corners included: columns ``x0..x1``, rows ``y0..y1``."""

    x0: int
    y0: int
    x1: int
    y1: int

    @classmethod
    def of(cls, surface: Surface, corners: Sequence[float] | None) -> Region:
        """The rectangle spanned by two corners (any order), clipped to the map; the whole map for None."""
        h, w = surface.shape
        if corners is None:
            return cls(0, 0, w - 1, h - 1)
        x0, y0, x1, y1 = (int(round(float(c))) for c in corners)
        left, right, top, bottom = min(x0, x1), max(x0, x1), min(y0, y1), max(y0, y1)
        if right < 0 or bottom < 0 or left > w - 1 or top > h - 1:
            raise MeasureError(
                f"region: ({left}, {top})..({right}, {bottom}) lies outside the {w}x{h} map; draw it on the map"
            )
        return cls(max(left, 0), max(top, 0), min(right, w - 1), min(bottom, h - 1))

    @property
    def slices(self) -> tuple[slice, slice]:
        return slice(self.y0, self.y1 + 1), slice(self.x0, self.x1 + 1)

    @property
    def pixels(self) -> int:
        return (self.x1 - self.x0 + 1) * (self.y1 - self.y0 + 1)

    def as_list(self) -> list[int]:
        return [self.x0, self.y0, self.x1, self.y1]


def _pixel(surface: Surface, x: float, y: float, what: str) -> tuple[int, int]:
    h, w = surface.shape
    col, row = int(round(float(x))), int(round(float(y)))
    if not (0 <= col < w and 0 <= row < h):
        raise MeasureError(f"{what} ({col}, {row}): outside the {w}x{h} map; pick a pixel on the map")
    return col, row


def _csv(rows: Iterable[Sequence[Any]]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    for row in rows:
        writer.writerow(["" if isinstance(v, float) and not np.isfinite(v) else v for v in row])
    return out.getvalue()


def _num(value: float) -> float | None:
    """A JSON-ready float (None for NaN)."""
    return float(value) if np.isfinite(value) else None


# --------------------------------------------------------------------------- line profile


@dataclass(frozen=True)
class Profile:
    """Values along a straight line, one sample per pixel step (nearest pixel)."""

    cols: np.ndarray
    rows: np.ndarray
    distance: np.ndarray  # along the line from its start, in lateral_unit
    lateral: np.ndarray  # (N, 2) x, y of each sample (NaN where invalid)
    values: np.ndarray
    unit: str
    lateral_unit: str

    def figures(self) -> dict[str, Any]:
        valid = np.isfinite(self.values)
        finite = self.values[valid]
        return {
            "tool": "profile",
            "unit": self.unit,
            "lateral_unit": self.lateral_unit,
            "samples": int(self.values.size),
            "valid": int(valid.sum()),
            "length": float(self.distance[-1]),
            "min": _num(finite.min()) if finite.size else None,
            "max": _num(finite.max()) if finite.size else None,
            "mean": _num(finite.mean()) if finite.size else None,
            "col": self.cols.tolist(),
            "row": self.rows.tolist(),
            "distance": [round(float(d), 4) for d in self.distance],
            "value": [_num(round(float(v), 4)) for v in self.values],
        }

    def csv(self) -> str:
        header = ["col", "row", f"distance_{self.lateral_unit}", f"x_{self.lateral_unit}", f"y_{self.lateral_unit}"]
        return _csv(
            [
                [*header, f"value_{self.unit}"],
                *zip(
                    self.cols.tolist(),
                    self.rows.tolist(),
                    self.distance.tolist(),
                    self.lateral[:, 0].tolist(),
                    self.lateral[:, 1].tolist(),
                    self.values.astype(np.float64).tolist(),
                ),
            ]
        )


def line_profile(surface: Surface, start: tuple[float, float], end: tuple[float, float]) -> Profile:
    """The map along the line ``start`` -> ``end`` (pixels), sampled at every pixel step.

    The distance axis is the pixel length scaled by the map's fitted pixel-to-mm mapping in the
    line's direction (so invalid samples still have a position along it).
    """
    c0, r0 = _pixel(surface, *start, what="profile start")
    c1, r1 = _pixel(surface, *end, what="profile end")
    steps = max(abs(c1 - c0), abs(r1 - r0))
    if steps == 0:
        raise MeasureError("profile: start and end are the same pixel; draw a line")
    t = np.linspace(0.0, 1.0, steps + 1)
    cols = np.rint(c0 + t * (c1 - c0)).astype(np.intp)
    rows = np.rint(r0 + t * (r1 - r0)).astype(np.intp)
    along = surface.pixel_to_lateral()[:, :2] @ np.array([c1 - c0, r1 - r0], dtype=np.float64)
    distance = t * float(np.hypot(*along))
    return Profile(
        cols,
        rows,
        distance,
        surface.lateral_at(cols, rows),
        surface.values[rows, cols].astype(np.float64),
        surface.unit,
        surface.lateral_unit,
    )


# --------------------------------------------------------------------------- point to point


@dataclass(frozen=True)
class Distance:
    """Two points on the surface and the distances between them."""

    cols: tuple[int, int]
    rows: tuple[int, int]
    lateral: np.ndarray  # (2, 2)
    values: tuple[float, float]
    unit: str
    lateral_unit: str

    @property
    def lateral_distance(self) -> float:
        return float(np.hypot(*(self.lateral[1] - self.lateral[0])))

    @property
    def rise(self) -> float:
        """Second value minus first (a step height when the points lie on either side of it)."""
        return self.values[1] - self.values[0]

    @property
    def distance_3d(self) -> float | None:
        """Euclidean distance in mm, when the lateral positions and the values are both in mm."""
        if self.lateral_unit != self.unit:
            return None
        return float(np.hypot(self.lateral_distance, self.rise))

    def figures(self) -> dict[str, Any]:
        return {
            "tool": "distance",
            "unit": self.unit,
            "lateral_unit": self.lateral_unit,
            "points": [
                {"col": c, "row": r, "x": float(xy[0]), "y": float(xy[1]), "value": v}
                for c, r, xy, v in zip(self.cols, self.rows, self.lateral, self.values)
            ],
            "lateral_distance": self.lateral_distance,
            "rise": self.rise,
            "distance_3d": self.distance_3d,
        }

    def csv(self) -> str:
        lu = self.lateral_unit
        rows: list[list[Any]] = [["point", "col", "row", f"x_{lu}", f"y_{lu}", f"value_{self.unit}"]]
        for i in range(2):
            rows.append([i + 1, self.cols[i], self.rows[i], *self.lateral[i].tolist(), self.values[i]])
        rows += [
            [],
            ["figure", "value", "unit"],
            ["lateral_distance", self.lateral_distance, lu],
            ["rise", self.rise, self.unit],
        ]
        if self.distance_3d is not None:
            rows.append(["distance_3d", self.distance_3d, self.unit])
        return _csv(rows)


def point_distance(surface: Surface, first: tuple[float, float], second: tuple[float, float]) -> Distance:
    """Distances between two pixels of the surface; both must hold a valid value."""
    picked = [_pixel(surface, *first, what="point 1"), _pixel(surface, *second, what="point 2")]
    cols = np.array([p[0] for p in picked])
    rows = np.array([p[1] for p in picked])
    values = surface.values[rows, cols].astype(np.float64)
    lateral = surface.lateral_at(cols, rows)
    for i, (c, r) in enumerate(picked):
        if not (np.isfinite(values[i]) and np.isfinite(lateral[i]).all()):
            raise MeasureError(f"point {i + 1} ({c}, {r}): no valid value there; pick a pixel on the surface")
    return Distance(
        (picked[0][0], picked[1][0]),
        (picked[0][1], picked[1][1]),
        lateral,
        (float(values[0]), float(values[1])),
        surface.unit,
        surface.lateral_unit,
    )


# --------------------------------------------------------------------------- plane fit


@dataclass(frozen=True)
class PlaneFit:
    """A plane fitted to the valid pixels of a region and the spread of the surface about it.

    ``orthogonal``: distances are measured along the plane's normal (lateral and height units
    agree, mm); otherwise (a phase map over pixels) they are vertical residuals of ``z = a x + b y + c``.
    """

    region: Region
    centroid: np.ndarray  # (3,) lateral x, y and value
    normal: np.ndarray  # (3,) unit, pointing to higher values
    orthogonal: bool
    residuals: np.ndarray  # signed distances of the fitted points
    unit: str
    lateral_unit: str

    @property
    def flatness(self) -> float:
        """Peak-to-valley of the distances to the plane (the form deviation of a flat)."""
        return float(self.residuals.max() - self.residuals.min())

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.residuals**2)))

    @property
    def tilt_deg(self) -> float | None:
        """Angle between the plane's normal and the height axis (only when units agree)."""
        if not self.orthogonal:
            return None
        return float(np.degrees(np.arccos(min(1.0, abs(float(self.normal[2]))))))

    def distance_of(self, x: np.ndarray, y: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Signed distance of points (lateral ``x``, ``y`` and ``values``, same shape) to the plane, above positive."""
        cx, cy, cz = (float(c) for c in self.centroid)
        nx, ny, nz = (float(c) for c in self.normal)
        if self.orthogonal:
            return np.asarray((x - cx) * nx + (y - cy) * ny + (values - cz) * nz)
        return np.asarray((values - cz) + ((x - cx) * nx + (y - cy) * ny) / nz)

    def figures(self) -> dict[str, Any]:
        return {
            "tool": "plane",
            "unit": self.unit,
            "lateral_unit": self.lateral_unit,
            "region": self.region.as_list(),
            "points": int(self.residuals.size),
            "flatness": self.flatness,
            "rms": self.rms,
            "tilt_deg": self.tilt_deg,
            "orthogonal": self.orthogonal,
            "normal": self.normal.tolist(),
            "centroid": self.centroid.tolist(),
        }

    def csv(self) -> str:
        lu = self.lateral_unit
        return _csv(
            [
                ["figure", "value", "unit"],
                ["region_x0_y0_x1_y1", " ".join(map(str, self.region.as_list())), "px"],
                ["points", self.residuals.size, ""],
                ["flatness", self.flatness, self.unit],
                ["rms", self.rms, self.unit],
                ["tilt", "" if self.tilt_deg is None else self.tilt_deg, "deg"],
                ["distances", "orthogonal" if self.orthogonal else "vertical", ""],
                ["normal_x", self.normal[0], ""],
                ["normal_y", self.normal[1], ""],
                ["normal_z", self.normal[2], ""],
                ["centroid_x", self.centroid[0], lu],
                ["centroid_y", self.centroid[1], lu],
                ["centroid_value", self.centroid[2], self.unit],
            ]
        )


def fit_plane(surface: Surface, corners: Sequence[float] | None = None) -> PlaneFit:
    """Least-squares plane through the valid pixels of the region (the whole map for None).

    The fit is the smallest eigenvector of the points' 3x3 scatter matrix (orthogonal), or the
    normal equations of ``z = a x + b y + c`` (vertical): one pass over the points either way.
    """
    region = Region.of(surface, corners)
    lateral = _lateral_block(surface, region)
    values = surface.values[region.slices].astype(np.float64)
    valid = np.isfinite(values) & np.isfinite(lateral).all(axis=-1)
    count = int(valid.sum())
    if count < MIN_PLANE_POINTS:
        raise MeasureError(
            f"plane: {count} valid pixels in the region {region.as_list()}; expected at least "
            f"{MIN_PLANE_POINTS} (draw the region on the surface)"
        )
    coords = [lateral[..., 0][valid], lateral[..., 1][valid], values[valid]]
    centroid = np.array([c.mean() for c in coords])
    centred = [c - m for c, m in zip(coords, centroid)]
    scatter = np.array([[float(np.dot(a, b)) for b in centred] for a in centred])
    spread = np.linalg.eigvalsh(scatter[:2, :2])
    if spread[0] <= 1e-12 * max(float(spread[1]), 1e-300):
        raise MeasureError(
            f"plane: the valid pixels of the region {region.as_list()} lie on a line; draw a wider region"
        )
    orthogonal = surface.lateral_unit == surface.unit
    if orthogonal:
        normal = np.linalg.eigh(scatter)[1][:, 0]
    else:
        slope = np.linalg.solve(scatter[:2, :2], scatter[:2, 2])
        normal = np.array([-slope[0], -slope[1], 1.0])
    normal = normal / np.linalg.norm(normal)
    if normal[2] < 0:
        normal = -normal
    fit = PlaneFit(region, centroid, normal, orthogonal, np.empty(0), surface.unit, surface.lateral_unit)
    residuals = fit.distance_of(*coords)
    return PlaneFit(region, centroid, normal, orthogonal, residuals, surface.unit, surface.lateral_unit)


def _lateral_block(surface: Surface, region: Region) -> np.ndarray:
    """(h, w, 2) lateral positions of a region's pixels (the points' x, y, or the pixels themselves)."""
    if surface.points is not None:
        return surface.points[region.slices][..., :2].astype(np.float64)
    rows, cols = np.mgrid[region.slices]
    return np.stack([cols, rows], axis=-1).astype(np.float64)


def height_above_plane(surface: Surface, plane: PlaneFit) -> np.ndarray:
    """(H, W) signed distance of every valid pixel to ``plane`` (NaN where invalid)."""
    h, w = surface.shape
    lateral = _lateral_block(surface, Region(0, 0, w - 1, h - 1))
    return plane.distance_of(lateral[..., 0], lateral[..., 1], surface.values.astype(np.float64)).astype(np.float32)


# --------------------------------------------------------------------------- region statistics


@dataclass(frozen=True)
class RegionStats:
    """Statistics of the valid values in a region."""

    region: Region
    valid: int
    mean: float
    std: float
    minimum: float
    maximum: float
    median: float
    size: tuple[float, float]  # lateral width and height of the region
    unit: str
    lateral_unit: str

    def figures(self) -> dict[str, Any]:
        return {
            "tool": "roi",
            "unit": self.unit,
            "lateral_unit": self.lateral_unit,
            "region": self.region.as_list(),
            "pixels": self.region.pixels,
            "valid": self.valid,
            "valid_fraction": self.valid / self.region.pixels,
            "mean": self.mean,
            "std": self.std,
            "min": self.minimum,
            "max": self.maximum,
            "median": self.median,
            "peak_to_valley": self.maximum - self.minimum,
            "width": self.size[0],
            "height": self.size[1],
        }

    def csv(self) -> str:
        unit_of = {"pixels": "", "valid": "", "valid_fraction": "", "width": self.lateral_unit}
        unit_of["height"] = self.lateral_unit
        rows: list[list[Any]] = [["figure", "value", "unit"]]
        for key, value in self.figures().items():
            if key in ("tool", "unit", "lateral_unit"):
                continue
            shown = " ".join(map(str, value)) if isinstance(value, list) else value
            rows.append([key, shown, "px" if key == "region" else unit_of.get(key, self.unit)])
        return _csv(rows)


def _region_values(surface: Surface, corners: Sequence[float] | None) -> tuple[Region, np.ndarray]:
    region = Region.of(surface, corners)
    values = surface.values[region.slices].astype(np.float64).ravel()
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        raise MeasureError(f"region {region.as_list()}: no valid pixel in it; draw it on the surface")
    return region, finite


def region_stats(surface: Surface, corners: Sequence[float] | None = None) -> RegionStats:
    """Count, mean, spread, extremes and median of the valid values of a region (the whole map for None)."""
    region, finite = _region_values(surface, corners)
    scale = surface.pixel_to_lateral()[:, :2]
    width = float(np.hypot(*(scale @ np.array([region.x1 - region.x0 + 1, 0.0]))))
    height = float(np.hypot(*(scale @ np.array([0.0, region.y1 - region.y0 + 1]))))
    return RegionStats(
        region,
        int(finite.size),
        float(finite.mean()),
        float(finite.std()),
        float(finite.min()),
        float(finite.max()),
        float(np.median(finite)),
        (width, height),
        surface.unit,
        surface.lateral_unit,
    )


# --------------------------------------------------------------------------- histogram


@dataclass(frozen=True)
class Histogram:
    """How many valid pixels of a region fall in each of equal-width bins of value."""

    region: Region
    edges: np.ndarray  # (bins + 1,)
    counts: np.ndarray  # (bins,)
    unit: str

    def figures(self) -> dict[str, Any]:
        total = int(self.counts.sum())
        peak = int(np.argmax(self.counts))
        return {
            "tool": "histogram",
            "unit": self.unit,
            "region": self.region.as_list(),
            "valid": total,
            "bins": int(self.counts.size),
            "edges": self.edges.tolist(),
            "counts": self.counts.tolist(),
            "mode": float((self.edges[peak] + self.edges[peak + 1]) / 2),
        }

    def csv(self) -> str:
        return _csv(
            [
                [f"low_{self.unit}", f"high_{self.unit}", "count"],
                *zip(self.edges[:-1].tolist(), self.edges[1:].tolist(), self.counts.tolist()),
            ]
        )


def histogram(
    surface: Surface,
    corners: Sequence[float] | None = None,
    bins: int = 64,
    value_range: tuple[float, float] | None = None,
) -> Histogram:
    """Histogram of the valid values of a region (whole map for None) over ``value_range`` (default: their extent)."""
    if not 1 <= bins <= 4096:
        raise MeasureError(f"bins: expected 1 to 4096, found {bins}")
    region, finite = _region_values(surface, corners)
    low, high = value_range if value_range is not None else (float(finite.min()), float(finite.max()))
    if not (np.isfinite(low) and np.isfinite(high)) or high < low:
        raise MeasureError(f"histogram range: expected low <= high, found {low}..{high}")
    if high == low:
        low, high = low - 0.5, high + 0.5
    counts, edges = np.histogram(finite, bins=bins, range=(low, high))
    return Histogram(region, edges, counts, surface.unit)
