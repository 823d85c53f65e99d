"""The thesis' speckle-embedded single-shot pattern (ch. 2.3): I = A + B cos(2 pi f0 x) + C Z(x, y).

``Z`` is a binary pseudo-random speckle field built on a grid of dots of ``dot_px`` x ``dot_px``
projector pixels, following the three rules of the thesis (after its ref. [104]):

1. every white speckle is one whole dot of ``dot_px`` x ``dot_px`` pixels;
2. every cell of 3 x 3 dots holds exactly one white dot;
3. no two white dots touch, not even diagonally (8-neighbourhood on the dot grid).

So about 1/9 (11.1 %) of the pixels are white, and a patch of a few cells around a pixel is
(with high probability) unique along a row, which the single-shot unwrapping uses to find the
fringe order.

Generation is vectorised: the cells are visited in four interleaved classes (cell row and column
parity); cells of one class are two cells apart and cannot conflict, so each class draws its dot
at once among the positions that do not touch dots already placed. The centre of a cell touches
nothing outside its own cell, so every cell always has a legal position.

The pattern that embeds the field in a sinusoid, ``speckle-sinusoid``, is defined with the other
pattern kinds in :mod:`processing.projection.patterns`, which uses this module (not the other way round).
"""

from __future__ import annotations

import functools

import numpy as np

CELL_DOTS = 3  # a cell is 3 x 3 dots holding one white dot
DEFAULT_DOT_PX = 3
DEFAULT_SPECKLE_GAIN = 0.3
DEFAULT_SEED = 0


def _check_size(name: str, value: int) -> int:
    if isinstance(value, bool) or int(value) != value or int(value) < 1:
        raise ValueError(f"{name}: expected a positive integer, found {value!r}")
    return int(value)


def speckle_dots(cells_y: int, cells_x: int, seed: int) -> np.ndarray:
    """Binary dot grid (3 cells_y, 3 cells_x) with one white dot per 3x3 cell, none 8-adjacent.

    Parameters
    ----------
    cells_y, cells_x : int
        Number of 3x3-dot cells down and across.
    seed : int
        Seed of the generator; the same seed gives the same grid.

    Returns
    -------
    (3 cells_y, 3 cells_x) bool array of white dots.
    """
    cells_y = _check_size("cells_y", cells_y)
    cells_x = _check_size("cells_x", cells_x)
    rng = np.random.default_rng(seed)
    dots = np.zeros((CELL_DOTS * cells_y, CELL_DOTS * cells_x), dtype=bool)
    # Random priorities for the 9 positions of every cell, drawn once so the result depends on the seed only.
    keys = rng.random((cells_y, cells_x, CELL_DOTS * CELL_DOTS))
    offsets = np.array([(i, j) for i in range(CELL_DOTS) for j in range(CELL_DOTS)])
    padded = np.zeros((dots.shape[0] + 2, dots.shape[1] + 2), dtype=bool)
    for parity_y in (0, 1):
        for parity_x in (0, 1):
            cy = np.arange(parity_y, cells_y, 2)
            cx = np.arange(parity_x, cells_x, 2)
            if cy.size == 0 or cx.size == 0:
                continue
            # touched[y, x]: some white dot already placed lies in the 3x3 neighbourhood of dot (y, x).
            padded[1:-1, 1:-1] = dots
            touched = np.zeros_like(dots)
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    touched |= padded[1 + dy : 1 + dy + dots.shape[0], 1 + dx : 1 + dx + dots.shape[1]]
            ys = CELL_DOTS * cy[:, None, None] + offsets[None, None, :, 0]
            xs = CELL_DOTS * cx[None, :, None] + offsets[None, None, :, 1]
            allowed = ~touched[ys, xs]  # (len(cy), len(cx), 9)
            score = np.where(allowed, keys[np.ix_(cy, cx)], -1.0)
            choice = np.argmax(score, axis=2)
            dots[CELL_DOTS * cy[:, None] + offsets[choice, 0], CELL_DOTS * cx[None, :] + offsets[choice, 1]] = True
    return dots


