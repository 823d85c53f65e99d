"""The stages each capture goes through (load, undistort, denoise, phase, correction) and height.

``phase`` turns the frames into the absolute phase: wrapped phase and unwrapping, fused in one pass
where the capture allows it (:func:`stage_phase`). Unwrapping methods come from
:mod:`rig.pipeline.unwrapping`, denoisers from :data:`DENOISERS`, corrections from
:mod:`rig.pipeline.corrections`.
"""

from __future__ import annotations

import functools
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration import models as calibration_models
from calibration.camera import undistort_stack
from calibration.errors import CalibrationError
from calibration.store import Calibration
from processing import concurrency
from processing.denoise.frames import rpca_denoise_stack
from processing.geometry.uncertainty import noise_sigma, phase_sigma
from processing.phase.convention import gray_offset, heterodyne_offset
from processing.phase.frequency_fusion import fuse_frequencies
from processing.phase.shifting import phase_shift, sample_stride, shadow_mask
from processing.quantiles import percentile
from processing.unwrap.fused_pass import FringePass, fringe_pass, modulation_thresholds
from processing.unwrap.neighbour_rescue import rescue
from rig.blas import kernel_blas, rpca_blas
from rig.errors import ProcessingError
from rig.pipeline import convention_check
from rig.pipeline.corrections import stage_correction
from rig.pipeline.exposures import fuse_state_exposures
from rig.pipeline.plan import (
    RATIO_RULE_RATIO,
    PatternGroups,
    ProcessOptions,
    _all_integers,
    accepted_params,
    choose_unwrap,
)
from rig.pipeline.state import SceneState, UnwrappedPhase, WrappedPhase
from rig.pipeline.unwrapping import REGISTRY as UNWRAPPERS
from rig.pipeline.unwrapping import UNWRAP_METHODS, GrayPlanes, UnwrapInputs, UnwrapMethod
from rig.store.capture import dtype_for_bit_depth

__all__ = ["DENOISERS", "SCENE_STAGES", "SceneState", "UnwrappedPhase", "WrappedPhase", "stage_height"]

log = logging.getLogger(__name__)


def stage_load(state: SceneState, options: ProcessOptions) -> None:
    """Decode every frame (checksums, size and bit depth checked) into an (N, H, W) stack.

    Frames given in memory (:func:`rig.pipeline.run.process`'s ``frames``) are checked against the
    manifest instead: one per pattern, the camera's size and the bit depth's dtype. A capture taken
    at several exposures leaves this stage as one fused stack of its base patterns
    (:mod:`rig.pipeline.exposures`).
    """
    if state.frames is None:
        state.frames = state.capture.load_frames()
        fuse_state_exposures(state)
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
    fuse_state_exposures(state)


def stage_undistort(state: SceneState, options: ProcessOptions) -> None:
    """Remove lens distortion with the calibration's ``camera_matrix`` / ``distortion``.

    Done by default when they are present, except for the stereo model, whose triangulation
    undistorts camera rays itself (the report says ``"undistorted": "rays"``). ``--no-undistort``
    skips it.
    """
    cal = state.calibration
    if cal is not None and cal.model == "stereo":  # --no-undistort is refused for it (rig.pipeline.run)
        state.info["undistorted"] = "rays"  # the triangulation undistorts camera and projector rays
        return
    if cal is None or options.undistort is False:
        return
    matrix, distortion = cal.extra.get("camera_matrix"), cal.extra.get("distortion")
    if matrix is None or distortion is None:
        if options.undistort:
            raise CalibrationError(f"{cal.where}: camera_matrix / distortion: missing, cannot undistort")
        return
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


@dataclass(frozen=True)
class Denoiser:
    """One registered fringe denoiser; calling it calls ``run``.

    ``run``: ``f(frames, groups, options)`` returning the frames, or (frames, info) to record its
    parameters and effort. ``description``: one line for ``--help``, the console and the docs.
    """

    name: str
    run: Callable[[np.ndarray, PatternGroups, ProcessOptions], Any]
    description: str

    def __call__(self, frames: np.ndarray, groups: PatternGroups, options: ProcessOptions) -> Any:
        return self.run(frames, groups, options)


