"""The phase of a single-shot capture: ``speckle-sinusoid`` frames (thesis ch. 2.3) through :mod:`processing.single_shot`.

The calibration's reference capture (same pattern, processed first) is separated by RPCA and
phased by FTP once (:func:`processing.single_shot.prepare_reference`); its absolute phase is its
FTP phase unwrapped along the rows with the smallest fringe order 0: a flat plane has no
discontinuity, and the projector column of the reference's first order is fixed only by the rig's
geometry, which the reference-plane and polynomial models do not need (they use object minus
reference). The object frame then gets its fringe orders from the reference speckle
(:func:`processing.single_shot.single_shot_unwrap`), so both phases share that offset. The result
fills ``state.wrapped`` / ``state.unwrapped`` for the correction and height stages; method,
parameters, RPCA iterations and rank and the time of each step go to the report.
"""

from __future__ import annotations

import dataclasses
import inspect
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from processing.ftp import FringeParts, ftp_fringe_parts
from processing.single_shot import (
    SingleShotReference,
    prepare_reference,
    separate_fringe_speckle,
    single_shot_unwrap,
)
from rig.errors import ProcessingError
from rig.pipeline.plan import TWO_PI, ProcessOptions, SinusoidGroup, accepted_params
from rig.pipeline.state import SceneState, UnwrappedPhase, WrappedPhase

# Arguments of processing.single_shot.single_shot_unwrap that the pipeline supplies itself.
_SINGLE_SHOT_OWN = ("image", "reference_image", "reference_absolute_phase", "frequency", "axis", "mask")

METHOD = (
    "speckle-embedded single shot (RPCA fringe/speckle separation, FTP, speckle NCC fringe orders, row voting, "
    "2-D fringe-segment vote)"
)


@dataclass
class _Shot:
    """The frame to phase and how: its pattern group, the image axis across the fringes, the
    ``--param`` entries given and every setting with its default."""

    image: np.ndarray
    group: SinusoidGroup
    axis: int
    given: dict[str, Any]
    settings: dict[str, Any]


@dataclass
class _Phased:
    """What either role (reference or object) computed: FTP parts, absolute phase, orders, RPCA, step times."""

    parts: FringeParts
    valid: np.ndarray
    absolute: np.ndarray
    orders: np.ndarray
    rpca: Any
    timings: dict[str, float]


def _single_shot_parameters(options: ProcessOptions) -> tuple[dict[str, Any], dict[str, Any]]:
    """(``--param`` entries single_shot_unwrap takes, all its settings with defaults) for the report."""
    given = {k: v for k, v in accepted_params(single_shot_unwrap, options.params).items() if k not in _SINGLE_SHOT_OWN}
    defaults = {
        name: p.default
        for name, p in inspect.signature(single_shot_unwrap).parameters.items()
        if p.kind is inspect.Parameter.KEYWORD_ONLY and name not in _SINGLE_SHOT_OWN
    }
    return given, {**defaults, **given}


def _check_request(state: SceneState, options: ProcessOptions, group: SinusoidGroup) -> None:
    """Notes for what the single shot leaves unused; refuse a denoiser that would remove the speckle."""
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


def _prepare_reference(
    image: np.ndarray, frequency: float, axis: int, given: dict[str, Any], settings: dict[str, Any]
) -> tuple[SingleShotReference, Any]:
    """The reference's fringe, speckle and absolute phase, and RPCA's result when it separated them."""
    ftp = {k: v for k, v in given.items() if k in ("carrier", "bandwidth")}
    if not settings["separate"]:
        return prepare_reference(image, None, frequency, axis=axis, separate=False, **ftp), None
    # Separate here (not inside prepare_reference) to keep RPCA's iterations and rank for the report.
    fringe, speckle, rpca = separate_fringe_speckle(
        image, tau=settings["tau"], tol=settings["rpca_tol"], svd=settings["svd"]
    )
    prepared = prepare_reference(fringe, None, frequency, axis=axis, separate=False, **ftp)
    return dataclasses.replace(prepared, speckle=speckle), rpca


