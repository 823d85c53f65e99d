"""One processing run: a capture (and its calibration's reference plane) through the stages to heights."""

from __future__ import annotations

import contextlib
import functools
import logging
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration import models as calibration_models
from calibration.errors import CalibrationError
from calibration.plane_axes import for_axis
from calibration.stereo import STEREO
from calibration.store import REFERENCE_PLANE, Calibration, read_calibration
from processing import concurrency
from processing.concurrency import side_by_side
from processing.geometry.axis_fusion import FusedPoints, fuse_points
from processing.geometry.plane_model import PlaneHeights, plane_heights
from processing.geometry.uncertainty import combined_phase_sigma, height_ahead, height_sigma
from rig.blas import rpca_blas
from rig.errors import ProcessingError
from rig.pipeline import reference_cache
from rig.pipeline.axes import (
    AXES,
    AxisChoice,
    captured_axes,
    choose_axes,
    conditioning_note,
    plane_conditioning,
    plane_sensitivities,
    stereo_conditioning,
)
from rig.pipeline.corrections import REGISTRY as CORRECTIONS
from rig.pipeline.fit import check_fit, refuse_kept_distortion
from rig.pipeline.plan import (
    PatternGroups,
    ProcessOptions,
    group_patterns,
)
from rig.pipeline.result import ProcessResult
from rig.pipeline.stages import (
    DENOISERS,
    SCENE_STAGES,
    SceneState,
    stage_height,
)
from rig.pipeline.unwrapping import UNWRAP_METHODS
from rig.store import files
from rig.store.capture import Capture, read_capture
from rig.store.exposures import ExposureSets, exposure_sets

log = logging.getLogger(__name__)


def _solves_rpca(stage: str, options: ProcessOptions) -> bool:
    """Whether ``stage`` may solve RPCA problems in this run, so runs with single-threaded BLAS (rig.blas).

    Denoising and the corrections; the phase stage limits BLAS itself around the single shot's
    separation. Setting the limit costs a few ms, so it is set only where a solve may run.
    """
    if stage == "denoise":
        return options.denoise != "none"
    if stage == "correction":
        return options.correction != "none"
    return False


# --------------------------------------------------------------------------- the whole run


def _capture_groups(capture: Capture) -> tuple[PatternGroups, ExposureSets | None]:
    """A capture's pattern groups and, for one taken at several exposures, its exposure sets.

    A multi-exposure capture is grouped by its base sequence (its exposures are fused when loaded).
    """
    where = str(capture.manifest_path)
    sets = exposure_sets(capture.pattern_models, where)
    return group_patterns(sets.base, where), (sets if sets.multiple else None)


def _scene(
    name: str,
    capture: Capture,
    axis: str | None = None,
    grouped: tuple[PatternGroups, ExposureSets | None] | None = None,
) -> SceneState:
    """A capture's state along ``axis`` (default: the first axis with fringes; ProcessingError if none)."""
    groups, exposures = _capture_groups(capture) if grouped is None else grouped
    if axis is None:
        captured = captured_axes(groups)
        if not captured:
            raise ProcessingError(f"{capture.manifest_path}: no sinusoid pattern: nothing to compute a phase from")
        axis = captured[0]
    return SceneState(name=name, capture=capture, groups=groups, axis=axis, exposures=exposures)


def total_steps(with_reference: bool) -> int:
    """Progress steps of :func:`process` (stages of each capture, then height)."""
    return len(SCENE_STAGES) * (2 if with_reference else 1) + 1


# Calibrations read, with their reference captures, by the identity of the files they came from:
# every scan a calibration serves reads the same two manifests again (a long-running console or
# batch worker skips reading and checking them until either file changes).
_READ: OrderedDict[tuple[Any, ...], tuple[Calibration, Capture | None, tuple[int, ...] | None]] = OrderedDict()
_READ_ENTRIES = 4


def _identity(path: Path) -> tuple[int, ...] | None:
    """A file's device, inode, size and change times (None when it cannot be read)."""
    try:
        info = path.stat()
    except OSError:
        return None
    return (info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns, info.st_ctime_ns)