DENOISERS: dict[str, Denoiser] = {
    entry.name: entry
    for entry in (
        Denoiser("none", _denoise_none, "the frames as captured"),
        Denoiser(
            "rpca",
            _denoise_rpca,
            "each frame's low-rank part by stable inexact-ALM RPCA, removing impulsive noise (thesis ch. 2.4)",
        ),
    )
}


def stage_denoise(state: SceneState, options: ProcessOptions) -> None:
    """Optional fringe denoising of the frames (``--denoise``)."""
    if options.denoise == "none":
        return
    assert state.frames is not None
    out = DENOISERS[options.denoise](state.frames, state.groups, options)
    state.frames, detail = out if isinstance(out, tuple) else (out, None)
    state.info["denoise"] = detail if detail is not None else options.denoise


def stage_phase(state: SceneState, options: ProcessOptions) -> None:
    """Absolute (or, for spatial methods, relative) phase at the highest frequency, from the frames.

    Three paths, each named in the report (``stage_info``):

    - phase-shifting groups only and a temporal method the fused float32 pass can run
      (:mod:`processing.unwrap.fused_pass`): wrapped phases, modulation mask and unwrapping in one visit
      of the frames (``fused_pass``);
    - otherwise the wrapped phase of every sinusoid group (phase shifting, or FTP for a single
      frame), then the unwrapping method of :mod:`rig.pipeline.unwrapping` (``phase_steps_s``: the
      seconds of each);
    - single-shot patterns: :data:`rig.pipeline.single_shot_phase.SINGLE_SHOT`, whose RPCA runs
      with single-threaded BLAS (``single_shot``).

    On the first two paths every phase-shifted frequency goes into the absolute phase, weighted by
    its predicted noise (:mod:`processing.phase.frequency_fusion`; ``frequency_fusion``), and the
    validity rule applies the predicted phase sigma (:func:`_bound_phase_sigma`; ``validity``).
    """
    assert state.frames is not None
    if state.groups.single_shot:
        # RPCA, FTP and scipy: loaded for single-shot captures only (rig process starts ~0.3 s sooner)
        from rig.pipeline.single_shot_phase import SINGLE_SHOT

        with rpca_blas():
            SINGLE_SHOT[state.groups.single_shot[0].kind](state, options)
        return
    if not _fused_pass(state, options):
        start = time.perf_counter()
        _wrapped_phases(state, options)
        wrapped = time.perf_counter()
        _unwrap(state, options)
        state.info["phase_steps_s"] = {
            "wrapped": round(wrapped - start, 4),
            "unwrap": round(time.perf_counter() - wrapped, 4),
        }
    _predict_phase_sigma(state)
    _bound_phase_sigma(state, options)


def _ratio_threshold_sigma(phase_sigma: np.ndarray, ratio: float) -> float:
    """The predicted phase sigma of a pixel whose modulation is ``ratio`` x the 99th percentile's.

    sigma is proportional to 1 / B, so the 1st percentile of sigma (over a regular subsample of
    about 16k pixels) belongs to the 99th percentile of B.
    """
    flat = phase_sigma.reshape(-1)[:: sample_stride(phase_sigma.shape)]
    flat = flat[np.isfinite(flat)]
    return percentile(flat, 1.0) / ratio if flat.size else 0.0  # flat: a fresh copy, reordered in place


def _predictable(state: SceneState) -> bool:
    """Whether the phase noise of this capture can be predicted: phase-shifted fringes along the axis."""
    along = state.groups.along(state.axis)
    return bool(along) and all(group.steps >= 3 for group in along)


