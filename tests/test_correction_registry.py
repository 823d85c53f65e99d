"""One correction registry with typed entries (issue 9): what --correction offers and what each needs."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.errors import CalibrationError
from processing.correction.method import CorrectionMethod
from processing.correction.registry import CORRECTIONS as NUMERIC
from rig.pipeline.corrections import REGISTRY, help_text, needed_inputs


def test_registry_is_the_numeric_methods_plus_the_calibration_backed_one() -> None:
    assert all(isinstance(m, CorrectionMethod) and m.description for m in REGISTRY.values())
    assert {name: m for name, m in REGISTRY.items() if name in NUMERIC} == NUMERIC
    assert set(REGISTRY) - set(NUMERIC) == {"gamma-table"}
    assert REGISTRY["gamma-table"].needs == ("phase_error",)
    assert all(not m.needs for m in NUMERIC.values())
    assert all(f"{name}: " in help_text() for name in REGISTRY)


def test_a_needed_input_missing_from_the_calibration_is_named() -> None:
    with pytest.raises(CalibrationError, match="--correction gamma-table: needs --calibration"):
        needed_inputs(REGISTRY["gamma-table"], None)
    assert needed_inputs(REGISTRY["vote"], None) == {}


def test_gamma_table_subtracts_the_tabulated_ripple() -> None:
    centers = np.linspace(0, 2 * np.pi, 32, endpoint=False) + np.pi / 32
    fields = {
        "phase_error_centers": centers.tolist(),
        "phase_error_rad": (0.05 * np.sin(3 * centers)).tolist(),
        "frequency": 8,
    }
    truth = np.linspace(0.1, 40.0, 600).reshape(20, 30)
    measured = truth + 0.05 * np.sin(3 * np.mod(truth, 2 * np.pi))
    phase, info = REGISTRY["gamma-table"](measured, np.mod(measured, 2 * np.pi), frequency=8, phase_error=fields)
    # the 0.05 rad ripple down to its second-order rest (the table is read at the measured phase: <= 3 * 0.05**2)
    assert np.max(np.abs(phase - truth)) < 3 * 0.05**2
    assert np.max(np.abs(measured - truth)) > 0.04
    assert info["method"] == "gamma-table" and info["table_rms_rad"] == pytest.approx(0.05 / np.sqrt(2), rel=0.05)
    with pytest.raises(CalibrationError, match="learnt at 8 fringes, the capture's phase is at 5"):
        REGISTRY["gamma-table"](measured, measured, frequency=5, phase_error=fields)