def _calibration_and_reference(calibration_path: str | Path) -> tuple[Calibration, Capture | None]:
    """The calibration and, when its model needs one, its reference capture (read once per file version)."""
    path = Path(calibration_path)
    key = (str(path), _identity(path if path.suffix == ".json" else path / "calibration.json"))
    cached = _READ.get(key) if key[1] is not None else None
    if cached is not None:
        calibration, reference, reference_identity = cached
        if reference is None or _identity(reference.manifest_path) == reference_identity:
            _READ.move_to_end(key)
            return calibration, reference
    calibration = read_calibration(calibration_path)
    reference, reference_identity = None, None
    if calibration_models.needs_reference(calibration):
        if calibration.reference is None or calibration.path is None:
            raise CalibrationError(f"{calibration.where}: reference: missing (the reference-plane capture)")
        # relative, and inside the calibration directory once every link is resolved
        ref_path = files.contained(
            calibration.path, calibration.reference, calibration.where, "reference", CalibrationError
        )
        if not (ref_path / "capture.json").is_file():
            raise CalibrationError(f"{calibration.where}: reference: no capture at {ref_path}")
        reference_identity = _identity(ref_path / "capture.json")  # before reading: a later change misses
        reference = read_capture(ref_path, verify=False)  # verified when loaded
    if key[1] is not None:
        _READ[key] = (calibration, reference, reference_identity)
        while len(_READ) > _READ_ENTRIES:
            _READ.popitem(last=False)
    return calibration, reference


def process(
    capture: Capture | str | Path,
    calibration_path: str | Path | None = None,
    options: ProcessOptions | None = None,
    progress: Any = None,
    salvage: bool = False,
    reference_cache_to_disk: bool = False,
    frames: np.ndarray | None = None,
) -> ProcessResult:
    """Run the stages on a capture and, with a calibration, on its reference plane; compute heights.

    ``capture``: a capture directory, or a :class:`Capture` already read (not read again).
    ``progress`` (a :class:`rig.events.Reporter` or the CLI's :class:`rig.progress.Progress`) gets
    ``begin(total)`` and one ``step`` per stage; a cancelled reporter stops the run between stages.
    The processed reference plane is reused from :mod:`rig.pipeline.reference_cache` (memory, and
    the calibration directory's cache, which ``reference_cache_to_disk`` also writes).
    ``frames``: the object's (N, H, W) frames already in memory (one per pattern, in pattern
    order), used instead of decoding the capture's files.
    """
    options = ProcessOptions() if options is None else options
    _check_options(options)
    started = time.perf_counter()
    if not isinstance(capture, Capture):
        capture = read_capture(capture, salvage=salvage, verify=False)  # the load stage checks every frame
    obj, second, ref, calibration = _scenes(capture, calibration_path, options)
    obj.frames = None if frames is None else np.asarray(frames)
    if second is not None:  # both axes: the frames are decoded once and read by both scenes
        if obj.frames is None:
            obj.frames = capture.load_frames()
        second.frames = obj.frames
    if progress is not None:
        progress.begin(total_steps(ref is not None))
    for state in ([ref] if ref is not None else []) + [obj]:
        _run_scene(state, options, progress, to_disk=reference_cache_to_disk and state is ref)
    if second is not None:  # its stages (and its reference plane's) are not among the progress steps announced
        if second.reference is not None:
            _run_scene(second.reference, options, None, to_disk=reference_cache_to_disk)
        _run_scene(second, options, None, to_disk=False)
    notes: list[str] = []
    t0 = time.perf_counter()
    height, points, mask, uncertainty, islands = _heights(obj, second, ref, calibration, options, notes)
    _bound_uncertainty(obj, mask, height, uncertainty, options.max_sigma, notes)
    height_time = time.perf_counter() - t0
    if progress is not None:
        progress.step("height")
    _drop_islands(obj, mask, height, options.min_island_fraction, notes, islands)
    _check_some_valid(obj, calibration, mask)
    timings: dict[str, Any] = {"object": dict(obj.timings)}
    if ref is not None:
        timings["reference"] = dict(ref.timings)
    timings["height"] = height_time
    timings["total"] = time.perf_counter() - started
    return ProcessResult(
        obj,
        ref,
        calibration,
        options,
        height,
        mask,
        timings,
        notes + obj.notes,
        point_grid=points,
        uncertainty=uncertainty,
    )