def _bound_phase_sigma(state: SceneState, options: ProcessOptions) -> None:
    """The validity rule (report: ``validity``): under the noise rule, pixels whose predicted phase
    sigma is above the bound leave the mask (``above_max_phase_sigma``).

    The bound is ``max_phase_sigma``, or the phase sigma of a pixel at the modulation ratio's
    threshold (0.2 x the 99th percentile of B) where that is larger: the noise rule adds dark
    pixels with a clean phase and never drops what the ratio rule keeps in a noisy capture.
    """
    predictable = _predictable(state)
    rule = options.noise_rule(predictable)
    bound = options.max_phase_sigma if rule else None
    unwrapped = state.unwrapped
    if bound is not None and state.phase_sigma is not None:
        ratio = RATIO_RULE_RATIO if options.min_modulation_ratio is None else options.min_modulation_ratio
        bound = max(bound, _ratio_threshold_sigma(state.phase_sigma, ratio))
    state.info["validity"] = {
        "rule": "noise" if rule else "modulation ratio",
        "min_modulation_ratio": options.modulation_ratio(predictable),
        "max_phase_sigma_rad": None if bound is None else round(float(bound), 5),
        "max_sigma_mm": options.max_sigma,
    }
    if bound is None or state.phase_sigma is None or unwrapped is None:
        return
    above = unwrapped.valid & ~(state.phase_sigma <= np.float32(bound))
    state.info["above_max_phase_sigma"] = int(np.count_nonzero(above))
    if above.any():
        unwrapped.valid = unwrapped.valid & ~above
        np.copyto(unwrapped.phase, np.float32(np.nan), where=above)  # the stage's own array


def _predict_phase_sigma(state: SceneState) -> None:
    """Each pixel's phase sigma at the phase's frequency, unless the frequency fusion predicted it already.

    Only for phase-shifted captures whose highest frequency kept its modulation B (with a
    calibration, or stage by stage); :mod:`processing.geometry.uncertainty` holds the model.
    """
    along = state.groups.along(state.axis)
    wrapped = state.wrapped
    if state.phase_sigma is not None or state.frames is None or wrapped is None or not along:
        return
    if any(group.steps < 3 for group in along):
        return
    modulation = wrapped.modulation[-1] if wrapped.modulation else None
    if modulation is None:
        return
    state.phase_sigma = phase_sigma(modulation, _noise_sigma(state), along[-1].steps)


def _noise_sigma(state: SceneState) -> float:
    """The capture's camera noise sigma_I in grey levels (report: ``noise_sigma_grey``), estimated once.

    The highest phase-shifted frequency's fit residual alone: ~16k sampled pixels pin sigma_I within 1 %.
    """
    known = state.info.get("noise_sigma_grey")
    if known is not None:
        return float(known)
    assert state.frames is not None
    along = [g for g in state.groups.along(state.axis) if g.steps >= 3]
    fitted = [g for g in along if g.steps >= 4][-1:] or along
    fused = state.info.get("exposures")  # fused exposures: unit noise at every pixel by construction
    sigma_i = (
        float(fused["noise_sigma_grey"])
        if fused
        else noise_sigma(
            state.frames, [g.indices for g in fitted], [np.asarray(g.shifts) for g in fitted], axis=state.axis
        )
    )
    state.info["noise_sigma_grey"] = round(sigma_i, 4)
    return sigma_i


def _fusing(state: SceneState, options: ProcessOptions) -> bool:
    """Whether every frequency goes into the absolute phase: two or more phase-shifted ones along the
    axis, all of them phase-shifted, and ``--param frequency_fusion=false`` not given."""
    along = state.groups.along(state.axis)
    return (
        options.params.get("frequency_fusion", True) is not False
        and len(along) > 1
        and all(group.steps >= 3 for group in along)
    )


def _note_fusion(state: SceneState, frequencies: Sequence[float], disagreeing: int, valid: np.ndarray) -> None:
    """report.json's ``frequency_fusion`` entry (:mod:`processing.phase.frequency_fusion`)."""
    state.info["frequency_fusion"] = {
        "frequencies": [float(f) for f in frequencies],
        "rule": "inverse predicted phase variance, each frequency scaled to the highest's units",
        "disagreeing_pixels": int(disagreeing),
        "disagreeing_fraction": round(disagreeing / max(1, int(np.count_nonzero(valid))), 6),
        "off": "--param frequency_fusion=false",
    }


def _wrapped_phases(state: SceneState, options: ProcessOptions) -> None:
    """Wrapped phase of every sinusoid group along the fringe axis, and the valid-pixel mask."""
    assert state.frames is not None
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
        out.valid &= shadow_mask(amplitude, background, min_ratio=options.modulation_ratio(_predictable(state)))
    state.wrapped = out
    state.info["valid_after_modulation"] = float(out.valid.mean())
    _note_other_axis(state)