@functools.lru_cache(maxsize=8)
def cached_speckle_field(width: int, height: int, seed: int, dot_px: int) -> np.ndarray:
    """Read-only :func:`speckle_field` (arguments already checked), cached for repeated frames."""
    cell_px = CELL_DOTS * dot_px
    cells_y = -(-height // cell_px)
    cells_x = -(-width // cell_px)
    dots = speckle_dots(cells_y, cells_x, seed)
    field = np.repeat(np.repeat(dots, dot_px, axis=0), dot_px, axis=1)[:height, :width]
    field = field.astype(np.float64)
    field.setflags(write=False)
    return field


def speckle_field(width: int, height: int, seed: int, dot_px: int = DEFAULT_DOT_PX) -> np.ndarray:
    """Seeded binary speckle field Z of ``height`` x ``width`` pixels (values 0 and 1).

    Parameters
    ----------
    width, height : int
        Size in pixels (projector pixels when it is projected).
    seed : int
        Generator seed; equal seeds give equal fields.
    dot_px : int
        Side of one speckle dot in pixels (thesis: 3).

    Returns
    -------
    (height, width) float64 array of 0 and 1; the grid of dots starts at pixel (0, 0) and the
    last row/column of cells is cut where the size is not a multiple of 3 dot_px.
    """
    width = _check_size("width", width)
    height = _check_size("height", height)
    dot_px = _check_size("dot_px", dot_px)
    if isinstance(seed, bool) or int(seed) != seed:
        raise ValueError(f"seed: expected an integer, found {seed!r}")
    return cached_speckle_field(width, height, int(seed), dot_px).copy()


def check_speckle_rules(field: np.ndarray, dot_px: int = DEFAULT_DOT_PX) -> list[str]:
    """Violations of the thesis' three speckle rules in a field; empty when it follows them.

    Checks that the values are 0/1, that every whole dot block is uniform (rule 1), that every
    whole 3x3-dot cell has exactly one white dot (rule 2) and that no two white dots are
    8-adjacent (rule 3). Blocks and cells cut by the field's border are checked as far as they
    go: a cut cell may hold no white dot, never more than one.
    """
    z = np.asarray(field)
    if z.ndim != 2:
        raise ValueError(f"field: expected a 2-D array, found shape {z.shape}")
    dot_px = _check_size("dot_px", dot_px)
    problems: list[str] = []
    if not np.all((z == 0) | (z == 1)):
        problems.append("values: expected only 0 and 1")
        return problems
    rows, cols = z.shape
    ny, nx = -(-rows // dot_px), -(-cols // dot_px)
    # Pad to whole dots with -1 (ignored) so blocks can be reshaped.
    padded = np.full((ny * dot_px, nx * dot_px), -1.0)
    padded[:rows, :cols] = z
    blocks = padded.reshape(ny, dot_px, nx, dot_px).transpose(0, 2, 1, 3).reshape(ny, nx, -1)
    present = blocks >= 0
    white_px = np.sum((blocks == 1), axis=2)
    dark_px = np.sum((blocks == 0), axis=2)
    mixed = (white_px > 0) & (dark_px > 0)
    if mixed.any():
        y, x = np.argwhere(mixed)[0]
        problems.append(f"rule 1: {int(mixed.sum())} dot blocks are partly white, first at dot ({y}, {x})")
    dots = (white_px > 0) & present.any(axis=2)
    cy, cx = -(-ny // CELL_DOTS), -(-nx // CELL_DOTS)
    grid = np.zeros((cy * CELL_DOTS, cx * CELL_DOTS), dtype=np.int64)
    grid[:ny, :nx] = dots
    per_cell = grid.reshape(cy, CELL_DOTS, cx, CELL_DOTS).sum(axis=(1, 3))
    whole_y = ny // CELL_DOTS if rows % dot_px == 0 else (ny - 1) // CELL_DOTS
    whole_x = nx // CELL_DOTS if cols % dot_px == 0 else (nx - 1) // CELL_DOTS
    whole = np.zeros_like(per_cell, dtype=bool)
    whole[:whole_y, :whole_x] = True
    bad = (per_cell > 1) | (whole & (per_cell != 1))
    if bad.any():
        y, x = np.argwhere(bad)[0]
        problems.append(
            f"rule 2: {int(bad.sum())} cells of 3x3 dots do not hold exactly one white dot, "
            f"first cell ({y}, {x}) holds {int(per_cell[y, x])}"
        )
    padded_dots = np.pad(dots, 1)
    touching = np.zeros_like(dots)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                touching |= dots & padded_dots[1 + dy : 1 + dy + ny, 1 + dx : 1 + dx + nx]
    if touching.any():
        y, x = np.argwhere(touching)[0]
        problems.append(f"rule 3: {int(touching.sum())} white dots touch another white dot, first at dot ({y}, {x})")
    return problems
