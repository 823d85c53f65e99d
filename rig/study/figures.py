"""Figures of the reproduction study drawn with OpenCV: colour maps, tiled panels, line plots.

OpenCV is already a dependency; these few primitives (axes, ticks, polylines, a legend) cover
the study's plots without adding a plotting library.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

FONT = cv2.FONT_HERSHEY_SIMPLEX
WHITE = (255, 255, 255)
BLACK = (0, 0, 0)
GREY = (200, 200, 200)
# Distinguishable BGR colours for plot series.
PALETTE = [
    (40, 40, 40),
    (31, 119, 180)[::-1],
    (255, 127, 14)[::-1],
    (44, 160, 44)[::-1],
    (214, 39, 40)[::-1],
    (148, 103, 189)[::-1],
    (140, 86, 75)[::-1],
    (227, 119, 194)[::-1],
    (23, 190, 207)[::-1],
]


def colorize(
    values: np.ndarray,
    lo: float | None = None,
    hi: float | None = None,
    colormap: int = cv2.COLORMAP_JET,
    size: int | None = 240,
) -> np.ndarray:
    """BGR image of a 2-D map scaled from ``lo`` to ``hi`` (default the finite range); NaN black."""
    arr = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(arr)
    if lo is None:
        lo = float(np.min(arr[finite])) if finite.any() else 0.0
    if hi is None:
        hi = float(np.max(arr[finite])) if finite.any() else 1.0
    scale = 255.0 / (hi - lo) if hi > lo else 0.0
    grey = np.clip((np.where(finite, arr, lo) - lo) * scale, 0, 255).astype(np.uint8)
    image = cv2.applyColorMap(grey, colormap)
    image[~finite] = 0
    return _fit(image, size)


def grey_image(values: np.ndarray, size: int | None = 240) -> np.ndarray:
    """BGR rendering of an intensity image stretched to its 1st..99th percentiles."""
    arr = np.asarray(values, dtype=np.float64)
    lo, hi = np.percentile(arr, [1, 99])
    grey = np.clip((arr - lo) * (255.0 / max(hi - lo, 1e-12)), 0, 255).astype(np.uint8)
    return _fit(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR), size)


def _fit(image: np.ndarray, size: int | None) -> np.ndarray:
    if size is None:
        return image
    rows, cols = image.shape[:2]
    scale = size / max(rows, cols)
    if scale >= 1.0:
        return cv2.resize(image, (round(cols * scale), round(rows * scale)), interpolation=cv2.INTER_NEAREST)
    return cv2.resize(image, (round(cols * scale), round(rows * scale)), interpolation=cv2.INTER_AREA)


def panel(tiles: Sequence[tuple[str, np.ndarray]], columns: int, title: str | None = None) -> np.ndarray:
    """Grid of equally sized BGR tiles, each with its caption above it."""
    if not tiles:
        raise ValueError("tiles: expected at least one image")
    tile_h = max(t.shape[0] for _, t in tiles)
    tile_w = max(t.shape[1] for _, t in tiles)
    caption = 24
    rows = math.ceil(len(tiles) / columns)
    top = 30 if title else 0
    canvas = np.full((top + rows * (tile_h + caption) + 4, columns * (tile_w + 4) + 4, 3), 255, np.uint8)
    if title:
        cv2.putText(canvas, title, (6, 21), FONT, 0.6, BLACK, 1, cv2.LINE_AA)
    for i, (text, tile) in enumerate(tiles):
        r, c = divmod(i, columns)
        y = top + r * (tile_h + caption)
        x = 4 + c * (tile_w + 4)
        cv2.putText(canvas, text, (x + 2, y + 17), FONT, 0.45, BLACK, 1, cv2.LINE_AA)
        canvas[y + caption : y + caption + tile.shape[0], x : x + tile.shape[1]] = tile
    return canvas


def _nice_ticks(lo: float, hi: float, count: int = 5) -> list[float]:
    if not hi > lo:
        return [lo]
    raw = (hi - lo) / count
    magnitude = 10 ** math.floor(math.log10(raw))
    step = min((m * magnitude for m in (1, 2, 2.5, 5, 10) if m * magnitude >= raw), default=raw)
    start = math.ceil(lo / step) * step
    ticks = []
    value = start
    while value <= hi + 1e-9 * step:
        ticks.append(round(value, 12))
        value += step
    return ticks


def _format(value: float, log: bool) -> str:
    if log:
        return f"1e{int(round(value))}"
    if value == 0:
        return "0"
    if abs(value) >= 1e5 or abs(value) < 0.01:
        return f"{value:.0e}"
    return f"{value:g}"


def line_plot(  # noqa: C901  the study report: one section after another
    series: Sequence[tuple[str, Sequence[float] | np.ndarray, Sequence[float] | np.ndarray]],
    title: str,
    xlabel: str,
    ylabel: str,
    logx: bool = False,
    logy: bool = False,
    ylim: tuple[float, float] | None = None,
    size: tuple[int, int] = (760, 460),
    markers: bool = True,
) -> np.ndarray:
    """A line plot of several (label, x, y) series; non-finite and (on log axes) non-positive points are skipped."""
    width, height = size
    left, right, top, bottom = 78, 170, 48, 50
    canvas = np.full((height, width, 3), 255, np.uint8)
    cleaned = []
    for label, xs, ys in series:
        x = np.asarray(xs, dtype=np.float64)
        y = np.asarray(ys, dtype=np.float64)
        keep = np.isfinite(x) & np.isfinite(y)
        if logx:
            keep &= x > 0
        if logy:
            keep &= y > 0
        x = np.log10(x[keep]) if logx else x[keep]
        y = np.log10(y[keep]) if logy else y[keep]
        cleaned.append((label, x, y))
    all_x = np.concatenate([c[1] for c in cleaned]) if cleaned else np.array([0.0, 1.0])
    all_y = np.concatenate([c[2] for c in cleaned]) if cleaned else np.array([0.0, 1.0])
    if all_x.size == 0:
        all_x = np.array([0.0, 1.0])
    if all_y.size == 0:
        all_y = np.array([0.0, 1.0])
    x_lo, x_hi = float(all_x.min()), float(all_x.max())
    if ylim is not None:
        y_lo, y_hi = (math.log10(ylim[0]), math.log10(ylim[1])) if logy else ylim
    else:
        y_lo, y_hi = float(all_y.min()), float(all_y.max())
    if logy:
        y_lo, y_hi = math.floor(y_lo), math.ceil(y_hi)
    if x_hi == x_lo:
        x_lo, x_hi = x_lo - 1, x_hi + 1
    if y_hi == y_lo:
        y_lo, y_hi = y_lo - 1, y_hi + 1
    pad = 0.04 * (x_hi - x_lo)
    x_lo, x_hi = x_lo - pad, x_hi + pad
    if not logy:
        pad = 0.05 * (y_hi - y_lo)
        y_lo, y_hi = y_lo - pad, y_hi + pad
    plot_w, plot_h = width - left - right, height - top - bottom

    def px(x: float, y: float) -> tuple[int, int]:
        return (
            int(round(left + (x - x_lo) / (x_hi - x_lo) * plot_w)),
            int(round(top + (1 - (y - y_lo) / (y_hi - y_lo)) * plot_h)),
        )

    cv2.rectangle(canvas, (left, top), (left + plot_w, top + plot_h), BLACK, 1)
    yticks = [float(v) for v in range(int(y_lo), int(y_hi) + 1)] if logy else _nice_ticks(y_lo, y_hi)
    xticks = [float(v) for v in range(math.ceil(x_lo), math.floor(x_hi) + 1)] if logx else _nice_ticks(x_lo, x_hi)
    for v in yticks:
        if y_lo <= v <= y_hi:
            p = px(x_lo, v)
            cv2.line(canvas, (left, p[1]), (left + plot_w, p[1]), GREY, 1)
            text = _format(v, logy)
            cv2.putText(canvas, text, (left - 8 - 8 * len(text), p[1] + 4), FONT, 0.4, BLACK, 1, cv2.LINE_AA)
    for v in xticks:
        if x_lo <= v <= x_hi:
            p = px(v, y_lo)
            cv2.line(canvas, (p[0], top), (p[0], top + plot_h), GREY, 1)
            text = _format(v, logx)
            cv2.putText(canvas, text, (p[0] - 4 * len(text), top + plot_h + 16), FONT, 0.4, BLACK, 1, cv2.LINE_AA)
    cv2.rectangle(canvas, (left, top), (left + plot_w, top + plot_h), BLACK, 1)
    cv2.putText(canvas, title, (left, 20), FONT, 0.55, BLACK, 1, cv2.LINE_AA)
    cv2.putText(canvas, xlabel, (left + plot_w // 2 - 4 * len(xlabel), height - 12), FONT, 0.45, BLACK, 1, cv2.LINE_AA)
    cv2.putText(canvas, ylabel, (6, top - 10), FONT, 0.42, BLACK, 1, cv2.LINE_AA)
    clip = (left, top, plot_w + 1, plot_h + 1)
    for i, (label, x, y) in enumerate(cleaned):
        colour = PALETTE[i % len(PALETTE)]
        points = [px(a, np.clip(b, y_lo, y_hi)) for a, b in zip(x, y)]
        if len(points) > 1:
            cv2.polylines(canvas, [np.array(points, np.int32)], False, colour, 2, cv2.LINE_AA)
        if markers and len(points) <= 60:
            for p in points:
                if cv2.clipLine(clip, p, p)[0]:
                    cv2.circle(canvas, p, 3, colour, -1, cv2.LINE_AA)
        ly = top + 14 + 20 * i
        cv2.line(canvas, (width - right + 10, ly - 4), (width - right + 34, ly - 4), colour, 2)
        cv2.putText(canvas, label[:18], (width - right + 40, ly), FONT, 0.42, BLACK, 1, cv2.LINE_AA)
    return canvas


def save_png(path, image: np.ndarray) -> None:
    """Write a PNG, raising OSError with the path if OpenCV cannot."""
    if not cv2.imwrite(str(path), image, [cv2.IMWRITE_PNG_COMPRESSION, 6]):
        raise OSError(f"{path}: could not write the PNG")
