"""The measuring tools against surfaces of known shape: a gauge block on a tilted plane, a flat with
a known form deviation, a staircase, and a phase map without points (rig.measure).

Each surface is drawn from a seeded family (pixel pitch, tilt, block height and place vary with
the seed); the tolerances are stated next to each check and follow from the noise drawn.
"""

from __future__ import annotations

import csv
import io
from typing import Any

import numpy as np
import pytest

from rig.measure import (
    MeasureError,
    Surface,
    fit_plane,
    height_above_plane,
    histogram,
    line_profile,
    point_distance,
    region_stats,
)

H, W = 120, 160
NOISE_MM = 0.02
SEEDS = (3, 11, 29)


def _pitch_and_points(rng: np.random.Generator, values: np.ndarray) -> tuple[float, np.ndarray]:
    pitch = float(rng.uniform(0.3, 1.2))
    rows, cols = np.mgrid[0:H, 0:W]
    points = np.stack([(cols - W / 2) * pitch, (rows - H / 2) * pitch, values], axis=-1).astype(np.float32)
    points[~np.isfinite(values)] = np.nan
    return pitch, points


def gauge_block(seed: int) -> dict[str, Any]:
    """A block of known height on a level plane, a band of invalid pixels, noise of NOISE_MM."""
    rng = np.random.default_rng(seed)
    block_mm = float(rng.uniform(5.0, 40.0))
    top, left = int(rng.integers(20, 40)), int(rng.integers(20, 60))
    box = (left, top, left + 50, top + 40)  # x0, y0, x1, y1 inclusive
    values = rng.normal(0.0, NOISE_MM, (H, W))
    values[box[1] : box[3] + 1, box[0] : box[2] + 1] += block_mm
    values[:, W - 8 :] = np.nan  # a shadow
    pitch, points = _pitch_and_points(rng, values)
    surface = Surface(values.astype(np.float32), "mm", points)
    return {"surface": surface, "block_mm": block_mm, "box": box, "pitch": pitch}


@pytest.mark.parametrize("seed", SEEDS)
def test_distance_gives_the_step_height_and_the_lateral_distance(seed: int) -> None:
    case = gauge_block(seed)
    x0, y0, x1, y1 = case["box"]
    d = point_distance(case["surface"], (x0 - 5, y0 + 10), (x1 - 3, y1 - 2))
    # rise: block height + the difference of two noise samples (|.| < 6 sigma * sqrt 2)
    assert d.rise == pytest.approx(case["block_mm"], abs=6 * np.sqrt(2) * NOISE_MM)
    expected_lateral = case["pitch"] * np.hypot(x1 - 3 - (x0 - 5), y1 - 2 - (y0 + 10))
    assert d.lateral_distance == pytest.approx(expected_lateral, rel=1e-5)
    assert d.distance_3d == pytest.approx(np.hypot(expected_lateral, case["block_mm"]), abs=0.2)
    rows = list(csv.reader(io.StringIO(d.csv())))
    assert rows[0][:3] == ["point", "col", "row"] and rows[1][1:3] == [str(x0 - 5), str(y0 + 10)]


@pytest.mark.parametrize("seed", SEEDS)
def test_region_statistics_give_the_block_top_and_its_size(seed: int) -> None:
    case = gauge_block(seed)
    x0, y0, x1, y1 = case["box"]
    stats = region_stats(case["surface"], (x1 - 2, y1 - 2, x0 + 2, y0 + 2))  # corners in any order
    n = (x1 - x0 - 3) * (y1 - y0 - 3)
    assert stats.valid == n
    assert stats.mean == pytest.approx(case["block_mm"], abs=5 * NOISE_MM / np.sqrt(n))
    assert stats.std == pytest.approx(NOISE_MM, rel=0.15)
    assert stats.size[0] == pytest.approx((x1 - x0 - 3) * case["pitch"], rel=1e-4)
    whole = region_stats(case["surface"])
    assert whole.valid == H * (W - 8) and whole.figures()["valid_fraction"] == pytest.approx((W - 8) / W)


@pytest.mark.parametrize("seed", SEEDS)
def test_histogram_splits_plane_and_block(seed: int) -> None:
    case = gauge_block(seed)
    x0, y0, x1, y1 = case["box"]
    hist = histogram(case["surface"], bins=20)
    block_pixels = (x1 - x0 + 1) * (y1 - y0 + 1)
    assert hist.counts.sum() == H * (W - 8)
    assert hist.counts[-1] == block_pixels and hist.counts[0] == H * (W - 8) - block_pixels
    assert hist.edges[-1] - hist.edges[0] == pytest.approx(case["block_mm"], abs=10 * NOISE_MM)
    assert list(csv.reader(io.StringIO(hist.csv())))[-1][2] == str(block_pixels)