def _heights(
    obj: SceneState,
    second: SceneState | None,
    ref: SceneState | None,
    calibration: Calibration | None,
    options: ProcessOptions,
    notes: list[str],
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Heights, points, mask and sigma along one axis or both, and the islands when they were found
    beside the sigma (one axis, nothing changing the mask between)."""
    if second is not None and ref is not None:
        return (*_height_both_planes(obj, second, notes), None)
    if second is not None:
        assert calibration is not None
        return (*_height_both(obj, second, calibration, notes), None)
    islands: np.ndarray | None = None
    uncertainty: np.ndarray | None
    planar = _plane_heights(obj, ref, calibration)
    if planar is not None:
        _note_conditioning(obj, calibration, None, options.axis, notes)
        if options.max_sigma is None:
            islands = _islands(planar.mask, options.min_island_fraction)
        return planar.height, None, planar.mask, planar.sigma, islands
    (height, points, mask), start = side_by_side(  # the model a step ahead needs no heights
        lambda: _height(obj, ref, calibration, notes), lambda: _uncertainty_start(obj, ref, calibration)
    )
    if options.max_sigma is None:  # the mask the islands are found in is final: both side by side
        uncertainty, islands = side_by_side(
            lambda: _uncertainty(obj, start, mask, height),
            lambda: _islands(mask, options.min_island_fraction),
        )
    else:
        uncertainty = _uncertainty(obj, start, mask, height)
    _note_conditioning(obj, calibration, points, options.axis, notes)
    return height, points, mask, uncertainty, islands


def _scenes(
    capture: Capture, calibration_path: str | Path | None, options: ProcessOptions
) -> tuple[SceneState, SceneState | None, SceneState | None, Calibration | None]:
    """The object's scene, its second axis's when both are processed (:mod:`rig.pipeline.axes`) and,
    with a calibration whose model needs one, the reference plane's."""
    where = str(capture.manifest_path)
    grouped = _capture_groups(capture)
    groups = grouped[0]
    calibration, reference_capture = (None, None)
    if calibration_path is not None:
        calibration, reference_capture = _calibration_and_reference(calibration_path)
        refuse_kept_distortion(calibration, options)
    choice = choose_axes(groups, calibration, options.axis, where)
    if calibration is not None:
        for axis in choice.axes:  # everything the two share must fit, along every processed axis
            check_fit(capture, calibration, axis, reference_capture)
    scenes = [_scene("object", capture, axis, grouped) for axis in choice.axes]
    for state in scenes:
        # a reference-plane model fitted on both axes converts each with that axis's own numbers
        state.calibration = None if calibration is None else for_axis(calibration, state.axis)
        if reference_capture is not None:
            state.reference = _scene("reference", reference_capture, state.axis)
            state.reference.calibration = state.calibration
    obj, second = scenes[0], (scenes[1] if len(scenes) == 2 else None)
    obj.info["axis_choice"] = {"axis": choice.name, "why": choice.why}
    return obj, second, obj.reference, obj.calibration


def _run_scene(state: SceneState, options: ProcessOptions, progress: Any, to_disk: bool) -> None:
    """Every stage on one scene; a reference plane processed before (same options) comes from the cache."""
    key = None
    if state.name == "reference" and reference_cache.cacheable(state):
        t0 = time.perf_counter()
        key = reference_cache.cache_key(state, options)
        if reference_cache.load(state, key):
            state.timings["cached"] = time.perf_counter() - t0
            if progress is not None:
                for name, _ in SCENE_STAGES:
                    progress.step(f"{state.name}: {name} (cached)")
            return
    for name, stage in SCENE_STAGES:
        t0 = time.perf_counter()
        try:
            with rpca_blas() if _solves_rpca(name, options) else contextlib.nullcontext():
                stage(state, options)
        except ValueError as exc:  # the numeric kernels name the argument that does not fit
            raise ProcessingError(f"{state.capture.manifest_path}: {name}: {exc}") from None
        state.timings[name] = time.perf_counter() - t0
        if progress is not None:
            progress.step(f"{state.name}: {name}")
    state.frames = None  # the frames are not needed any more; free them early
    if key is not None:
        reference_cache.store(state, key, to_disk=to_disk)


def _plane_heights(obj: SceneState, ref: SceneState | None, calibration: Calibration | None) -> PlaneHeights | None:
    """Heights, sigma and mask of the reference-plane model in one blocked pass
    (:mod:`processing.geometry.plane_model`), where it applies: absolute phases of the object and
    its reference at one frequency, and lateral points finite for every finite height (any real rig).
    None elsewhere: the stepwise :func:`_height` and :func:`_uncertainty` then.
    """
    if calibration is None or calibration.model != REFERENCE_PLANE or ref is None:
        return None
    if obj.unwrapped is None or ref.unwrapped is None or not (obj.unwrapped.absolute and ref.unwrapped.absolute):
        return None
    if ref.unwrapped.frequency != obj.unwrapped.frequency:
        return None  # stage_height refuses it, with its message
    if calibration_models.lateral_bound(calibration, obj.unwrapped.phase.shape) is not None:
        return None
    assert calibration.l0_mm is not None and calibration.d0_mm is not None  # checked when read
    return plane_heights(
        obj.unwrapped.phase,
        ref.unwrapped.phase,
        obj.unwrapped.valid,
        ref.unwrapped.valid,
        (calibration.l0_mm, calibration.d0_mm, calibration.per_mm(obj.unwrapped.frequency)),
        phase_sigma=obj.phase_sigma,
        reference_sigma=ref.phase_sigma,
        threads=concurrency.THREADS,
    )


def _height(
    obj: SceneState, ref: SceneState | None, calibration: Calibration | None, notes: list[str]
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray]:
    """Heights (float32, NaN outside the mask), the model's points (or None) and the valid mask.

    Valid: a phase in the object (and the reference), and a finite stored height and point.
    """
    assert obj.unwrapped is not None
    mask = obj.unwrapped.valid.copy()
    if calibration is None:
        notes.append("no calibration: height, points and height preview skipped; phase, mask and wrapped phase written")
        return None, None, mask
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # absurd calibrations: masked below
        points, height = stage_height(obj, ref, calibration, notes)
        # valid only where the stored (float32) height and point are finite: no infinity in any output
        height32 = np.asarray(height).astype(np.float32, copy=False)  # stage_height's own array
        finite = np.isfinite(height32)
        if points is not None:
            finite &= np.isfinite(np.asarray(points).astype(np.float32)).all(axis=-1)
        else:  # plane models: points are made from the heights when written
            finite = calibration_models.plane_points_finite(calibration, height32, finite)
    if ref is not None:
        assert ref.unwrapped is not None
        mask &= ref.unwrapped.valid
    mask &= finite
    np.copyto(height32, np.float32(np.nan), where=~mask)  # our own float32 array: masked in place
    return height32, points, mask


@dataclass
class _UncertaintyStart:
    """The uncertainty map's inputs that do not need the heights (found beside them)."""

    sigma_phi: np.ndarray  # the object's and the reference's phase sigma in quadrature
    height_of: Callable[[np.ndarray], np.ndarray]
    # the model at phase + step for a forward difference from the heights themselves (None: central)
    ahead: np.ndarray | None


def _uncertainty_start(
    obj: SceneState, ref: SceneState | None, calibration: Calibration | None
) -> _UncertaintyStart | None:
    """The combined phase sigma and the model's heights a step ahead (None: no uncertainty map).

    The object's and the reference's phase sigma add in quadrature (docs/uncertainty.md).
    """
    if calibration is None or obj.phase_sigma is None:
        return None
    assert obj.unwrapped is not None
    sigma_phi = obj.phase_sigma
    if ref is not None and ref.phase_sigma is not None:
        sigma_phi = combined_phase_sigma(sigma_phi, ref.phase_sigma)
    height_of = functools.partial(_model_height, obj, ref, calibration)
    # the heights themselves as the forward difference's base, unless points move (stereo) or the
    # heights carry the spatial unwrapping's per-region offsets that the model call does not
    forward = calibration.model != "stereo" and obj.unwrapped.absolute and (ref is None or _absolute(ref))
    ahead = height_ahead(height_of, obj.unwrapped.phase) if forward else None
    return _UncertaintyStart(sigma_phi, height_of, ahead)


def _uncertainty(
    obj: SceneState, start: _UncertaintyStart | None, mask: np.ndarray, height: np.ndarray | None
) -> np.ndarray | None:
    """Predicted height sigma (mm, NaN where invalid) from :func:`_uncertainty_start`'s inputs and the heights."""
    if start is None or height is None:
        return None
    assert obj.unwrapped is not None
    uncertainty = height_sigma(
        start.height_of,
        obj.unwrapped.phase,
        start.sigma_phi,
        base=None if start.ahead is None else height,
        ahead=start.ahead,
    )
    np.copyto(uncertainty, np.float32(np.nan), where=~mask)
    return uncertainty


def _bound_uncertainty(
    obj: SceneState,
    mask: np.ndarray,
    height: np.ndarray | None,
    uncertainty: np.ndarray | None,
    max_sigma: float | None,
    notes: list[str],
) -> None:
    """With ``max_sigma`` the pixels whose predicted sigma is above it leave the mask (in place); a bound
    that no valid pixel meets is refused (ProcessingError), naming the smallest sigma predicted."""
    if max_sigma is None:
        return
    if uncertainty is None or height is None:
        notes.append("--max-sigma: no uncertainty predicted for this capture (phase-shifted fringes needed)")
        return
    above = mask & ~(uncertainty <= np.float32(max_sigma))
    if above.any() and not (mask & ~above).any():  # a bound no pixel meets: say so, not "no finite height"
        sigma = uncertainty[above]
        raise ProcessingError(
            f"--max-sigma {max_sigma:g} mm: every one of the {int(above.sum())} valid pixels has a larger predicted "
            f"height sigma (smallest {np.nanmin(sigma):.3g} mm, median {np.nanmedian(sigma):.3g} mm); "
            "raise the bound or leave it out"
        )
    obj.info["above_max_sigma"] = int(np.count_nonzero(above))
    mask &= ~above
    np.copyto(height, np.float32(np.nan), where=above)
    np.copyto(uncertainty, np.float32(np.nan), where=above)


def _note_conditioning(
    obj: SceneState, calibration: Calibration | None, points: np.ndarray | None, requested: str | None, notes: list[str]
) -> None:
    """Each axis's depth per projector pixel in the report (stereo model; reference-plane model fitted on
    both axes, with each axis's sensitivity); a warning for an ill-conditioned choice."""
    if calibration is None:
        return
    if calibration.model == STEREO and points is not None:
        per_pixel = stereo_conditioning(calibration, points)
    elif len(per_pixel := plane_conditioning(calibration, obj.capture.projector_size)) == 2:
        obj.info["sensitivity_rad_per_mm"] = {
            axis: round(value, 4) for axis, value in plane_sensitivities(calibration, obj.groups).items()
        }
    else:
        return
    obj.info["depth_per_projector_pixel_mm"] = per_pixel
    note = conditioning_note(AxisChoice((obj.axis,), "", requested), per_pixel)
    if note is not None:
        notes.append(note)


def _height_both(
    obj: SceneState, second: SceneState, calibration: Calibration, notes: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Heights, points, mask and sigma of a stereo capture triangulated along both axes.

    Each axis's points and predicted sigma along the camera ray, combined by
    :func:`processing.geometry.axis_fusion.fuse_points`; report: ``axis_fusion`` (pixels from both,
    from one alone, disagreeing) and each axis's depth per projector pixel.
    """
    points, sigmas = [], []
    for state in (obj, second):
        assert state.unwrapped is not None
        axis_points, _ = stage_height(state, None, calibration, notes)
        assert axis_points is not None  # the stereo model makes points
        axis_points = np.where(state.unwrapped.valid[..., None], axis_points, np.nan)
        phase_sigma = state.phase_sigma if state.phase_sigma is not None else np.float32(1.0)
        height_of = functools.partial(_model_height, state, None, calibration)
        points.append(axis_points)
        sigmas.append(height_sigma(height_of, state.unwrapped.phase, np.asarray(phase_sigma, dtype=np.float32)))
    fused = fuse_points(points, sigmas)
    height = calibration_models.stereo_model(calibration).heights(fused.points).astype(np.float32)
    per_pixel = stereo_conditioning(calibration, fused.points)
    mask, uncertainty = _fused_axes(obj, second, fused, height, "the two points on each camera ray", per_pixel, notes)
    return height, fused.points, mask, uncertainty


def _height_both_planes(
    obj: SceneState, second: SceneState, notes: list[str]
) -> tuple[np.ndarray, None, np.ndarray, np.ndarray]:
    """Heights, mask and sigma of a reference-plane capture converted along both axes.

    Each axis's heights (with its own l0, d0, f0 and reference phase) and predicted sigma, combined
    by the inverse-variance mean of :func:`processing.geometry.axis_fusion.fuse_points`; without a
    predicted phase noise, each axis is weighted by its height per projector pixel alone.
    """
    assert obj.calibration is not None
    per_pixel = plane_conditioning(obj.calibration, obj.capture.projector_size)
    heights, sigmas = [], []
    for state in (obj, second):
        assert state.calibration is not None
        height, _, mask = _height(state, state.reference, state.calibration, notes)
        assert height is not None  # a calibration gives heights
        sigma = _uncertainty(state, _uncertainty_start(state, state.reference, state.calibration), mask, height)
        if sigma is None:
            sigma = np.where(mask, np.float32(per_pixel[state.axis]), np.float32(np.nan))
        heights.append(height[..., None])
        sigmas.append(sigma)
    fused = fuse_points(heights, sigmas)
    height = fused.points[..., 0].astype(np.float32)
    mask, uncertainty = _fused_axes(obj, second, fused, height, "the two heights of each pixel", per_pixel, notes)
    return height, None, mask, uncertainty


def _fused_axes(
    obj: SceneState,
    second: SceneState,
    fused: FusedPoints,
    height: np.ndarray,
    what: str,
    per_pixel: dict[str, float],
    notes: list[str],
) -> tuple[np.ndarray, np.ndarray]:
    """Mask and sigma of heights fused from both axes (``height`` set NaN outside the mask, in place), and
    what the report says of the fusion: ``axis_fusion``, the other axis's stages, each axis's conditioning."""
    mask = np.isfinite(height) & np.isfinite(fused.sigma)
    np.copyto(height, np.float32(np.nan), where=~mask)
    uncertainty = np.where(mask, fused.sigma, np.float32(np.nan)).astype(np.float32)
    obj.info["axis_fusion"] = _fusion_info(fused, what)
    obj.info["other_axis"] = second.info
    obj.info["depth_per_projector_pixel_mm"] = per_pixel
    if any(state.phase_sigma is None for state in (obj, second)):
        notes.append("--axis both: no phase noise predicted; the axes are weighted by their geometry alone")
    return mask, uncertainty


def _fusion_info(fused: FusedPoints, what: str) -> dict[str, Any]:
    """report.json's ``axis_fusion``: the pixels from both axes, from one alone, and where they disagree."""
    return {
        "both_axes_pixels": fused.combined,
        "x_only_pixels": fused.alone[0],
        "y_only_pixels": fused.alone[1],
        "disagreeing_pixels": fused.disagreeing,
        "rule": f"inverse-variance mean of {what}; where they disagree beyond "
        "6 sigma, no point (nothing tells which axis is right)",
    }


def _absolute(state: SceneState) -> bool:
    return state.unwrapped is not None and state.unwrapped.absolute


def _model_height(obj: SceneState, ref: SceneState | None, calibration: Calibration, phase: np.ndarray) -> np.ndarray:
    """The calibration model's heights (or stereo points) of an object phase, for the uncertainty's derivative."""
    assert obj.unwrapped is not None
    ref_phase = None if ref is None or ref.unwrapped is None else ref.unwrapped.phase
    width, height = obj.capture.projector_size
    extent = float(width if obj.axis == "x" else height)
    if calibration.model == "stereo":
        return calibration_models.points_from_phase(
            calibration, phase, ref_phase, obj.unwrapped.frequency, axis=obj.axis, extent=extent
        )[0]
    return calibration_models.height_from_phase(
        calibration, phase, ref_phase, obj.unwrapped.frequency, axis=obj.axis, extent=extent
    )


def _islands(mask: np.ndarray, fraction: float) -> np.ndarray | None:
    """The valid regions under ``fraction`` of the largest (None when ``fraction`` is 0: none dropped)."""
    if fraction <= 0:
        return None
    from processing.correction.islands import island_mask

    return island_mask(mask, fraction)


def _drop_islands(
    obj: SceneState,
    mask: np.ndarray,
    height: np.ndarray | None,
    fraction: float,
    notes: list[str],
    islands: np.ndarray | None = None,
) -> None:
    """Drop (in place) valid regions under ``fraction`` of the largest: background specks.

    ``islands``: :func:`_islands` of this ``mask`` when the caller found them already.
    """
    if fraction <= 0:
        return
    if islands is None:
        islands = _islands(mask, fraction)
        assert islands is not None
    dropped = int(np.count_nonzero(islands))
    obj.info["islands_dropped"] = dropped
    if not dropped:
        return
    mask &= ~islands
    if height is not None:  # our own float32 array, already NaN outside the mask
        np.copyto(height, np.float32(np.nan), where=islands)
    notes.append(
        f"{dropped} valid pixels in isolated islands (regions under {fraction:g} of the "
        "largest) dropped as background specks; --keep-islands keeps them"
    )


def _check_some_valid(obj: SceneState, calibration: Calibration | None, mask: np.ndarray) -> None:
    """ProcessingError when no pixel is left, naming the likelier cause."""
    if mask.any():
        return
    assert obj.unwrapped is not None
    if calibration is not None and obj.unwrapped.valid.any():  # lit pixels, but the model gave no finite height
        raise ProcessingError(
            f"{calibration.where}: no pixel has a finite height with this calibration although "
            f"{int(obj.unwrapped.valid.sum())} pixels have a phase (check its numbers and matrices)"
        )
    raise ProcessingError(
        f"{obj.capture.manifest_path}: no valid pixel (all in shadow or too little fringe modulation)"
    )


def _check_options(options: ProcessOptions) -> None:
    if options.unwrap not in UNWRAP_METHODS:
        raise ProcessingError(f"--unwrap: expected one of {', '.join(UNWRAP_METHODS)}, found {options.unwrap!r}")
    if options.denoise not in DENOISERS:
        raise ProcessingError(f"--denoise: expected one of {', '.join(DENOISERS)}, found {options.denoise!r}")
    if options.correction not in CORRECTIONS:
        raise ProcessingError(f"--correction: expected one of {', '.join(CORRECTIONS)}, found {options.correction!r}")
    if not 0 <= options.min_island_fraction <= 1:
        raise ProcessingError(f"--min-island: expected a fraction in [0, 1], found {options.min_island_fraction}")
    if options.axis not in (None, *AXES):
        raise ProcessingError(f"--axis: expected one of {', '.join(AXES)}, found {options.axis!r}")
    if options.max_sigma is not None and not options.max_sigma > 0:
        raise ProcessingError(f"--max-sigma: expected a positive number of mm, found {options.max_sigma}")
    if options.min_modulation_ratio is not None and not 0 < options.min_modulation_ratio <= 1:
        raise ProcessingError(f"--min-modulation: expected a fraction in (0, 1], found {options.min_modulation_ratio}")
    if options.max_phase_sigma is not None and not options.max_phase_sigma > 0:
        raise ProcessingError(
            f"--max-phase-sigma: expected a positive number of radians, found {options.max_phase_sigma}"
        )