def _note_other_axis(state: SceneState) -> None:
    """Say which sinusoids along the other axis the phase stage left unused (none when both axes are processed)."""
    other = sorted({g.frequency for g in state.groups.sinusoids if g.axis != state.axis})
    if other and state.info.get("axis_choice", {}).get("axis") != "both":
        state.notes.append(f"sinusoids along the other axis (frequencies {other}) not used; choose them with --axis")


def _fusable_method(state: SceneState, options: ProcessOptions) -> UnwrapMethod | None:
    """The unwrapping method when the fused pass can run it on this capture, else None."""
    along = state.groups.along(state.axis)
    if not along or any(group.steps < 3 for group in along):
        return None
    try:
        name = options.unwrap if options.unwrap != "auto" else choose_unwrap(state.groups, state.axis)
    except ProcessingError:
        return None  # the stage-by-stage path reports it
    method = UNWRAPPERS.get(name)
    freqs = [group.frequency for group in along]
    if method is None or not method.fused or not _all_integers(freqs) or len(freqs) < method.frequencies:
        return None
    return method


def _fused_pass(state: SceneState, options: ProcessOptions) -> bool:
    """Wrapped phases, mask and temporal unwrapping in one pass, when the capture allows it; False if not."""
    method = _fusable_method(state, options)
    if method is None:
        return False
    along = state.groups.along(state.axis)
    freqs = [group.frequency for group in along]
    max_residual = float(options.params.get("max_residual", np.pi / 2))  # e.g. 3.14 for drifting beats
    check = method.name == "heterodyne" and convention_check.enabled(options)
    assert state.frames is not None
    frames, groups, shifts = state.frames, [group.indices for group in along], [np.asarray(g.shifts) for g in along]
    ratio = options.modulation_ratio(True)  # the pass runs on phase-shifted fringes only
    fusing = _fusing(state, options)
    try:
        # the subsamples' and the blocks' small products (a few rows by 16k-64k pixels): a second BLAS
        # thread only synchronises (the noise fit's: 4-8 ms with two threads beside a busy core, 0.1 with one)
        with kernel_blas():
            # the mask's thresholds and the noise (both from subsamples) are independent: side by side
            thresholds, fuse = concurrency.side_by_side(
                lambda: modulation_thresholds(frames, groups, shifts, ratio),
                lambda: _noise_sigma(state) if fusing else None,
            )
            scan = fringe_pass(
                frames,
                groups,
                freqs,
                method.name,
                shifts=shifts,
                min_ratio=ratio,
                thresholds=thresholds,
                max_residual=max_residual,
                # auto weighs its order changes against the lower frequencies' wrapped phases
                keep_all=state.calibration is None or check or options.correction == "auto",
                orders=False,  # the corrections re-derive orders from the phases; nothing else reads them
                # A + B, the texture, instead of A and B apart (one map fewer) unless B is wanted for sigma:
                # the fusion predicts it; without fusion the uncertainty (calibrated) or the noise rule read B
                brightness=fuse is not None or (state.calibration is None and not options.noise_rule(True)),
                fuse_noise=fuse,
                threads=concurrency.THREADS,  # the blocks on both cores (1 in rig's batch workers)
            )
    except ValueError:
        return False  # e.g. frequencies the method refuses: the stage-by-stage path reports it as before
    _keep_fused(state, options, scan, freqs, method.name, check)
    if scan.sigma is not None:
        assert state.unwrapped is not None  # _keep_fused set it
        state.phase_sigma = scan.sigma
        state.unwrapped.fused = True
        _note_fusion(state, freqs, scan.disagreeing, scan.valid)
    state.info["fused_pass"] = "phase shifting, modulation mask and unwrapping in one float32 pass"
    _note_other_axis(state)
    return True


def _keep_fused(
    state: SceneState, options: ProcessOptions, scan: FringePass, freqs: list[float], method: str, check: bool
) -> None:
    """The fused pass's maps as the state's wrapped and unwrapped phase (rejected pixels rescued or NaN)."""
    maps = {index: slot for slot, index in enumerate(scan.kept)}

    def kept(values: list[np.ndarray]) -> list[np.ndarray | None]:
        return [values[maps[i]] if i in maps and values else None for i in range(len(freqs))]

    state.wrapped = WrappedPhase(
        freqs, kept(scan.wrapped), kept(scan.modulation), kept(scan.background), scan.modulated, kept(scan.brightness)
    )
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


