"""The correction stage and the one registry of corrections ``rig process --correction`` offers.

The registry holds typed entries (:class:`processing.correction.method.CorrectionMethod`): the
numeric methods of :mod:`processing.correction.registry` and the calibration-backed ``gamma-table``
(:mod:`rig.pipeline.gamma_correction`). An entry's ``needs`` names what it takes beyond the
phase pair; the stage fetches it from the calibration (``phase_error``) and refuses clearly when
it is missing.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from calibration.errors import CalibrationError
from calibration.store import Calibration
from processing.angles import wrap_to_pi
from processing.correction.method import CorrectionMethod
from processing.correction.registry import CORRECTIONS as NUMERIC_CORRECTIONS
from processing.correction.sampling import fringe_step_rad, undersampled_for_spatial_methods
from processing.geometry.uncertainty import correction_gain
from rig.errors import ProcessingError
from rig.pipeline.gamma_correction import GAMMA_TABLE
from rig.pipeline.plan import ProcessOptions, accepted_params
from rig.pipeline.state import SceneState

REGISTRY: dict[str, CorrectionMethod] = {**NUMERIC_CORRECTIONS, GAMMA_TABLE.name: GAMMA_TABLE}


def help_text() -> str:
    """One line per correction for ``--help``."""
    return "; ".join(f"{m.name}: {m.description}" for m in REGISTRY.values())


def method_params(method: CorrectionMethod, params: Mapping[str, Any]) -> dict[str, Any]:
    """The ``--param`` entries that the method's function takes as keyword arguments (not what it ``needs``)."""
    return {key: value for key, value in accepted_params(method.run, params).items() if key not in method.needs}


def needed_inputs(method: CorrectionMethod, calibration: Calibration | None) -> dict[str, Any]:
    """What ``method.needs``, taken from the calibration; CalibrationError naming what is missing."""
    inputs: dict[str, Any] = {}
    for need in method.needs:
        if calibration is None:
            raise CalibrationError(f"--correction {method.name}: needs --calibration (its {need} table)")
        value = calibration.extra.get(need)
        if not isinstance(value, dict):
            raise CalibrationError(f"{calibration.where}: {need}: missing (recalibrate with rig calibrate, or --from)")
        inputs[need] = value
    return inputs


def stage_correction(state: SceneState, options: ProcessOptions) -> None:
    """Optional correction of the unwrapped phase (``--correction``); the method's info goes to the report."""
    if options.correction == "none":
        return
    method = REGISTRY[options.correction]
    unwrapped = state.unwrapped
    assert unwrapped is not None
    if method.name == "auto" and not unwrapped.absolute:
        state.info["correction"] = {
            "method": "auto",
            "skipped": "relative phase (spatial unwrapping): nothing to correct",
        }
        return
    if _too_dense_for_spatial_methods(state, method.name):
        return
    inputs = needed_inputs(method, state.calibration)
    wrapped = None
    # a fused phase is no longer the highest frequency's wrapped phase + 2 pi k: its own wrap is
    if not unwrapped.fused and state.wrapped is not None and unwrapped.frequency in state.wrapped.frequencies:
        wrapped = state.wrapped.phase[state.wrapped.frequencies.index(unwrapped.frequency)]
    if wrapped is None or not np.isfinite(wrapped[unwrapped.valid]).all():
        wrapped = wrap_to_pi(np.nan_to_num(unwrapped.phase))  # Phi = phi + 2 pi k wraps back to phi
    if method.name == "auto":
        inputs["lower_wrapped"] = _lower_wrapped(state)
    try:
        phase, info = method(
            unwrapped.phase,
            wrapped,
            orders=unwrapped.orders,
            mask=unwrapped.valid,
            frequency=unwrapped.frequency,
            **method_params(method, options.params),
            **inputs,
        )
    except CalibrationError as exc:
        where = state.calibration.where if state.calibration is not None else "--calibration"
        raise CalibrationError(f"{where}: {exc}") from None
    except ValueError as exc:
        raise ProcessingError(f"--correction {method.name}: {exc}") from None
    if state.phase_sigma is not None:  # the noise the correction took away no longer counts
        gain = correction_gain(unwrapped.phase, phase, state.phase_sigma, unwrapped.valid)
        state.phase_sigma = state.phase_sigma * np.float32(gain)
        state.info["correction_noise_gain"] = round(gain, 4)
    unwrapped.phase = phase
    state.unresolved = info.pop("unresolved_mask", None)  # an array: the result's unresolved.npy, not the report
    if unwrapped.orders is not None:
        orders = np.rint((np.nan_to_num(phase) - np.mod(wrapped, 2.0 * np.pi)) / (2.0 * np.pi))
        unwrapped.orders = np.where(unwrapped.valid, orders, unwrapped.orders).astype(unwrapped.orders.dtype)
    state.info["correction"] = info
    _note_unresolved(state, info)


def _lower_wrapped(state: SceneState) -> list[tuple[float, np.ndarray]]:
    """(frequency, wrapped phase) of every frequency below the unwrapped one that the capture kept: the
    temporal evidence ``auto`` weighs its order changes against (none after spatial unwrapping)."""
    unwrapped, wrapped = state.unwrapped, state.wrapped
    if unwrapped is None or wrapped is None or not unwrapped.absolute:
        return []
    return [
        (float(f), phase)
        for f, phase in zip(wrapped.frequencies, wrapped.phase)
        if phase is not None and 0 < float(f) < float(unwrapped.frequency)
    ]


def _note_unresolved(state: SceneState, info: dict[str, Any]) -> None:
    """A note naming how much of the map has fringe orders no evidence could settle (``info["unresolved"]``)."""
    unresolved = info.get("unresolved")
    if not unresolved or not unresolved.get("pixels"):
        return
    regions = unresolved.get("regions") or []
    where = (
        f"; largest at rows {regions[0][0]}..{regions[0][2]}, columns {regions[0][1]}..{regions[0][3]}"
        if regions
        else ""
    )
    state.notes.append(
        f"--correction {info.get('method')}: fringe orders unresolved on {unresolved['fraction']:.2%} of the "
        f"{state.name} ({unresolved['pixels']} pixels in {len(regions)}{'+' if len(regions) >= 20 else ''} regions{where}): "
        "the measured orders are kept there; see report.json stage_info"
    )


def _too_dense_for_spatial_methods(state: SceneState, name: str) -> bool:
    """Fringes below 2.5 px per period: ``auto`` is skipped (it would make the result worse); an
    explicitly requested method runs with a note saying why its result cannot be trusted."""
    unwrapped = state.unwrapped
    assert unwrapped is not None
    if not unwrapped.absolute:
        return False
    step = fringe_step_rad(unwrapped.phase, unwrapped.valid, axis=1 if state.axis == "x" else 0)
    if not undersampled_for_spatial_methods(step):
        return False
    why = (
        f"fringes {2 * np.pi / step:.1f} px apart at frequency {unwrapped.frequency:g}: too dense for corrections "
        "that compare neighbouring pixels (they need more than 2.5 px per fringe)"
    )
    if name == "auto":
        state.info["correction"] = {"method": "auto", "skipped": why}
        state.notes.append(f"--correction auto skipped: {why}; the temporally unwrapped phase is kept")
        return True
    state.notes.append(f"--correction {name}: {why}; its result is unreliable")
    return False
