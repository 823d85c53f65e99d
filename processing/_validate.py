"""Argument checks shared by the processing modules.

Each helper normalises one argument and raises ``ValueError`` whose message starts with the
argument's name, so a caller (or the CLI, one level up) can tell exactly what was wrong.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def real_array(value: object, name: str, ndim: int | None = None) -> np.ndarray:
    """``value`` as a real numeric array (any int/float dtype kept), optionally of ``ndim`` dims."""
    arr = np.asarray(value)
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise ValueError(f"{name}: expected a real integer or float array, found dtype {arr.dtype}")
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name}: expected a {ndim}-D array, found shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name}: expected a non-empty array, found shape {arr.shape}")
    return arr


def finite_array(value: object, name: str, ndim: int | None = None) -> np.ndarray:
    """:func:`real_array` with no NaN or infinity anywhere."""
    arr = real_array(value, name, ndim)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}: contains NaN or infinity")
    return arr


def image(value: object, name: str) -> np.ndarray:
    """A 2-D real image (dtype kept)."""
    return real_array(value, name, ndim=2)


def phase_map(
    value: object, name: str, shape: tuple[int, ...] | None = None, refuse_infinity: bool = True
) -> np.ndarray:
    """A 2-D float64 phase map; NaN allowed (invalid pixels), infinities refused.

    ``refuse_infinity=False`` skips that scan for callers whose kernels turn infinities into
    NaN (invalid) anyway: on a megapixel map the scan costs as much as a whole kernel pass.
    """
    arr = image(value, name).astype(np.float64, copy=False)
    if refuse_infinity and np.isinf(arr).any():
        raise ValueError(f"{name}: contains infinity")
    same_shape(arr, shape, name)
    return arr


def same_shape(arr: np.ndarray, shape: tuple[int, ...] | None, name: str) -> None:
    """Refuse ``arr`` unless its shape is ``shape`` (skipped when ``shape`` is None)."""
    if shape is not None and arr.shape != tuple(shape):
        raise ValueError(f"{name}: shape {arr.shape} differs from the expected {tuple(shape)}")


def bool_mask(value: object | None, name: str, shape: tuple[int, ...]) -> np.ndarray | None:
    """An optional boolean mask of ``shape`` (None passes through)."""
    if value is None:
        return None
    arr = np.asarray(value)
    if arr.dtype != np.bool_:
        raise ValueError(f"{name}: expected a boolean array, found dtype {arr.dtype}")
    same_shape(arr, shape, name)
    return arr


def positive_int(value: object, name: str, minimum: int = 1) -> int:
    """An integer >= ``minimum`` (bools and non-integral floats refused)."""
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name}: expected an integer >= {minimum}, found {value!r}")
    try:
        as_int = int(value)  # type: ignore[call-overload]  # anything int() takes; the rest raises below
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected an integer >= {minimum}, found {value!r}") from None
    if as_int != value or as_int < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, found {value!r}")
    return as_int


def frequency_list(values: Sequence[object], name: str, count: int | None = None, minimum_count: int = 1) -> list[int]:
    """Integer fringe frequencies (fringes across the projector), each >= 1."""
    try:
        items = list(values)  # type: ignore[call-overload]
    except TypeError:
        raise ValueError(f"{name}: expected a sequence of integer frequencies, found {values!r}") from None
    if count is not None and len(items) != count:
        raise ValueError(f"{name}: expected {count} frequencies, found {len(items)}")
    if len(items) < minimum_count:
        raise ValueError(f"{name}: expected at least {minimum_count} frequencies, found {len(items)}")
    return [positive_int(f, f"{name}[{i}]") for i, f in enumerate(items)]


def phase_maps(values: Sequence[object], name: str, count: int, refuse_infinity: bool = True) -> list[np.ndarray]:
    """``count`` 2-D float64 phase maps of one shape."""
    try:
        items = list(values)  # type: ignore[call-overload]
    except TypeError:
        raise ValueError(f"{name}: expected a sequence of phase maps") from None
    if isinstance(values, np.ndarray) and values.ndim == 2:
        raise ValueError(f"{name}: expected a sequence of {count} phase maps, found one 2-D array")
    if len(items) != count:
        raise ValueError(f"{name}: expected {count} phase maps (one per frequency), found {len(items)}")
    maps = [phase_map(p, f"{name}[{i}]", refuse_infinity=refuse_infinity) for i, p in enumerate(items)]
    for i, p in enumerate(maps[1:], start=1):
        same_shape(p, maps[0].shape, f"{name}[{i}]")
    return maps


def finite_float(value: object, name: str, minimum: float | None = None, strict: bool = False) -> float:
    """A finite float, optionally > (``strict``) or >= ``minimum``."""
    try:
        as_float = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, found {value!r}") from None
    if not math.isfinite(as_float):
        raise ValueError(f"{name}: expected a finite number, found {value!r}")
    if minimum is not None and (as_float <= minimum if strict else as_float < minimum):
        relation = ">" if strict else ">="
        raise ValueError(f"{name}: expected {relation} {minimum}, found {value!r}")
    return as_float


def finite_pixels(*arrays: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Boolean map of the pixels finite in every one of ``arrays`` (of one shape) and set in ``mask``."""
    keep = np.logical_and.reduce([np.isfinite(a) for a in arrays])
    if mask is not None:
        keep &= np.asarray(mask, dtype=bool)
    return keep
