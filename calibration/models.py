"""Heights and points from absolute phase, whatever the calibration's model.

* ``"reference-plane"``: thesis eq. 1.15 on Phi_object - Phi_reference with l0, d0, f0; lateral
  coordinates X = (x - cx) pixel_mm (l0 - h) / l0 (capture-format.md);
* ``"polynomial"``: per-pixel polynomial in Phi_object - Phi_reference
  (:mod:`calibration.polynomial`), lateral coordinates as above when ``l0_mm`` and ``pixel_mm`` are
  present, else ``pixel_mm`` alone;
* ``"stereo"``: camera rays meet projector planes (:mod:`calibration.stereo`); the reference phase
  is not needed; heights above the calibration's ``plane`` if it has one, else depth.

:func:`height_from_phase` and :func:`points_from_phase` are what ``rig process`` calls.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from calibration.errors import CalibrationError
from calibration.polynomial import POLYNOMIAL, load_polynomial
from calibration.stereo import STEREO, StereoModel, triangulate
from calibration.store import REFERENCE_PLANE
from processing.geometry.height import phase_to_height

MODELS = (REFERENCE_PLANE, POLYNOMIAL, STEREO)


class CalibrationLike(Protocol):
    """What this module reads of :class:`calibration.store.Calibration`."""

    model: str
    l0_mm: float | None
    d0_mm: float | None
    pixel_mm: float | None

    def per_mm(self, frequency: float) -> float: ...
    def to_dict(self) -> dict[str, Any]: ...

    @property
    def where(self) -> str: ...


def needs_reference(calibration: CalibrationLike) -> bool:
    """Whether the model subtracts a reference-plane phase."""
    _check_model(calibration)
    return calibration.model != STEREO


def _check_model(calibration: CalibrationLike) -> None:
    if calibration.model not in MODELS:
        raise CalibrationError(
            f"{calibration.where}: model: expected one of {', '.join(MODELS)}, found {calibration.model!r}"
        )


# Shortest plausible lengths in millimetres: a value below is almost surely in metres (or cm).
_MIN_BASELINE_MM = 5.0
_MIN_DISTANCE_MM = 20.0


def units_problem(calibration: CalibrationLike) -> str | None:
    """A sentence naming a length that is implausible in millimetres (likely metres), or None.

    A stereo baseline under 5 mm or a camera-to-plane distance l0 / projector offset d0 under
    20 mm is no FPP rig; such files almost always store metres where millimetres are expected.
    """
    fields = calibration.to_dict()
    if calibration.model == STEREO and "translation_mm" in fields:
        try:
            baseline = float(np.linalg.norm(np.asarray(fields["translation_mm"], dtype=np.float64)))
        except (TypeError, ValueError):
            return None
        if 0 < baseline < _MIN_BASELINE_MM:
            return (
                f"translation_mm: baseline {baseline:.4g} mm is implausibly short for a projector-camera rig; likely "
                f"cause: the translation is in metres; fix: multiply translation_mm by 1000 ({baseline * 1000:.4g} mm)"
            )
    for key in ("l0_mm", "d0_mm"):
        value = fields.get(key)
        if isinstance(value, (int, float)) and 0 < abs(value) < _MIN_DISTANCE_MM:
            return (
                f"{key}: {value:.4g} mm is implausibly short for a rig distance; likely cause: the value is in "
                f"metres; fix: write it in millimetres ({value * 1000:.4g})"
            )
    return None


def _delta(object_phase: np.ndarray, reference_phase: np.ndarray | None, calibration: CalibrationLike) -> np.ndarray:
    if reference_phase is None:
        raise CalibrationError(f"{calibration.where}: model {calibration.model!r} needs the reference-plane phase")
    obj, ref = np.asarray(object_phase), np.asarray(reference_phase)
    if obj.shape != ref.shape:
        raise CalibrationError(f"reference phase: shape {ref.shape} differs from the object's {obj.shape}")
    if obj.dtype == ref.dtype == np.float32:
        return obj - ref  # the fused pass's phases: float32 keeps 1e-5 rad at 2 pi 64, far below their noise
    return obj.astype(np.float64, copy=False) - ref.astype(np.float64, copy=False)


def stereo_model(calibration: CalibrationLike) -> StereoModel:
    """The stereo model held in a ``"stereo"`` calibration's fields."""
    return StereoModel.from_fields(calibration.to_dict(), where=calibration.where)


def height_from_phase(
    calibration: CalibrationLike,
    object_phase: np.ndarray,
    reference_phase: np.ndarray | None,
    frequency: float,
    axis: str = "x",
    extent: float | None = None,
) -> np.ndarray:
    """Height map (H, W) in mm from the object's absolute phase at ``frequency`` (NaN where invalid).

    Parameters
    ----------
    calibration : Calibration
        Any model of :data:`MODELS`.
    object_phase, reference_phase : (H, W) arrays
        Absolute phases 2 pi f u / W (NaN invalid); the reference is ignored by ``stereo``.
    frequency : float
        Fringes across the projector of the phases.
    axis, extent :
        Fringe axis and pattern extent in projector pixels (``stereo`` only; default the
        calibrated projector size along the axis).
    """
    _check_model(calibration)
    if calibration.model == REFERENCE_PLANE:
        delta = _delta(object_phase, reference_phase, calibration)
        assert calibration.l0_mm is not None and calibration.d0_mm is not None  # checked when read
        with np.errstate(invalid="ignore", divide="ignore"):
            return phase_to_height(  # _delta's array is our own: heights written into it
                delta,
                calibration.l0_mm,
                calibration.d0_mm,
                calibration.per_mm(frequency),
                dtype=delta.dtype.type,
                in_place=True,
            )
    if calibration.model == POLYNOMIAL:
        polynomial = load_polynomial(calibration.to_dict(), getattr(calibration, "path", None), calibration.where)
        return polynomial.height(_delta(object_phase, reference_phase, calibration), frequency)
    stereo = stereo_model(calibration)
    return stereo.heights(triangulate(stereo, object_phase, frequency, axis=axis, extent=extent))


