"""`rig process --correction gamma-table`: remove the projector-gamma phase ripple in processing.

For captures whose projector could not be pre-corrected (see :mod:`calibration.gamma`): the
calibration's ``phase_error`` table (learnt by ``rig calibrate`` on the reference plane: mean
wrapped-phase error per phase bin against a smooth fit) is subtracted from the absolute phase of
the object and of the reference, both at the table's frequency.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from calibration.errors import CalibrationError
from calibration.gamma import compensate_phase, table_from_fields
from processing.correction.method import CorrectionMethod, Result

NAME = "gamma-table"


def correct_gamma_ripple(
    absolute_phase: np.ndarray,
    wrapped_phase: np.ndarray,
    orders: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    frequency: float | None = None,
    *,
    phase_error: Mapping[str, Any],
) -> Result:
    """``absolute_phase`` minus the ripple tabulated in a calibration's ``phase_error`` fields.

    ``phase_error`` must have been learnt at ``frequency`` (when it records one).
    """
    start = time.perf_counter()
    table = table_from_fields(dict(phase_error))
    learnt = float(phase_error.get("frequency", frequency if frequency is not None else np.nan))
    if frequency is not None and learnt != frequency:
        raise CalibrationError(f"phase_error: learnt at {learnt:g} fringes, the capture's phase is at {frequency:g}")
    phase = np.asarray(absolute_phase, dtype=np.float64)
    out = np.where(np.isfinite(phase), compensate_phase(phase, table), np.nan)
    if mask is not None:
        out = np.where(np.asarray(mask, dtype=bool), out, np.nan)
    info: dict[str, Any] = {
        "method": NAME,
        "parameters": {"bins": int(table.error.size)},
        "iterations": 0,
        "rank": None,
        "seconds": round(time.perf_counter() - start, 4),
        "table_rms_rad": float(np.sqrt(np.mean(table.error**2))),
    }
    if frequency is not None:
        info["frequency"] = float(frequency)
    return out, info


GAMMA_TABLE = CorrectionMethod(
    NAME,
    correct_gamma_ripple,
    "subtract the projector-gamma phase ripple the calibration tabulated (needs --calibration)",
    needs=("phase_error",),
)
