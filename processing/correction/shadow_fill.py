"""Fill shadowed (invalid) pixels from their neighbours before matrix methods such as RPCA.

RPCA needs a complete matrix; the thesis fills projector shadows by interpolation first (chs. 3
and 4). Phase and fringe-order maps vary mainly along the fringe axis (rows), so the default is
linear interpolation along each row between the nearest valid pixels on either side, constant
beyond the ends of a row; rows without any valid pixel take the nearest valid pixel in 2-D.
"""

from __future__ import annotations

import numpy as np

from processing import _validate

FILL_METHODS = ("linear", "nearest")


def valid_mask(image: np.ndarray, mask: np.ndarray | None, name: str = "image") -> np.ndarray:
    """The pixels to trust: ``mask`` (True = valid) and finite; NaN inside the mask is refused.

    Raises
    ------
    ValueError
        ``mask`` of the wrong shape or dtype, NaN at a pixel the mask calls valid, or no valid pixel.
    """
    finite = np.isfinite(image)
    checked = _validate.bool_mask(mask, "mask", image.shape)
    if checked is None:
        valid = finite
    else:
        if np.any(checked & ~finite):
            raise ValueError(
                f"{name}: NaN or infinity at {int(np.count_nonzero(checked & ~finite))} pixels the mask marks valid"
            )
        valid = checked
    if not valid.any():
        raise ValueError("mask: no valid pixel (the whole map is shadow)")
    return valid


def fill_shadows(image: np.ndarray, mask: np.ndarray | None = None, method: str = "linear") -> np.ndarray:
    """Replace the invalid pixels of a map by values interpolated from valid neighbours.

    Parameters
    ----------
    image : (H, W) array
        Map to fill; values at invalid pixels are ignored (may be NaN).
    mask : (H, W) bool array, optional
        True where ``image`` is valid; default: its finite pixels.
    method : {"linear", "nearest"}
        "linear": along each row between the nearest valid pixels left and right (constant past
        the ends); "nearest": the nearest valid pixel in 2-D (Euclidean distance transform).

    Returns
    -------
    (H, W) float64 array, equal to ``image`` at the valid pixels and finite everywhere.
    """
    arr = _validate.image(image, "image").astype(np.float64)
    if np.isinf(arr).any() and mask is None:
        raise ValueError("image: contains infinity")
    if method not in FILL_METHODS:
        raise ValueError(f"method: expected one of {', '.join(FILL_METHODS)}, found {method!r}")
    valid = valid_mask(arr, mask)
    if valid.all():
        return arr
    if method == "nearest":
        return _nearest_fill(arr, valid)
    # The 2-D nearest fill is only needed for rows without any valid pixel (a distance transform
    # of the whole map otherwise costs more than the interpolation itself).
    empty_rows = ~valid.any(axis=1)
    fallback = _nearest_fill(arr, valid) if empty_rows.any() else arr
    return _row_linear_fill(arr, valid, fallback)


def _nearest_fill(arr: np.ndarray, valid: np.ndarray) -> np.ndarray:
    from scipy import ndimage  # lazily: most maps have a valid pixel in every row

    indices = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    return arr[tuple(indices)]


def _row_linear_fill(arr: np.ndarray, valid: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    rows, cols = arr.shape
    col = np.broadcast_to(np.arange(cols), arr.shape)
    # Index of the last valid pixel at or left of each pixel (-1: none), and first at or right (cols: none).
    left = np.maximum.accumulate(np.where(valid, col, -1), axis=1)
    right = np.minimum.accumulate(np.where(valid, col, cols)[:, ::-1], axis=1)[:, ::-1]
    has_left, has_right = left >= 0, right < cols
    row_index = np.arange(rows)[:, None]
    left_value = arr[row_index, np.clip(left, 0, cols - 1)]
    right_value = arr[row_index, np.clip(right, 0, cols - 1)]
    span = np.maximum(right - left, 1)
    weight = (col - left) / span
    out = np.where(has_left & has_right, left_value + weight * (right_value - left_value), 0.0)
    out = np.where(has_left & ~has_right, left_value, out)
    out = np.where(~has_left & has_right, right_value, out)
    out = np.where(~has_left & ~has_right, fallback, out)
    return np.where(valid, arr, out)