def points_from_phase(
    calibration: CalibrationLike,
    object_phase: np.ndarray,
    reference_phase: np.ndarray | None,
    frequency: float,
    axis: str = "x",
    extent: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Points (H, W, 3) in mm and the height map (H, W); NaN where invalid.

    Stereo points are in the camera frame; the others are X, Y on the reference plane (origin at
    the image centre) and Z = height.
    """
    _check_model(calibration)
    if calibration.model == STEREO:
        model = stereo_model(calibration)
        points = triangulate(model, object_phase, frequency, axis=axis, extent=extent)
        return points, model.heights(points)
    height = height_from_phase(calibration, object_phase, reference_phase, frequency)
    points = plane_points(calibration, height).reshape(*height.shape, 3)
    return np.where(np.isfinite(height)[..., None], points, np.nan), height


def plane_points_finite(
    calibration: CalibrationLike, height: np.ndarray, finite: np.ndarray | None = None
) -> np.ndarray:
    """Where :func:`plane_points` of ``height`` is finite in float32: the height and both lateral coordinates.

    ``finite``: ``np.isfinite(height)`` of float32 heights when the caller has it already (it
    is returned, possibly narrowed in place, instead of a new mask).
    """
    h = np.asarray(height)
    limit = float(np.finfo(np.float32).max)
    if finite is None or h.dtype != np.float32:  # a finite float32 is within the float32 range
        finite = np.isfinite(h) & (np.abs(h) <= limit)
    bound = lateral_bound(calibration, h.shape)
    if bound is None:
        return finite
    if bound == 0.0:
        return np.zeros_like(finite)
    assert calibration.l0_mm  # lateral_bound gives a finite bound only with l0
    with np.errstate(over="ignore", invalid="ignore"):
        finite &= np.abs(calibration.l0_mm - h.astype(np.float64)) < bound
    return finite


def lateral_bound(calibration: CalibrationLike, shape: tuple[int, ...]) -> float | None:
    """The bound on ``|l0 - h|`` under which :func:`plane_points`' lateral coordinates of an (H, W) map stay
    finite in float32; None where every finite float32 height qualifies (any real rig), 0 where none does.

    |X| <= reach |l0 - h| / l0 with ``reach`` the largest |x - cx| pixel_mm.
    """
    pixel = calibration.pixel_mm
    if pixel is None:
        raise CalibrationError(f"{calibration.where}: pixel_mm: missing (needed for lateral point coordinates)")
    reach = max(shape[1] - 1, shape[0] - 1) / 2.0 * abs(pixel)
    limit = float(np.finfo(np.float32).max)
    if not calibration.l0_mm:
        return None if reach < limit else 0.0
    bound = limit / (reach / abs(calibration.l0_mm)) if reach > 0 else np.inf
    return None if bound >= 2.0 * limit else bound


def plane_points(calibration: CalibrationLike, height: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Points (N, 3) in mm of a reference-plane or polynomial model's height map.

    X = (x - cx) pixel_mm (l0 - h) / l0, the same for Y (pixel_mm alone without l0), Z = h, with
    (cx, cy) the image centre; for the pixels of ``mask`` in C order (default every pixel), so
    that no (H, W, 3) array is built for the points a caller keeps. The dtype is the height's
    (float32 stays float32).
    """
    pixel = calibration.pixel_mm
    if pixel is None:
        raise CalibrationError(f"{calibration.where}: pixel_mm: missing (needed for lateral point coordinates)")
    h = np.asarray(height)
    dtype = h.dtype if h.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    h = h.astype(dtype, copy=False)
    rows, cols = h.shape
    if calibration.l0_mm:
        scale = (dtype.type(calibration.l0_mm) - h) * dtype.type(pixel / calibration.l0_mm)
    else:
        scale = np.full(h.shape, pixel, dtype=dtype)
    xs = np.arange(cols, dtype=dtype) - dtype.type((cols - 1) / 2.0)
    ys = np.arange(rows, dtype=dtype) - dtype.type((rows - 1) / 2.0)
    keep = None if mask is None else np.asarray(mask, dtype=bool)

    def kept(values: np.ndarray) -> np.ndarray:
        return values.reshape(-1) if keep is None else values[keep]

    # Whole-image products, then the kept pixels: cheaper than gathering pixel indices first.
    points = np.empty((h.size if keep is None else int(np.count_nonzero(keep)), 3), dtype=dtype)
    points[:, 0] = kept(scale * xs[None, :])
    points[:, 1] = kept(scale * ys[:, None])
    points[:, 2] = kept(h)
    return points