def _phase_reference(state: SceneState, shot: _Shot) -> _Phased:
    """The reference plane: prepared once for the objects (kept in the state), its FTP phase made absolute."""
    if state.name != "reference":
        raise ProcessingError(
            f"{state.capture.manifest_path}: a speckle-sinusoid (single-shot) capture takes its fringe orders from a "
            "reference-plane capture under the same pattern: give a --calibration whose reference capture has it "
            "(rig calibrate itself needs phase-shifting patterns)"
        )
    start = time.perf_counter()
    image, group, axis, settings = shot.image, shot.group, shot.axis, shot.settings
    prepared, rpca = _prepare_reference(image, group.frequency, axis, shot.given, settings)
    prepared.seconds = time.perf_counter() - start
    state.single_shot_reference = prepared
    parts = ftp_fringe_parts(prepared.fringe, prepared.carrier, axis, settings["bandwidth"], settings["min_modulation"])
    absolute = prepared.absolute_phase
    orders = np.where(parts.valid, np.rint((absolute - prepared.wrapped_phase) / TWO_PI), -1).astype(np.int64)
    return _Phased(parts, parts.valid, absolute, orders, rpca, {"reference": prepared.seconds})


def _phase_object(state: SceneState, shot: _Shot) -> _Phased:
    """An object: fringe orders from the reference speckle (the reference's preparation is reported there)."""
    assert state.reference is not None
    prepared = state.reference.single_shot_reference
    if prepared is None:
        raise ProcessingError(
            f"{state.capture.manifest_path}: the reference capture is not a speckle-sinusoid single shot like this capture"
        )
    axis, settings = shot.axis, shot.settings
    result = single_shot_unwrap(shot.image, prepared, None, shot.group.frequency, axis=axis, **shot.given)
    parts = ftp_fringe_parts(result.fringe, prepared.carrier, axis, settings["bandwidth"], settings["min_modulation"])
    valid = result.mask & np.isfinite(result.absolute_phase)
    timings = dict(result.timings)
    timings.pop("reference", None)  # prepared with the reference capture, reported there
    state.info["single_shot_correlation_median"] = float(np.median(result.correlation[valid])) if valid.any() else None
    return _Phased(parts, valid, result.absolute_phase, result.orders, result.rpca, timings)


def _record(
    state: SceneState, group: SinusoidGroup, phased: _Phased, parameters: dict[str, Any], seconds: float
) -> None:
    """Fill the state's wrapped and unwrapped phase and the report's single-shot entry."""
    parts, valid, rpca = phased.parts, phased.valid, phased.rpca
    state.wrapped = WrappedPhase([group.frequency], [parts.phase], [parts.amplitude], [parts.background], valid)
    state.unwrapped = UnwrappedPhase(
        phase=np.where(valid, phased.absolute, np.nan),
        valid=valid,
        frequency=group.frequency,
        method="single-shot",
        absolute=True,
        orders=phased.orders,
    )
    state.info["valid_after_modulation"] = float(valid.mean())
    state.info["single_shot"] = {
        "method": METHOD,
        "role": "reference" if state.reference is None else "object",
        "parameters": parameters,
        "iterations": None if rpca is None else int(rpca.iterations),
        "rank": None if rpca is None else int(rpca.rank),
        "seconds": round(seconds, 4),
        "timings_s": {k: round(float(v), 4) for k, v in phased.timings.items()},
    }
    if state.reference is not None:
        state.notes.append(
            "single-shot: the reference plane's absolute phase is its FTP phase unwrapped along the rows with "
            "smallest fringe order 0; object phases share that offset, which object - reference cancels"
        )


def speckle_single_shot(state: SceneState, options: ProcessOptions) -> None:
    """Wrapped and absolute phase of a ``speckle-sinusoid`` capture, as the reference or as an object."""
    group = state.groups.single_shot[0]
    assert state.frames is not None
    image = state.frames[group.indices[0]].astype(np.float32)
    _check_request(state, options, group)
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
    phase = _phase_reference if state.reference is None else _phase_object
    try:
        phased = phase(state, _Shot(image, group, axis, given, settings))
    except ValueError as exc:
        raise ProcessingError(f"{state.capture.manifest_path}: single-shot: {exc}") from None
    _record(state, group, phased, parameters, time.perf_counter() - start)


# Single-shot pattern kind -> f(state, options) filling state.wrapped and state.unwrapped.
SINGLE_SHOT: dict[str, Callable[[SceneState, ProcessOptions], None]] = {"speckle-sinusoid": speckle_single_shot}
