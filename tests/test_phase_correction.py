"""Absolute phase correction by RPCA (thesis ch. 4), order re-derivation, and the correction registry."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.correction_protocol import ProtocolCase, table41_case
from processing.correction.phase_rpca import (
    correct_phase_rpca,
    keep_coherent_detail,
    reorder_from_low_rank,
    restore_detail,
    update_coherent_detail,
)
from processing.correction.registry import CORRECTIONS, correct

TWO_PI = 2.0 * np.pi


@pytest.fixture(scope="module")
def case() -> ProtocolCase:
    """Sphere cap, f = (5, 8), 6 steps, 15 dB at 128 x 128: about 1% wrong fringe orders."""
    return table41_case(128, 128, snr_db=15.0, seed=0)


@pytest.fixture(scope="module")
def results(case: ProtocolCase) -> dict[str, float]:
    """NMSE_h of every registered correction (object and reference corrected alike), and the oracle."""
    out = {"oracle": case.nmse_h(case.object.oracle(), case.reference.oracle())}
    for name in CORRECTIONS:
        phases = [
            correct(name, m.absolute, m.wrapped, orders=m.orders, mask=m.mask, frequency=8)[0]
            for m in (case.object, case.reference)
        ]
        out[name] = case.nmse_h(*phases)
    return out


def test_rpca_phase_removes_order_errors_and_noise(case: ProtocolCase, results: dict[str, float]) -> None:
    # Thesis Table 4.1: 0.3893 -> 0.0003; the low-rank part also removes noise the oracle keeps.
    assert results["none"] > 1.0
    assert results["rpca-phase"] < results["oracle"] / 3


@pytest.mark.parametrize("name", ["vote", "rpca-orders", "rpca-phase", "auto"])
def test_every_method_improves_on_none(results: dict[str, float], name: str) -> None:
    assert results[name] < results["none"] / 100


def test_auto_is_within_twice_the_oracle(results: dict[str, float]) -> None:
    assert results["auto"] <= 2 * results["oracle"]
    assert results["auto"] <= results["none"]


def test_auto_is_no_worse_than_none_without_order_errors() -> None:
    # 40 dB: no order errors; auto must not smooth real structure (steps) away.
    quiet = table41_case(128, 128, snr_db=40.0, seed=1, scene="steps")
    assert quiet.object.order_errors() == 0
    phases = [correct("auto", m.absolute, m.wrapped, mask=m.mask)[0] for m in (quiet.object, quiet.reference)]
    assert quiet.nmse_h(*phases) <= quiet.nmse_h(quiet.object.absolute, quiet.reference.absolute)


def test_reorder_from_low_rank_gives_the_true_orders(case: ProtocolCase) -> None:
    m = case.object
    low_rank, result = correct_phase_rpca(m.absolute, m.mask)
    assert result.converged and result.rank <= 5
    reordered = reorder_from_low_rank(low_rank, m.wrapped, m.mask)
    np.testing.assert_allclose(reordered[m.mask], m.oracle()[m.mask])


def test_stable_mode_is_more_accurate_than_exact_equality(case: ProtocolCase) -> None:
    exact = [correct_phase_rpca(m.absolute, m.mask, stable=False)[0] for m in (case.object, case.reference)]
    stable = [correct_phase_rpca(m.absolute, m.mask)[0] for m in (case.object, case.reference)]
    assert case.nmse_h(*stable) < case.nmse_h(*exact)


def test_full_svd_reference_gives_the_same_low_rank_phase(case: ProtocolCase) -> None:
    # The randomised SVD is approximate: allow 1/25 of the phase noise (0.13 rad) per pixel.
    fast = [correct_phase_rpca(m.absolute, m.mask, svd="auto")[0] for m in (case.object, case.reference)]
    full = [correct_phase_rpca(m.absolute, m.mask, svd="full")[0] for m in (case.object, case.reference)]
    np.testing.assert_allclose(fast[0], full[0], atol=5e-3)
    assert case.nmse_h(*fast) == pytest.approx(case.nmse_h(*full), rel=0.02)


def test_restore_detail_keeps_structure_the_low_rank_part_misses() -> None:
    rng = np.random.default_rng(5)
    low_rank = np.tile(np.linspace(0.0, 20.0, 80), (60, 1))
    measured = low_rank + rng.normal(0.0, 0.05, low_rank.shape)
    measured[20:25, 40:45] += 1.5  # a small bump the low-rank model does not have
    out = restore_detail(low_rank, measured, k_sigma=4.0)
    np.testing.assert_allclose(out[20:25, 40:45], measured[20:25, 40:45])
    assert np.mean(out == low_rank) > 0.99


def _blurred_step(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ramp with a 5 rad step down the rows at row 30 (more than pi: the pixels on either side break), its
    measurement (noise 0.02 rad) and a low-rank estimate that blurs the step over the two rows beside it."""
    rng = np.random.default_rng(seed)
    truth = np.tile(np.linspace(0.0, 20.0, 80), (60, 1))
    truth[30:] += 5.0
    estimate = truth.copy()
    estimate[29:31] = 0.5 * (truth[29] + truth[30])  # L's in-between value: 2.5 rad off each side
    return truth, truth + rng.normal(0.0, 0.02, truth.shape), estimate