def _ftp_frame(image: np.ndarray, axis: str, shift: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wrapped phase, amplitude and background of a single fringe frame (Fourier transform profilometry).

    The background is the mean over one fringe period along the axis (the detected carrier).
    """
    from processing.phase.ftp import detect_carrier, fringe_background, ftp_phase  # scipy.fft: single frames only

    img = np.asarray(image, dtype=np.float64)
    along = 1 if axis == "x" else 0
    phase, amplitude = ftp_phase(img, axis=along)
    phase = np.angle(np.exp(1j * (phase - shift)))
    background = fringe_background(img, detect_carrier(img, along), along)
    return phase, np.asarray(amplitude, dtype=np.float64), background


def _gray_threshold(state: SceneState) -> np.ndarray | None:
    """Per-pixel threshold for Gray planes: mid of white and black flat frames if captured, else the fringe mean A.

    The sinusoid's mean A is the mid-level of a pixel lit by a full and a dark projector pixel,
    whatever the pixel's reflectivity: it holds on dark surfaces, where one image-wide level
    would read every bit as 0. None (decode_gray's own level) when neither is at hand.
    """
    assert state.frames is not None
    levels = {level: index for index, level in state.groups.flats}
    if 1.0 in levels and 0.0 in levels:
        return (state.frames[levels[1.0]].astype(np.float64) + state.frames[levels[0.0]]) / 2.0
    wrapped = state.wrapped
    background = wrapped.background[-1] if wrapped is not None and wrapped.background else None
    return None if background is None else np.asarray(background, dtype=np.float64)


def _gray_planes(state: SceneState) -> GrayPlanes:
    """The capture's code planes (Gray or binary) along the fringe axis (ProcessingError when it has none)."""
    gray = state.groups.gray.get(state.axis)
    if gray is None:
        raise ProcessingError(f"--unwrap gray: the capture has no Gray- or binary-code planes along {state.axis}")
    assert state.frames is not None
    width, height = state.capture.projector_size
    extent = float(width if state.axis == "x" else height)
    cell = None
    if gray.period_px is not None:
        covered = float(gray.period_px) * (1 << gray.bits)
        if covered < extent:
            raise ProcessingError(
                f"{state.capture.manifest_path}: {gray.code} code along {state.axis}: {1 << gray.bits} cells of "
                f"{gray.period_px:g} px cover {covered:g} px; expected at least the projector's {extent:g} px"
            )
        cell = float(gray.period_px) / extent
    planes = state.frames[[gray.planes[b] for b in range(gray.bits)]]
    inverted = state.frames[[gray.inverted[b] for b in range(gray.bits)]] if gray.inverted else None
    threshold = None if inverted is not None else _gray_threshold(state)
    return GrayPlanes(planes, inverted, threshold, gray.bits, gray.binary, cell, gray.period_px)


def _unwrap_inputs(state: SceneState, options: ProcessOptions, method: UnwrapMethod) -> UnwrapInputs:
    """What ``method`` declared it needs, from the wrapped phases and pattern groups (ProcessingError if missing)."""
    wrapped = state.wrapped
    assert wrapped is not None
    freqs = wrapped.frequencies
    phis = [p for p in wrapped.phase if p is not None]  # all of them: only the fused pass leaves some out
    assert len(phis) == len(freqs)
    need = method.frequencies
    if len(freqs) < need:
        raise ProcessingError(
            f"--unwrap {method.name}: needs at least {need} sinusoid frequencies, the capture has {freqs}"
        )
    if method.whole and not _all_integers(freqs):
        raise ProcessingError(f"--unwrap {method.name}: frequencies must be whole fringe counts, found {freqs}")
    use = slice(None) if method.all_frequencies else slice(-need, None)
    return UnwrapInputs(
        phases=phis[use],
        frequencies=[int(f) for f in freqs[use]] if method.whole else list(freqs[use]),
        valid=wrapped.valid,
        params=options.params,
        check_convention=functools.partial(_check_convention, state, options),
        gray=_gray_planes(state) if "gray" in method.needs else None,
        info=state.info,
    )


def _unwrap(state: SceneState, options: ProcessOptions) -> None:
    """The state's wrapped phases unwrapped by the requested (or automatically chosen) method."""
    wrapped = state.wrapped
    assert wrapped is not None
    name = options.unwrap if options.unwrap != "auto" else choose_unwrap(state.groups, state.axis)
    method = UNWRAPPERS.get(name)
    if method is None:
        raise ProcessingError(f"--unwrap: expected one of {', '.join(UNWRAP_METHODS)}, found {name!r}")
    result = method(_unwrap_inputs(state, options, method))
    phase = np.asarray(result.phase)
    mask = wrapped.valid & np.isfinite(phase)
    mask &= np.asarray(result.valid, dtype=bool)
    if method.rescue and options.params.get("neighbour_rescue", True) is not False:
        mask = _rescue_rejected(state, phase, mask, wrapped.valid)
    state.unwrapped = UnwrappedPhase(
        phase=np.where(mask, phase, np.nan),
        valid=mask,
        frequency=wrapped.frequencies[-1],
        method=method.name,
        absolute=result.absolute,
        orders=result.orders,
    )
    if result.absolute and _fusing(state, options):
        _fuse_stage_by_stage(state)


def _fuse_stage_by_stage(state: SceneState) -> None:
    """Every frequency's wrapped phase into the unwrapped phase (the stage-by-stage twin of the fused pass's)."""
    wrapped, unwrapped = state.wrapped, state.unwrapped
    assert wrapped is not None and unwrapped is not None
    maps = [wrapped.phase, wrapped.modulation]
    if any(m is None for group in maps for m in group):
        return
    along = state.groups.along(state.axis)
    fused = fuse_frequencies(
        unwrapped.phase,
        [p for p in wrapped.phase if p is not None],
        wrapped.frequencies,
        [m for m in wrapped.modulation if m is not None],
        [group.steps for group in along],
        _noise_sigma(state),
    )
    unwrapped.phase = fused.phase
    unwrapped.fused = True
    state.phase_sigma = fused.sigma
    _note_fusion(state, wrapped.frequencies, fused.disagreeing, unwrapped.valid)


def _rescue_rejected(
    state: SceneState, phase: np.ndarray, mask: np.ndarray, modulated: np.ndarray, rejected: bool | None = None
) -> np.ndarray:
    """Take back modulated pixels a temporal residual test rejected where neighbours vouch for their phase.

    ``rejected``: whether any modulated pixel is outside ``mask``, when the caller knows.
    """
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
    freqs: Sequence[float],
    stripes: np.ndarray | None = None,
    bits: int = 0,
    cell_periods: float | None = None,
) -> None:
    """Refuse images whose phase convention differs from the capture's (:mod:`rig.pipeline.convention_check`)."""
    if not convention_check.enabled(options):
        return
    assert state.wrapped is not None
    if evidence == "gray":
        assert stripes is not None
        estimate = gray_offset(maps[0], stripes, bits, freqs[0], state.wrapped.valid, state.axis, cell_periods)
        text = "the Gray-code period boundaries fall mid-period instead of at the phase wrap"
    else:
        estimate = heterodyne_offset(maps, [int(f) for f in freqs], state.wrapped.valid)
        text = "the heterodyne residuals are far above the noise (the beats disagree with the finest phase)"
    state.info["phase_convention_offset_rad"] = estimate.offset
    convention_check.check(estimate, text, state.capture, state.capture.patterns, str(state.capture.manifest_path))


# The stages of one capture, by what each does: decode the frames, remove lens distortion, denoise
# the fringes, compute the (absolute) phase, correct it. run.process times each for report.json.
SCENE_STAGES: list[tuple[str, Callable[[SceneState, ProcessOptions], None]]] = [
    ("load", stage_load),
    ("undistort", stage_undistort),
    ("denoise", stage_denoise),
    ("phase", stage_phase),
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
        from processing.unwrap.spatial import remove_region_offsets  # scipy: only spatial unwrapping pays for it

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
