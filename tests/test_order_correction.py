"""Fringe order correction by RPCA on the order map (thesis ch. 3), on the seeded Table 4.1 protocol."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.correction_protocol import ProtocolCase, table41_case
from processing.correction.orders import correct_orders_rpca, monotonic_rows, postprocess_orders

TWO_PI = 2.0 * np.pi


@pytest.fixture(scope="module")
def case() -> ProtocolCase:
    """Sphere cap, f = (5, 8), 6 steps, 15 dB at 128 x 128: about 1% wrong fringe orders."""
    return table41_case(128, 128, snr_db=15.0, seed=0)


def orders_of(maps) -> np.ndarray:
    return np.where(maps.mask, np.rint((maps.absolute - np.mod(maps.wrapped, TWO_PI)) / TWO_PI), 0)


def corrected_nmse(case: ProtocolCase, **kwargs) -> float:
    phases = [correct_orders_rpca(orders_of(m), m.wrapped, m.mask, **kwargs)[0] for m in (case.object, case.reference)]
    return case.nmse_h(*phases)


def test_case_has_order_errors(case: ProtocolCase) -> None:
    assert case.object.order_errors() > 50 and case.reference.order_errors() > 50
    assert case.nmse_h(case.object.absolute, case.reference.absolute) > 1.0


def test_rpca_orders_with_postprocessing_reaches_the_true_orders(case: ProtocolCase) -> None:
    oracle = case.nmse_h(case.object.oracle(), case.reference.oracle())
    assert corrected_nmse(case) == pytest.approx(oracle, rel=1e-9)


def test_postprocessing_removes_the_misalignment_left_by_rpca(case: ProtocolCase) -> None:
    # Thesis Table 4.1: 0.2959 without, 0.0057 with post-processing.
    without = corrected_nmse(case, postprocess=False)
    with_post = corrected_nmse(case)
    none = case.nmse_h(case.object.absolute, case.reference.absolute)
    assert with_post < without / 10
    assert without < none


def test_postprocessing_the_unprocessed_result_equals_postprocess_true(case: ProtocolCase) -> None:
    # The study reports ch. 3 with and without post-processing from one RPCA solve this way.
    m = case.object
    without, _, _ = correct_orders_rpca(orders_of(m), m.wrapped, m.mask, postprocess=False)
    with_post, _, _ = correct_orders_rpca(orders_of(m), m.wrapped, m.mask)
    assert np.count_nonzero(np.abs(without - with_post) > np.pi) > 0  # the pass changes something
    np.testing.assert_array_equal(postprocess_orders(without, np.isfinite(without)), with_post)


def test_adm_solver_and_ialm_solver_agree_after_postprocessing(case: ProtocolCase) -> None:
    m = case.object
    ialm, k_ialm, r_ialm = correct_orders_rpca(orders_of(m), m.wrapped, m.mask)
    adm, k_adm, r_adm = correct_orders_rpca(orders_of(m), m.wrapped, m.mask, solver="adm")
    np.testing.assert_array_equal(k_ialm, k_adm)
    assert r_ialm.iterations < r_adm.iterations


def test_corrected_orders_follow_the_temporal_convention(case: ProtocolCase) -> None:
    m = case.object
    phase, orders, _ = correct_orders_rpca(m.orders, m.wrapped, m.mask)
    np.testing.assert_allclose(phase[m.mask], np.mod(m.wrapped, TWO_PI)[m.mask] + TWO_PI * orders[m.mask])


def sequential_pass(phase: np.ndarray) -> np.ndarray:
    """The thesis' pass written as the pixel loop it describes (reference for the vectorised one)."""
    out = phase.copy()
    for row in out:
        for x in range(len(row) - 1):
            step = row[x + 1] - row[x]
            if abs(step) > np.pi:
                row[x + 1] -= TWO_PI * np.round(step / TWO_PI)
    return out


def test_monotonic_rows_equals_the_sequential_pass() -> None:
    rng = np.random.default_rng(3)
    truth = np.cumsum(rng.uniform(0.0, 0.5, (6, 40)), axis=1)
    phase = truth + TWO_PI * rng.integers(-2, 3, truth.shape) * (rng.random(truth.shape) < 0.2)
    np.testing.assert_allclose(monotonic_rows(phase), sequential_pass(phase))


def test_anchored_pass_survives_a_wrong_first_pixel_and_shadows() -> None:
    truth = np.tile(np.linspace(0.0, 30.0, 60), (3, 1))
    phase = truth.copy()
    phase[:, 0] += TWO_PI  # the sequential pass trusts this pixel and shifts the whole row
    valid = np.ones(truth.shape, dtype=bool)
    valid[:, 30:33] = False
    phase[:, 33:] += TWO_PI * 3  # after a shadow, a wrong offset the anchor knows better
    anchor = truth + 0.1
    out = monotonic_rows(phase, anchor=anchor, valid=valid)
    np.testing.assert_allclose(out[valid], truth[valid], atol=1e-9)
    assert not np.allclose(sequential_pass(phase)[:, 1:30], truth[:, 1:30])


@pytest.mark.parametrize(
    ("args", "kwargs", "name"),
    [
        ((np.zeros((8, 8)), np.zeros((8, 9))), {}, "wrapped_phase"),
        ((np.zeros((8, 8)), np.zeros((8, 8))), {"mask": np.zeros((8, 8), dtype=bool)}, "mask"),
        ((np.full((8, 8), np.nan), np.zeros((8, 8))), {"mask": np.ones((8, 8), dtype=bool)}, "orders"),
        ((np.zeros(8), np.zeros(8)), {}, "orders"),
        ((np.zeros((8, 8)), np.zeros((8, 8))), {"t": 0.0}, "t"),
        ((np.zeros((8, 8)), np.zeros((8, 8))), {"solver": "pcp"}, "solver"),
    ],
)
def test_bad_input_names_the_argument(args: tuple, kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=f"^{name}:"):
        correct_orders_rpca(*args, **kwargs)