def test_detail_keeps_the_edge_of_a_real_step_its_temporal_orders_vouch_for() -> None:
    truth, measured, estimate = _blurred_step(6)
    # r = +-2.5 rad on the two edge rows: their 3 x 3 means cancel, and each edge pixel breaks with the other row
    without = restore_detail(estimate, measured, k_sigma=4.0, noise_sigma=0.02)
    assert np.abs(without - truth)[29:31].min() > 2.0  # L's blur stays (the rule before unwrapped_phase)
    out = restore_detail(estimate, measured, k_sigma=4.0, noise_sigma=0.02, unwrapped_phase=measured)
    np.testing.assert_array_equal(out[29:31], measured[29:31])
    assert np.abs(out - truth).max() < 0.15


def test_detail_keeps_the_blur_where_the_correction_moved_the_edge_pixels_order() -> None:
    truth, kept, estimate = _blurred_step(7)
    unwrapped = kept.copy()
    unwrapped[29] -= TWO_PI  # measured a fringe off there: the kept order is the correction's
    out = restore_detail(estimate, kept, k_sigma=4.0, noise_sigma=0.02, unwrapped_phase=unwrapped)
    np.testing.assert_array_equal(out[29], estimate[29])  # nothing vouches for the kept order there
    np.testing.assert_array_equal(out[30], kept[30])  # the other edge row's order is the measured one


@pytest.mark.parametrize("changes", [0, 40, 3000])  # none; a few (near the changes only); many (the whole map)
def test_detail_update_near_changed_orders_is_bit_identical_to_the_whole_map(changes: int) -> None:
    rng = np.random.default_rng(changes)
    rows, cols = 90, 120
    estimate = np.add.outer(np.linspace(0.0, 3.0, rows), np.linspace(0.0, 40.0, cols))
    valid = rng.random((rows, cols)) > 0.05  # holes in the mask
    before = estimate + rng.normal(0.0, 0.05, estimate.shape)
    before[30:36, 50:58] += 1.0  # structure the low-rank part misses
    before[rng.random(before.shape) < 0.01] += TWO_PI  # lone wrong orders
    after = before.copy()
    where = rng.choice(rows * cols, changes, replace=False)
    where = np.concatenate([where, [0, cols - 1, (rows - 1) * cols]]) if changes else where  # corners too
    after.flat[where] += TWO_PI * rng.choice([-1.0, 1.0], where.size)
    sigma = 0.05
    unwrapped = before.copy()  # the lone wrong orders in it, and a step more than pi high
    unwrapped[60:, :] += 4.0
    before[60:, :] += 4.0
    after[60:, :] += 4.0
    previous = keep_coherent_detail(estimate, before, valid, 4.0, sigma, unwrapped)
    whole = keep_coherent_detail(estimate, after, valid, 4.0, sigma, unwrapped)
    updated = update_coherent_detail(previous, before, estimate, after, valid, 4.0, sigma, unwrapped)
    assert updated.tobytes() == whole.tobytes()
    assert changes == 0 or np.count_nonzero(~np.isclose(whole, previous) & valid) > 0  # the changes matter


