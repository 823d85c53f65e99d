"""The stages each capture goes through (load, undistort, denoise, wrapped, unwrap, correction) and height."""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration import models as calibration_models
from calibration.errors import CalibrationError
from calibration.store import Calibration
from rig.errors import ProcessingError
from rig.pipeline.corrections import stage_correction
from rig.pipeline.plan import (
    TWO_PI,
    UNWRAP_METHODS,
    PatternGroups,
    ProcessOptions,
    _all_integers,
    accepted_params,
    choose_unwrap,
)
from rig.store.capture import Capture, dtype_for_bit_depth

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------- per-capture state


@dataclass
class WrappedPhase:
    """Wrapped phase per frequency (any 2 pi representation), with the modulation and background of each.

    The fused pass keeps these maps only for the highest frequency (what height, texture and
    corrections read) unless the capture has no calibration (wrapped.npy has them all); the
    other entries are then None.
    """

    frequencies: list[float]
    phase: list[np.ndarray | None]
    modulation: list[np.ndarray | None]
    background: list[np.ndarray | None]
    valid: np.ndarray
    # A + B per frequency instead of the two apart (the fused pass: the texture is all that reads them)
    brightness: list[np.ndarray | None] | None = None


@dataclass
class UnwrappedPhase:
    """Absolute phase 2 pi f u / W at ``frequency`` (NaN where invalid); ``absolute`` False for spatial."""

    phase: np.ndarray
    valid: np.ndarray
    frequency: float
    method: str
    absolute: bool = True
    orders: np.ndarray | None = None


@dataclass
class SceneState:
    """One capture on its way through the stages."""

    name: str
    capture: Capture
    groups: PatternGroups
    axis: str
    frames: np.ndarray | None = None
    wrapped: WrappedPhase | None = None
    unwrapped: UnwrappedPhase | None = None
    reference: SceneState | None = None
    timings: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)
    calibration: Calibration | None = None
    single_shot_reference: Any = None  # processing.single_shot.SingleShotReference of a reference capture


def stage_load(state: SceneState, options: ProcessOptions) -> None:
    """Decode every frame (checksums, size and bit depth checked) into an (N, H, W) stack.

    Frames given in memory (:func:`rig.pipeline.run.process`'s ``frames``) are checked against the
    manifest instead: one per pattern, the camera's size and the bit depth's dtype.
    """
    if state.frames is None:
        state.frames = state.capture.load_frames()
        return
    capture, frames = state.capture, state.frames
    expected = (len(capture.patterns), *capture.shape)
    if frames.shape != expected:
        raise ProcessingError(
            f"frames: expected shape {expected} (one frame per pattern of {capture.manifest_path}), found {frames.shape}"
        )
    dtype = dtype_for_bit_depth(capture.bit_depth)
    if frames.dtype != dtype:
        raise ProcessingError(
            f"frames: expected dtype {dtype} for camera.bit_depth {capture.bit_depth}, found {frames.dtype}"
        )