@pytest.mark.parametrize("seed", SEEDS)
def test_profile_crosses_the_step_where_it_is(seed: int) -> None:
    case = gauge_block(seed)
    x0, y0, x1, y1 = case["box"]
    row = (y0 + y1) // 2
    profile = line_profile(case["surface"], (x0 - 10, row), (x1 + 10, row))
    high = profile.values > case["block_mm"] / 2
    assert profile.cols[high].min() == x0 and profile.cols[high].max() == x1
    assert profile.distance[-1] == pytest.approx((x1 - x0 + 20) * case["pitch"], rel=1e-4)
    assert profile.values.size == x1 - x0 + 21


def tilted_flat(seed: int) -> dict[str, Any]:
    """A tilted plane, exact but for two pixels off it by +a and -b along the height axis."""
    rng = np.random.default_rng(seed)
    slope = rng.uniform(-0.2, 0.2, 2)
    rows, cols = np.mgrid[0:H, 0:W]
    pitch = float(rng.uniform(0.3, 1.2))
    x, y = (cols - W / 2) * pitch, (rows - H / 2) * pitch
    values = 40.0 + slope[0] * x + slope[1] * y
    bump, dip = float(rng.uniform(0.1, 0.5)), float(rng.uniform(0.1, 0.5))
    values[30, 40] += bump
    values[90, 120] -= dip
    points = np.stack([x, y, values], axis=-1)
    cos_tilt = 1.0 / np.sqrt(1.0 + slope @ slope)
    return {"surface": Surface(values, "mm", points), "flatness": (bump + dip) * cos_tilt, "slope": slope}


@pytest.mark.parametrize("seed", SEEDS)
def test_plane_fit_gives_the_flatness_and_tilt_of_a_flat(seed: int) -> None:
    case = tilted_flat(seed)
    plane = fit_plane(case["surface"])
    # the two outliers pull the fit by about their size / (H * W): well under 1e-3 mm
    assert plane.flatness == pytest.approx(case["flatness"], abs=1e-3)
    assert plane.tilt_deg == pytest.approx(np.degrees(np.arctan(np.hypot(*case["slope"]))), abs=1e-3)
    above = height_above_plane(case["surface"], plane)
    assert np.nanmax(above) - np.nanmin(above) == pytest.approx(plane.flatness, abs=1e-6)
    assert np.nanmedian(np.abs(above)) < 1e-4


@pytest.mark.parametrize("seed", SEEDS)
def test_height_above_a_plane_fitted_beside_the_block_is_the_block(seed: int) -> None:
    case = gauge_block(seed)
    x0, y0, x1, y1 = case["box"]
    surface = case["surface"]
    assert surface.points is not None
    tilt = 0.05 * surface.points[..., 0]
    tilted = Surface(
        surface.values + tilt, "mm", np.concatenate([surface.points[..., :2], (surface.values + tilt)[..., None]], -1)
    )
    plane = fit_plane(tilted, (0, 0, W - 1, y0 - 5))  # the band above the block: plane only
    assert plane.flatness < 12 * NOISE_MM  # peak-to-valley of ~2000 normal samples: under 8 sigma
    above = height_above_plane(tilted, plane)
    top = above[y0 + 2 : y1 - 1, x0 + 2 : x1 - 1]
    cos_tilt = 1.0 / np.sqrt(1.0 + 0.05**2)
    assert float(np.median(top)) == pytest.approx(case["block_mm"] * cos_tilt, abs=5 * NOISE_MM)


def test_a_phase_map_without_points_is_measured_in_pixels_with_vertical_residuals() -> None:
    rows, cols = np.mgrid[0:H, 0:W]
    phase = (0.3 * cols + 0.1 * rows).astype(np.float64)
    phase[10, 10] += 1.0
    surface = Surface(phase, "rad")
    plane = fit_plane(surface)
    assert not plane.orthogonal and plane.tilt_deg is None
    assert plane.flatness == pytest.approx(1.0, abs=1e-3)
    d = point_distance(surface, (0, 0), (30, 40))
    assert d.lateral_unit == "px" and d.lateral_distance == pytest.approx(50.0) and d.distance_3d is None
    assert d.rise == pytest.approx(0.3 * 30 + 0.1 * 40)


def test_what_cannot_be_measured_says_so() -> None:
    case = gauge_block(5)
    surface = case["surface"]
    with pytest.raises(MeasureError, match=r"point 2 \(155, 10\): no valid value"):
        point_distance(surface, (10, 10), (155, 10))
    with pytest.raises(MeasureError, match="outside the 160x120 map"):
        point_distance(surface, (10, 10), (500, 10))
    with pytest.raises(MeasureError, match="no valid pixel"):
        region_stats(surface, (W - 5, 0, W - 1, 20))
    with pytest.raises(MeasureError, match="same pixel"):
        line_profile(surface, (3, 3), (3, 3))
    with pytest.raises(MeasureError, match="lie on a line"):
        fit_plane(surface, (10, 10, 50, 10))
    with pytest.raises(MeasureError, match="bins"):
        histogram(surface, bins=0)