def test_shadows_stay_invalid_and_do_not_disturb_the_rest(case: ProtocolCase) -> None:
    m = case.object
    mask = m.mask.copy()
    mask[40:60, 30:50] = False
    out, info = correct("auto", np.where(mask, m.absolute, np.nan), m.wrapped, mask=mask)
    assert np.isnan(out[~mask]).all() and np.isfinite(out[mask]).all()
    assert np.abs(out - m.truth)[mask].max() < np.pi
    assert info["method"] == "auto" and info["iterations"] > 0 and info["rank"] >= 1


def test_info_records_method_parameters_and_effort(case: ProtocolCase) -> None:
    m = case.object
    for name in CORRECTIONS:
        _, info = correct(name, m.absolute, m.wrapped, mask=m.mask, frequency=8)
        assert info["method"] == name
        assert {"parameters", "iterations", "rank", "seconds"} <= set(info)
        assert info["frequency"] == 8.0


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda: correct_phase_rpca(np.full((8, 8), np.nan)), "mask"),
        (lambda: correct_phase_rpca(np.zeros((8, 8)), np.ones((8, 7), dtype=bool)), "mask"),
        (lambda: correct_phase_rpca(np.full((8, 8), np.nan), np.ones((8, 8), dtype=bool)), "absolute_phase"),
        (lambda: correct_phase_rpca(np.zeros(8)), "absolute_phase"),
        (lambda: reorder_from_low_rank(np.zeros((8, 8)), np.zeros((4, 8))), "wrapped_phase"),
        (lambda: correct("magic", np.zeros((8, 8)), np.zeros((8, 8))), "correction"),
        (lambda: correct("auto", np.zeros((8, 8)), np.full((8, 8), np.nan)), "wrapped_phase"),
    ],
)
def test_bad_input_names_the_argument(call, name: str) -> None:
    with pytest.raises(ValueError, match=f"^{name}:"):
        call()


def test_order_changes_are_accepted_only_where_they_fit_the_neighbours() -> None:
    from processing.correction.phase_rpca import accept_if_consistent

    rng = np.random.default_rng(6)
    truth = np.add.outer(np.linspace(0.0, 2.0, 40), np.arange(60) * 2.5)  # steep: 2.5 rad per pixel
    measured = truth + rng.normal(0.0, 0.02, truth.shape)
    measured[10, 20] += TWO_PI  # a real order error
    candidate = measured.copy()
    candidate[10, 20] -= TWO_PI  # its fix
    candidate[30, 40] += TWO_PI  # a bad proposal where the measurement was right
    valid = np.ones(truth.shape, dtype=bool)
    out = accept_if_consistent(candidate, measured, valid)
    assert abs(out[10, 20] - truth[10, 20]) < 0.1
    assert abs(out[30, 40] - truth[30, 40]) < 0.1


def test_order_fixes_on_the_border_survive_a_wrong_neighbour() -> None:
    # Regression: at the last column only the up-down pair is complete; with the pixel above also
    # wrong, that pair alone rejected the right fix (3 pixels left wrong on 1000 x 1000 Table 4.1).
    from processing.correction.phase_rpca import accept_if_consistent

    truth = np.add.outer(np.linspace(0.0, 1.0, 20), np.arange(30) * 0.2)
    measured = truth.copy()
    measured[9, -1] -= 5 * TWO_PI
    measured[10, -1] -= 3 * TWO_PI
    out = accept_if_consistent(truth, measured, np.ones(truth.shape, dtype=bool))
    np.testing.assert_allclose(out, truth)