def stage_undistort(state: SceneState, options: ProcessOptions) -> None:
    """Remove lens distortion with the calibration's ``camera_matrix`` / ``distortion``.

    Done by default when they are present, except for the stereo model, whose triangulation
    undistorts camera rays itself. ``--no-undistort`` skips it.
    """
    cal = state.calibration
    if cal is None or options.undistort is False or cal.model == "stereo":
        return
    matrix, distortion = cal.extra.get("camera_matrix"), cal.extra.get("distortion")
    if matrix is None or distortion is None:
        if options.undistort:
            raise CalibrationError(f"{cal.where}: camera_matrix / distortion: missing, cannot undistort")
        return
    from calibration.camera import undistort_stack

    try:
        matrix_arr = np.asarray(matrix, dtype=np.float64).reshape(3, 3)
        dist_arr = np.asarray(distortion, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise CalibrationError(
            f"{cal.where}: camera_matrix / distortion: expected a 3x3 matrix and a list of numbers"
        ) from None
    assert state.frames is not None
    state.frames = undistort_stack(state.frames, matrix_arr, dist_arr)
    state.info["undistorted"] = True


def _denoise_none(frames: np.ndarray, groups: PatternGroups, options: ProcessOptions) -> np.ndarray:
    return frames


def _denoise_rpca(
    frames: np.ndarray, groups: PatternGroups, options: ProcessOptions
) -> tuple[np.ndarray, dict[str, Any]]:
    """Thesis ch. 2.4: each frame's low-rank part (stable inexact ALM RPCA); returns frames and stage info."""
    from processing.denoise import rpca_denoise_stack

    params = accepted_params(rpca_denoise_stack, options.params)
    start = time.perf_counter()
    try:
        denoised, results = rpca_denoise_stack(frames, **params)
    except ValueError as exc:
        raise ProcessingError(f"--denoise rpca: {exc}") from None
    return denoised, {
        "method": "rpca",
        "parameters": params,
        "iterations": [r.iterations for r in results],
        "rank": [r.rank for r in results],
        "seconds": round(time.perf_counter() - start, 4),
    }


# A denoiser returns the frames, or (frames, info) to record its parameters and effort.
DENOISERS: dict[str, Callable[[np.ndarray, PatternGroups, ProcessOptions], Any]] = {
    "none": _denoise_none,
    "rpca": _denoise_rpca,
}


def stage_denoise(state: SceneState, options: ProcessOptions) -> None:
    """Optional fringe denoising of the frames (``--denoise``)."""
    if options.denoise == "none":
        return
    assert state.frames is not None
    out = DENOISERS[options.denoise](state.frames, state.groups, options)
    state.frames, detail = out if isinstance(out, tuple) else (out, None)
    state.info["denoise"] = detail if detail is not None else options.denoise


def stage_wrapped(state: SceneState, options: ProcessOptions) -> None:
    """Wrapped phase of every sinusoid group along the fringe axis, and the valid-pixel mask.

    With phase-shifting groups only and a temporal unwrapping method (the default path), the
    fused float32 pass (:mod:`processing.fringe_pass`) also unwraps, in the same visit of the
    frames; the unwrap stage then has nothing left to do.
    """
    if state.groups.single_shot:
        return  # the single-shot handler computes its own phase in the unwrap stage
    assert state.frames is not None
    if _fused_pass(state, options):
        return
    from processing.phase_shift import phase_shift, shadow_mask

    frames = state.frames
    out = WrappedPhase([], [], [], [], np.ones(state.capture.shape, dtype=bool))
    for group in state.groups.along(state.axis):
        if group.steps < 3:
            if group.steps != 1:
                raise ProcessingError(
                    f"sinusoid frequency {group.frequency:g}: expected 1 frame (FTP) or >= 3 phase shifts, found {group.steps}"
                )
            phase, amplitude, background = _ftp_frame(frames[group.indices[0]], state.axis, group.shifts[0])
        else:
            result = phase_shift(frames[group.indices], shifts=np.asarray(group.shifts))
            phase, amplitude, background = result.phase, result.modulation, result.background
        out.frequencies.append(group.frequency)
        out.phase.append(phase)
        out.modulation.append(amplitude)
        out.background.append(background)
        out.valid &= shadow_mask(amplitude, background, min_ratio=options.min_modulation_ratio)
    state.wrapped = out
    state.info["valid_after_modulation"] = float(out.valid.mean())
    _note_other_axis(state)


def _note_other_axis(state: SceneState) -> None:
    """Say which sinusoids along the other axis the wrapped stage left unused."""
    other = sorted({g.frequency for g in state.groups.sinusoids if g.axis != state.axis})
    if other:
        state.notes.append(f"sinusoids along the other axis (frequencies {other}) not used; choose them with --axis")


def _fused_pass(state: SceneState, options: ProcessOptions) -> bool:
    """Wrapped phases, mask and temporal unwrapping in one pass, when the capture allows it; False if not."""
    from processing.temporal import TEMPORAL_METHODS

    along = state.groups.along(state.axis)
    if not along or any(group.steps < 3 for group in along):
        return False
    try:
        method = options.unwrap if options.unwrap != "auto" else choose_unwrap(state.groups, state.axis)
    except ProcessingError:
        return False  # the unwrap stage reports it
    freqs = [group.frequency for group in along]
    if method not in TEMPORAL_METHODS or not _all_integers(freqs) or len(freqs) < _FREQUENCIES_NEEDED[method]:
        return False
    from processing.fringe_pass import fringe_pass
    from rig.pipeline import convention_check

    max_residual = float(options.params.get("max_residual", np.pi / 2))  # e.g. 3.14 for drifting beats
    check = method == "heterodyne" and convention_check.enabled(options)
    assert state.frames is not None
    try:
        scan = fringe_pass(
            state.frames,
            [group.indices for group in along],
            freqs,
            method,
            shifts=[np.asarray(group.shifts) for group in along],
            min_ratio=options.min_modulation_ratio,
            max_residual=max_residual,
            keep_all=state.calibration is None or check,
            orders=False,  # the corrections re-derive orders from the phases; nothing else reads them
            brightness=True,  # A + B, the texture, instead of A and B apart: one map fewer
        )
    except ValueError:
        return False  # e.g. frequencies the method refuses: the stage-by-stage path reports it as before
    maps = {index: slot for slot, index in enumerate(scan.kept)}

    def kept(values: list[np.ndarray]) -> list[np.ndarray | None]:
        return [values[maps[i]] if i in maps else None for i in range(len(freqs))]

    none: list[np.ndarray | None] = [None] * len(freqs)
    state.wrapped = WrappedPhase(freqs, kept(scan.wrapped), none, list(none), scan.modulated, kept(scan.brightness))
    state.info["valid_after_modulation"] = np.count_nonzero(scan.modulated) / scan.modulated.size
    if check:
        _check_convention(state, options, "heterodyne", scan.wrapped, [int(f) for f in freqs])
    assert scan.phase is not None
    mask, phase = scan.valid, scan.phase
    rejected = bool(np.any(scan.modulated > mask))  # modulated pixels the method's test rejected
    if options.params.get("neighbour_rescue", True) is not False:
        mask = _rescue_rejected(state, phase, mask, scan.modulated, rejected)
    if rejected and np.any(scan.modulated > mask):  # their phase, kept by the pass, becomes NaN
        np.copyto(phase, np.float32(np.nan), where=~mask)  # the pass's own array
    state.unwrapped = UnwrappedPhase(
        phase=phase, valid=mask, frequency=freqs[-1], method=method, absolute=True, orders=scan.orders
    )
    state.info["fused_pass"] = "phase shifting, modulation mask and unwrapping in one float32 pass"
    _note_other_axis(state)
    return True


# Frequencies each temporal method needs (it takes the highest when more are captured).
_FREQUENCIES_NEEDED = {"two-frequency": 2, "three-frequency": 3, "heterodyne": 2, "hierarchical": 2}


def _ftp_frame(image: np.ndarray, axis: str, shift: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wrapped phase, amplitude and background of a single fringe frame (Fourier transform profilometry).

    The background is the mean over one fringe period along the axis (the detected carrier).
    """
    from processing.ftp import detect_carrier, fringe_background, ftp_phase

    img = np.asarray(image, dtype=np.float64)
    along = 1 if axis == "x" else 0
    phase, amplitude = ftp_phase(img, axis=along)
    phase = np.angle(np.exp(1j * (phase - shift)))
    background = fringe_background(img, detect_carrier(img, along), along)
    return phase, np.asarray(amplitude, dtype=np.float64), background


# Arguments of processing.single_shot.single_shot_unwrap that the pipeline supplies itself.
_SINGLE_SHOT_OWN = ("image", "reference_image", "reference_absolute_phase", "frequency", "axis", "mask")


def _single_shot_parameters(options: ProcessOptions) -> tuple[dict[str, Any], dict[str, Any]]:
    """(``--param`` entries single_shot_unwrap takes, all its settings with defaults) for the report."""
    import inspect

    from processing.single_shot import single_shot_unwrap

    given = {k: v for k, v in accepted_params(single_shot_unwrap, options.params).items() if k not in _SINGLE_SHOT_OWN}
    defaults = {
        name: p.default
        for name, p in inspect.signature(single_shot_unwrap).parameters.items()
        if p.kind is inspect.Parameter.KEYWORD_ONLY and name not in _SINGLE_SHOT_OWN
    }
    return given, {**defaults, **given}


def _speckle_single_shot(state: SceneState, options: ProcessOptions) -> None:
    """``speckle-sinusoid`` captures (thesis ch. 2.3) through :mod:`processing.single_shot`.

    The calibration's reference capture (same pattern, processed first) is separated by RPCA and
    phased by FTP once (:func:`processing.single_shot.prepare_reference`); its absolute phase is
    its FTP phase unwrapped along the rows with the smallest fringe order 0: a flat plane has no
    discontinuity, and the projector column of the reference's first order is fixed only by the
    rig's geometry, which the reference-plane and polynomial models do not need (they use object
    minus reference). The object frame then gets its fringe orders from the reference speckle
    (:func:`processing.single_shot.single_shot_unwrap`), so both phases share that offset. The
    result fills ``state.wrapped`` / ``state.unwrapped`` for the correction and height stages;
    method, parameters, RPCA iterations and rank and the time of each step go to the report.
    """
    from processing.ftp import ftp_fringe_parts
    from processing.single_shot import (
        prepare_reference,
        separate_fringe_speckle,
        single_shot_unwrap,
    )

    group = state.groups.single_shot[0]
    where = str(state.capture.manifest_path)
    assert state.frames is not None
    image = state.frames[group.indices[0]].astype(np.float32)
    if group.steps > 1 or len(group.indices) > 1:
        state.notes.append(
            f"single-shot: {len(group.indices)} speckle-sinusoid frames; used the first (pattern {group.indices[0]})"
        )
    if options.denoise != "none":
        raise ProcessingError(
            f"--denoise {options.denoise}: not for a speckle-sinusoid (single-shot) capture, whose speckle it would "
            "remove; the single shot separates fringes and speckle by RPCA itself (leave --denoise none)"
        )
    if options.unwrap != "auto":
        state.notes.append(
            f"single-shot capture: --unwrap {options.unwrap} does not apply; fringe orders from the speckle"
        )
    axis = 1 if state.axis == "x" else 0
    given, settings = _single_shot_parameters(options)
    pattern = state.capture.patterns[group.indices[0]]  # read only
    parameters: dict[str, Any] = {
        "frequency": group.frequency,
        "fringe_axis": state.axis,
        **settings,
        **{k: pattern[k] for k in ("seed", "dot_px", "speckle_gain") if k in pattern},
    }
    start = time.perf_counter()
    try:
        if state.reference is None:
            if state.name != "reference":
                raise ProcessingError(
                    f"{where}: a speckle-sinusoid (single-shot) capture takes its fringe orders from a reference-plane "
                    "capture under the same pattern: give a --calibration whose reference capture has it "
                    "(rig calibrate itself needs phase-shifting patterns)"
                )
            prep = {k: v for k, v in given.items() if k in ("carrier", "bandwidth", "tau", "rpca_tol", "svd")}
            rpca = None
            if settings["separate"]:
                # Separate here (not inside prepare_reference) to keep RPCA's iterations and rank for the report.
                fringe, speckle, rpca = separate_fringe_speckle(
                    image, tau=settings["tau"], tol=settings["rpca_tol"], svd=settings["svd"]
                )
                prepared = prepare_reference(
                    fringe,
                    None,
                    group.frequency,
                    axis=axis,
                    separate=False,
                    **{k: v for k, v in prep.items() if k in ("carrier", "bandwidth")},
                )
                prepared = dataclasses.replace(prepared, speckle=speckle)
            else:
                prepared = prepare_reference(
                    image,
                    None,
                    group.frequency,
                    axis=axis,
                    separate=False,
                    **{k: v for k, v in prep.items() if k in ("carrier", "bandwidth")},
                )
            prepared.seconds = time.perf_counter() - start
            state.single_shot_reference = prepared
            parts = ftp_fringe_parts(
                prepared.fringe, prepared.carrier, axis, settings["bandwidth"], settings["min_modulation"]
            )
            wrapped, amplitude, background, valid = parts.phase, parts.amplitude, parts.background, parts.valid
            absolute = prepared.absolute_phase
            orders = np.where(valid, np.rint((absolute - prepared.wrapped_phase) / TWO_PI), -1).astype(np.int64)
            timings = {"reference": prepared.seconds}
        else:
            prepared = state.reference.single_shot_reference
            if prepared is None:
                raise ProcessingError(
                    f"{where}: the reference capture is not a speckle-sinusoid single shot like this capture"
                )
            result = single_shot_unwrap(image, prepared, None, group.frequency, axis=axis, **given)
            rpca = result.rpca
            parts = ftp_fringe_parts(
                result.fringe, prepared.carrier, axis, settings["bandwidth"], settings["min_modulation"]
            )
            wrapped, amplitude, background = parts.phase, parts.amplitude, parts.background
            valid = result.mask & np.isfinite(result.absolute_phase)
            absolute, orders, timings = result.absolute_phase, result.orders, dict(result.timings)
            timings.pop("reference", None)  # prepared with the reference capture, reported there
            state.info["single_shot_correlation_median"] = (
                float(np.median(result.correlation[valid])) if valid.any() else None
            )
    except ValueError as exc:
        raise ProcessingError(f"{where}: single-shot: {exc}") from None
    state.wrapped = WrappedPhase([group.frequency], [wrapped], [amplitude], [background], valid)
    state.unwrapped = UnwrappedPhase(
        phase=np.where(valid, absolute, np.nan),
        valid=valid,
        frequency=group.frequency,
        method="single-shot",
        absolute=True,
        orders=orders,
    )
    state.info["valid_after_modulation"] = float(valid.mean())
    state.info["single_shot"] = {
        "method": "speckle-embedded single shot (RPCA fringe/speckle separation, FTP, speckle NCC fringe orders, row voting, 2-D fringe-segment vote)",
        "role": "reference" if state.reference is None else "object",
        "parameters": parameters,
        "iterations": None if rpca is None else int(rpca.iterations),
        "rank": None if rpca is None else int(rpca.rank),
        "seconds": round(time.perf_counter() - start, 4),
        "timings_s": {k: round(float(v), 4) for k, v in timings.items()},
    }
    if state.reference is not None:
        state.notes.append(
            "single-shot: the reference plane's absolute phase is its FTP phase unwrapped along the rows with "
            "smallest fringe order 0; object phases share that offset, which object - reference cancels"
        )


SINGLE_SHOT: dict[str, Callable[[SceneState, ProcessOptions], None]] = {"speckle-sinusoid": _speckle_single_shot}


def _as_unwrap_parts(result: Any) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(phase, orders, valid) of an UnwrapResult, or of a bare phase array."""
    if isinstance(result, np.ndarray):
        return result, None, None
    return np.asarray(result.phase), getattr(result, "orders", None), getattr(result, "valid", None)


def _gray_threshold(state: SceneState) -> np.ndarray | None:
    """Threshold for Gray planes: mid of white and black flat frames if captured (else decode_gray's default)."""
    assert state.frames is not None
    levels = {level: index for index, level in state.groups.flats}
    if 1.0 in levels and 0.0 in levels:
        return (state.frames[levels[1.0]].astype(np.float64) + state.frames[levels[0.0]]) / 2.0
    return None


def _rescue_rejected(
    state: SceneState, phase: np.ndarray, mask: np.ndarray, modulated: np.ndarray, rejected: bool | None = None
) -> np.ndarray:
    """Take back modulated pixels a temporal residual test rejected where neighbours vouch for their phase.

    ``rejected``: whether any modulated pixel is outside ``mask``, when the caller knows.
    """
    from processing.neighbour_rescue import rescue

    if not (np.any(modulated > mask) if rejected is None else rejected):  # nothing to take back
        state.info["neighbour_rescue"] = {"readmitted": 0, "off": "--param neighbour_rescue=false"}
        return mask
    rescued = rescue(phase, mask, modulated)  # rescue skips non-finite phases itself
    state.info["neighbour_rescue"] = {
        "readmitted": int(np.count_nonzero(rescued & ~mask)),
        "off": "--param neighbour_rescue=false",
    }
    return rescued


def _check_convention(
    state: SceneState,
    options: ProcessOptions,
    evidence: str,
    maps: Sequence[np.ndarray],
    freqs: Sequence[int],
    stripes: np.ndarray | None = None,
    bits: int = 0,
) -> None:
    """Refuse images whose phase convention differs from the capture's (:mod:`rig.pipeline.convention_check`)."""
    from processing.convention import gray_offset, heterodyne_offset
    from rig.pipeline import convention_check

    if not convention_check.enabled(options):
        return
    assert state.wrapped is not None
    if evidence == "gray":
        assert stripes is not None
        estimate = gray_offset(maps[0], stripes, bits, freqs[0], state.wrapped.valid, state.axis)
        text = "the Gray-code period boundaries fall mid-period instead of at the phase wrap"
    else:
        estimate = heterodyne_offset(maps, freqs, state.wrapped.valid)
        text = "the heterodyne residuals are far above the noise (the beats disagree with the finest phase)"
    state.info["phase_convention_offset_rad"] = estimate.offset
    convention_check.check(estimate, text, state.capture, state.capture.patterns, str(state.capture.manifest_path))


def stage_unwrap(state: SceneState, options: ProcessOptions) -> None:
    """Absolute (or, for spatial methods, relative) phase at the highest frequency."""
    if state.groups.single_shot:
        SINGLE_SHOT[state.groups.single_shot[0].kind](state, options)
        return
    if state.unwrapped is not None:
        return  # unwrapped by the fused pass of the wrapped stage
    wrapped = state.wrapped
    assert wrapped is not None
    method = options.unwrap if options.unwrap != "auto" else choose_unwrap(state.groups, state.axis)
    freqs = wrapped.frequencies
    phis = [p for p in wrapped.phase if p is not None]  # all of them: only the fused pass leaves some out
    assert len(phis) == len(freqs)
    need = _FREQUENCIES_NEEDED.get(method, 1)
    if len(freqs) < need:
        raise ProcessingError(f"--unwrap {method}: needs at least {need} sinusoid frequencies, the capture has {freqs}")
    absolute = True
    result: Any  # an UnwrapResult, or a bare phase array from spatial unwrapping
    if method in ("two-frequency", "three-frequency", "hierarchical", "heterodyne", "gray"):
        from processing import temporal
    if method in ("two-frequency", "three-frequency", "hierarchical", "heterodyne"):
        if not _all_integers(freqs):
            raise ProcessingError(f"--unwrap {method}: frequencies must be whole fringe counts, found {freqs}")
        use = slice(-need, None) if method in ("two-frequency", "three-frequency") else slice(None)
        ints, maps = [int(f) for f in freqs[use]], phis[use]
        if method == "two-frequency":
            result = temporal.unwrap_two_frequency(maps[0], maps[1], ints[0], ints[1])
        elif method == "three-frequency":
            result = temporal.unwrap_three_frequency(maps, ints)
        else:
            extra = {}
            if "max_residual" in options.params:  # e.g. --param max_residual=3.14 for rendered data with drifting beats
                extra["max_residual"] = float(options.params["max_residual"])
            unwrap = temporal.unwrap_hierarchical if method == "hierarchical" else temporal.unwrap_heterodyne
            if method == "heterodyne":
                _check_convention(state, options, "heterodyne", maps, ints)
            result = unwrap(maps, ints, **extra)
    elif method == "gray":
        gray = state.groups.gray.get(state.axis)
        if gray is None:
            raise ProcessingError(f"--unwrap gray: the capture has no Gray-code planes along {state.axis}")
        assert state.frames is not None
        planes = state.frames[[gray.planes[b] for b in range(gray.bits)]]
        inverted = state.frames[[gray.inverted[b] for b in range(gray.bits)]] if gray.inverted else None
        threshold = None if inverted is not None else _gray_threshold(state)
        stripes = temporal.decode_gray(planes, inverted=inverted, threshold=threshold)
        frequency = freqs[-1]
        complementary = (1 << gray.bits) == 2 * int(frequency)
        if not complementary and (1 << gray.bits) != int(frequency):
            raise ProcessingError(
                f"--unwrap gray: {gray.bits} Gray bits give {1 << gray.bits} stripes; expected the fringe count "
                f"{frequency:g} (or twice it, complementary Gray code)"
            )
        _check_convention(state, options, "gray", [phis[-1]], [int(frequency)], stripes, gray.bits)
        result = temporal.unwrap_gray(phis[-1], stripes, gray.bits, int(frequency), complementary=complementary)
    elif method in ("spatial", "ftp"):
        from processing import spatial

        result = spatial.unwrap_quality_guided(phis[-1], mask=wrapped.valid)
        absolute = False
    else:
        raise ProcessingError(f"--unwrap: expected one of {', '.join(UNWRAP_METHODS)}, found {method!r}")
    phase, orders, valid = _as_unwrap_parts(result)
    mask = wrapped.valid & np.isfinite(phase)
    if valid is not None:
        mask &= np.asarray(valid, dtype=bool)
        if method != "gray" and options.params.get("neighbour_rescue", True) is not False:
            mask = _rescue_rejected(state, phase, mask, wrapped.valid)
    state.unwrapped = UnwrappedPhase(
        phase=np.where(mask, phase, np.nan),
        valid=mask,
        frequency=freqs[-1],
        method=method,
        absolute=absolute,
        orders=orders,
    )


SCENE_STAGES: list[tuple[str, Callable[[SceneState, ProcessOptions], None]]] = [
    ("load", stage_load),
    ("undistort", stage_undistort),
    ("denoise", stage_denoise),
    ("wrapped", stage_wrapped),
    ("unwrap", stage_unwrap),
    ("correction", stage_correction),
]


# --------------------------------------------------------------------------- height


def stage_height(
    obj: SceneState, ref: SceneState | None, calibration: Calibration, notes: list[str]
) -> tuple[np.ndarray | None, np.ndarray]:
    """Points (H, W, 3) and heights (H, W) in mm from the object's (and reference's) absolute phase.

    The points come back only from the stereo model, whose triangulation makes them; the plane
    models' points follow from the heights (:func:`calibration.models.plane_points`) for the
    pixels a caller keeps, without an (H, W, 3) array.
    """
    assert obj.unwrapped is not None
    obj_phase = obj.unwrapped.phase
    ref_phase = None
    if ref is not None:
        assert ref.unwrapped is not None
        if ref.unwrapped.frequency != obj.unwrapped.frequency:
            raise ProcessingError("object and reference phases are at different frequencies")
        ref_phase = ref.unwrapped.phase
    ref_absolute = ref is None or (ref.unwrapped is not None and ref.unwrapped.absolute)
    if not (obj.unwrapped.absolute and ref_absolute):
        if ref_phase is None:
            raise ProcessingError(
                f"{obj.capture.manifest_path}: spatial unwrapping gives phase only up to 2 pi k, and the "
                f"{calibration.model!r} calibration has no reference plane to fix k; capture temporal patterns"
            )
        from processing.spatial import remove_region_offsets

        obj_phase = ref_phase + remove_region_offsets(obj_phase - ref_phase)
        notes.append(
            "spatial unwrapping: phase known up to 2 pi k per connected region; removed from each region the "
            "multiple of 2 pi nearest its median object-reference difference (right where the reference plane "
            "shows in the region)"
        )
    width, height = obj.capture.projector_size
    extent = float(width if obj.axis == "x" else height)
    with np.errstate(invalid="ignore", divide="ignore"):
        if calibration.model == "stereo":
            return calibration_models.points_from_phase(
                calibration, obj_phase, ref_phase, obj.unwrapped.frequency, axis=obj.axis, extent=extent
            )
        return None, calibration_models.height_from_phase(
            calibration, obj_phase, ref_phase, obj.unwrapped.frequency, axis=obj.axis, extent=extent
        )
