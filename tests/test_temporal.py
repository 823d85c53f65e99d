"""Temporal unwrapping: exact fringe orders on simulated scans and at the stated tolerances."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mock_devices import scenes, synth
from processing.phase.shifting import phase_shift
from processing.projection.patterns import gray_stripe_index
from processing.unwrap.temporal import (
    UnwrapResult,
    decode_gray,
    pair_table,
    unwrap_gray,
    unwrap_heterodyne,
    unwrap_hierarchical,
    unwrap_three_frequency,
    unwrap_two_frequency,
    unwrap_two_frequency_stacks,
)

TWO_PI = 2.0 * np.pi
REAL_DATA = Path(__file__).resolve().parents[2] / "shared" / "real-data"


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * x))


# ----------------------------------------------------------------------------- simulated scans


def _geometry(width: int = 160, height: int = 120) -> synth.RigGeometry:
    """The default rig seen by a small camera with the same field of view."""
    base = synth.RigGeometry()
    return replace(base.with_camera(width, height), pixel_mm=base.pixel_mm * base.camera_width / width)


def _scan(frequencies, steps=4, scene="hemisphere", snr_db=40.0, seed=0):
    """Wrapped phases (one per frequency), the truth mapping and geometry of a simulated scan."""
    geometry = _geometry()
    heights = scenes.make_scene(scene, geometry.camera_height, geometry.camera_width, geometry.pixel_mm)
    mapping = synth.projector_coordinates(heights, geometry)
    appearance = synth.Appearance(ambient=0.05, snr_db=snr_db)
    stack = synth.render_stack(
        synth.sinusoid_patterns(frequencies, steps), mapping, geometry, appearance, np.random.default_rng(seed)
    )
    phases = [phase_shift(stack[i * steps : (i + 1) * steps]).phase for i in range(len(frequencies))]
    return phases, mapping, geometry


def _assert_exact_orders(result: UnwrapResult, mapping, geometry, frequency: int, min_valid: float = 0.99) -> None:
    """Every valid lit pixel within pi of the truth (right order), and almost all lit pixels valid."""
    truth = synth.true_absolute_phase(mapping, geometry, frequency)
    lit = mapping.lit
    assert result.valid[lit].mean() >= min_valid
    good = lit & result.valid
    error = np.abs(result.phase[good] - truth[good])
    assert error.max() < np.pi, f"{np.sum(error >= np.pi)} pixels with a wrong order"
    assert error.max() < 0.3  # the noise of the highest frequency, not a fraction of a period
    fraction = result.phase / TWO_PI - result.orders  # phase = 2 pi (order + wrapped turns in [0, 1))
    assert np.all(fraction[good] > -1e-9) and np.all(fraction[good] < 1.0 + 1e-9)


def test_two_frequency_simulated_scan() -> None:
    phases, mapping, geometry = _scan([7, 8], steps=6)
    result = unwrap_two_frequency(phases[0], phases[1], 7, 8)
    assert result.phase.dtype == np.float64 and result.valid.dtype == bool
    assert np.issubdtype(result.orders.dtype, np.integer)
    _assert_exact_orders(result, mapping, geometry, 8)
    assert result.phase.min() >= 0.0 and result.phase.max() < TWO_PI * 8


def _stacks(frequencies, steps, seed=0):
    geometry = _geometry()
    heights = scenes.make_scene("hemisphere", geometry.camera_height, geometry.camera_width, geometry.pixel_mm)
    mapping = synth.projector_coordinates(heights, geometry)
    stack = synth.render_stack(
        synth.sinusoid_patterns(frequencies, steps),
        mapping,
        geometry,
        synth.Appearance(ambient=0.05, snr_db=40.0),
        np.random.default_rng(seed),
    )
    return [stack[i * steps : (i + 1) * steps] for i in range(len(frequencies))], mapping, geometry


def test_fused_two_frequency_matches_separate_steps() -> None:
    (low, high), mapping, geometry = _stacks([7, 8], steps=6)
    fused = unwrap_two_frequency_stacks(low, high, 7, 8)
    _assert_exact_orders(fused.unwrapped, mapping, geometry, 8)
    separate_high = phase_shift(high)
    separate = unwrap_two_frequency(phase_shift(low).phase, separate_high.phase, 7, 8)
    # Lit pixels agree; in shadow the phases are noise and m can sit on a rounding boundary,
    # where float32 and float64 turns may round differently.
    lit = mapping.lit
    np.testing.assert_array_equal(fused.unwrapped.orders[lit], separate.orders[lit])
    np.testing.assert_allclose(fused.unwrapped.phase[lit], separate.phase[lit], atol=1e-5)
    np.testing.assert_array_equal(fused.unwrapped.valid[lit], separate.valid[lit])
    np.testing.assert_allclose(fused.modulation, separate_high.modulation, rtol=1e-6)
    np.testing.assert_allclose(fused.background, separate_high.background, rtol=1e-6)


def test_fused_two_frequency_arbitrary_shifts_and_bad_input() -> None:
    (low, high), mapping, geometry = _stacks([5, 8], steps=4)
    shifts = 2 * np.pi * np.arange(4) / 4
    fused = unwrap_two_frequency_stacks(low, high, 5, 8, shifts, shifts)
    _assert_exact_orders(fused.unwrapped, mapping, geometry, 8)
    with pytest.raises(ValueError, match="stack2"):
        unwrap_two_frequency_stacks(low, high[:, :10], 5, 8)
    with pytest.raises(ValueError, match="coprime"):
        unwrap_two_frequency_stacks(low, high, 4, 8)
    with pytest.raises(ValueError, match="stack"):
        unwrap_two_frequency_stacks(low[:2], high, 5, 8)


def test_two_frequency_representation_does_not_matter() -> None:
    phases, _, _ = _scan([5, 8], steps=4)
    a = unwrap_two_frequency(phases[0], phases[1], 5, 8)
    b = unwrap_two_frequency(np.mod(phases[0], TWO_PI), phases[1] + 6 * np.pi, 5, 8)
    np.testing.assert_allclose(a.phase, b.phase, atol=1e-9)
    np.testing.assert_array_equal(a.orders, b.orders)


def test_three_frequency_simulated_scan() -> None:
    phases, mapping, geometry = _scan([6, 10, 15], steps=4)
    _assert_exact_orders(unwrap_three_frequency(phases, [6, 10, 15]), mapping, geometry, 15)


def test_hierarchical_simulated_scan() -> None:
    phases, mapping, geometry = _scan([1, 8, 64], steps=4)
    _assert_exact_orders(unwrap_hierarchical(phases, [1, 8, 64]), mapping, geometry, 64)


def test_heterodyne_two_frequencies_simulated_scan() -> None:
    phases, mapping, geometry = _scan([16, 15], steps=4)
    _assert_exact_orders(unwrap_heterodyne(phases, [16, 15]), mapping, geometry, 16)


def test_heterodyne_three_frequencies_simulated_scan() -> None:
    """64, 58, 53 as in the real capture: beats 6 and 5, unit beat 1."""
    phases, mapping, geometry = _scan([64, 58, 53], steps=4, snr_db=45.0)
    result = unwrap_heterodyne(phases, [64, 58, 53])
    _assert_exact_orders(result, mapping, geometry, 64)
    shuffled = unwrap_heterodyne([phases[2], phases[0], phases[1]], [53, 64, 58])
    np.testing.assert_array_equal(shuffled.orders, result.orders)


# ----------------------------------------------------------------------------- tolerances


def _positions(count: int = 200_000, seed: int = 0, margin: float = 0.1) -> np.ndarray:
    """Projector positions u / W away from the two ends, where noise wraps the lowest frequency
    around and every method returns the other end of the range."""
    return np.random.default_rng(seed).uniform(margin, 1.0 - margin, (1, count))


def _noisy_wrapped(u: np.ndarray, frequencies, bound: float, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [_wrap(TWO_PI * f * u + rng.uniform(-bound, bound, u.shape)) for f in frequencies]


def _wrong_orders(result: UnwrapResult, u: np.ndarray, frequency: int) -> int:
    return int(np.sum(np.abs(result.phase - TWO_PI * frequency * u) >= np.pi))


@pytest.mark.parametrize(("f1", "f2"), [(5, 8), (7, 16), (14, 15)])
def test_two_frequency_tolerance_is_pi_over_sum(f1: int, f2: int) -> None:
    """Uniform phase errors just below pi / (f1 + f2): every order right; just above: some wrong."""
    u = _positions()
    bound = np.pi / (f1 + f2)
    below = unwrap_two_frequency(*_noisy_wrapped(u, (f1, f2), 0.99 * bound, seed=1), f1, f2)
    assert _wrong_orders(below, u, f2) == 0
    assert below.valid.all()
    above = unwrap_two_frequency(*_noisy_wrapped(u, (f1, f2), 1.3 * bound, seed=1), f1, f2)
    assert _wrong_orders(above, u, f2) > 0


def test_two_frequency_errors_beyond_tolerance_are_large() -> None:
    """Beyond the tolerance m lands on another valid pair: order errors of many fringes, unflagged."""
    u = _positions(50_000)
    result = unwrap_two_frequency(*_noisy_wrapped(u, (5, 8), 3.0 * np.pi / 13, seed=2), 5, 8)
    error_orders = np.rint((result.phase - TWO_PI * 8 * u) / TWO_PI)
    assert np.max(np.abs(error_orders)) >= 3
    assert result.valid.mean() > 0.95


def test_two_frequency_flags_out_of_range_m() -> None:
    """m = -f1 or f2 (wrapped phases no position produces) is marked invalid."""
    phi1 = np.array([[0.0, 0.999 * TWO_PI, 0.3]])
    phi2 = np.array([[0.999 * TWO_PI, 0.0, 0.48]])
    result = unwrap_two_frequency(phi1, phi2, 5, 8)
    np.testing.assert_array_equal(result.valid, [[False, False, True]])


def test_pair_table_reachable_count() -> None:
    for fa, fb in [(5, 8), (7, 16), (1, 2), (13, 14)]:
        table = pair_table(fa, fb)
        assert table.reachable.sum() == fa + fb - 1
        m = np.arange(-fa, fb + 1)
        reach = table.reachable
        np.testing.assert_array_equal((fa * table.kb[reach] - fb * table.ka[reach]), m[reach])


def test_three_frequency_tolerance_beats_two_frequency() -> None:
    """6, 10, 15: tolerance min(3 pi / 21, 5 pi / 25) = pi / 7, four times that of (14, 15)."""
    freqs = (6, 10, 15)
    bound = min(math.gcd(f, 15) * np.pi / (f + 15) for f in freqs[:2])
    assert bound == pytest.approx(np.pi / 7)
    u = _positions()
    below = unwrap_three_frequency(_noisy_wrapped(u, freqs, 0.99 * bound, seed=3), freqs)
    assert _wrong_orders(below, u, 15) == 0 and below.valid.all()
    above = unwrap_three_frequency(_noisy_wrapped(u, freqs, 1.5 * bound, seed=3), freqs)
    assert _wrong_orders(above, u, 15) > 0
    phases = _noisy_wrapped(u, (14, 15), 0.99 * bound, seed=3)
    assert _wrong_orders(unwrap_two_frequency(*phases, 14, 15), u, 15) > 0


def test_hierarchical_tolerance_and_residual_flag() -> None:
    """Ratio 8: errors e with 8 e + e < pi are safe; valid flags residuals above max_residual."""
    u = _positions()
    bound = 0.99 * np.pi / 9
    result = unwrap_hierarchical(_noisy_wrapped(u, (1, 8), bound, seed=4), [1, 8], max_residual=np.pi)
    assert _wrong_orders(result, u, 8) == 0 and result.valid.all()
    strict = unwrap_hierarchical(_noisy_wrapped(u, (1, 8), bound, seed=4), [1, 8], max_residual=0.1)
    assert 0.0 < strict.valid.mean() < 1.0
    above = unwrap_hierarchical(_noisy_wrapped(u, (1, 8), 1.5 * np.pi / 9, seed=4), [1, 8])
    assert _wrong_orders(above, u, 8) > 0


def test_nan_inputs_are_invalid() -> None:
    u = _positions(100)
    phases = _noisy_wrapped(u, (1, 5, 8), 0.0, seed=0)
    for p in phases:
        p[0, 3] = np.nan
    results = [
        unwrap_two_frequency(phases[1], phases[2], 5, 8),
        unwrap_hierarchical([phases[0], phases[2]], [1, 8]),
        unwrap_heterodyne([phases[2], _wrap(TWO_PI * 7 * u)], [8, 7]),
    ]
    for result in results:
        assert np.isnan(result.phase[0, 3]) and not result.valid[0, 3] and result.orders[0, 3] == 0
        assert result.valid.sum() == 99


# ----------------------------------------------------------------------------- Gray code


def _gray_scan(bits: int, misregistration_px: float, seed: int = 0):
    """Gray planes (+ inverted) and a sinusoid of 2**(bits-1) fringes; the code shifted on the projector."""
    geometry = _geometry()
    heights = scenes.make_scene("sphere-cap", geometry.camera_height, geometry.camera_width, geometry.pixel_mm)
    mapping = synth.projector_coordinates(heights, geometry)
    rng = np.random.default_rng(seed)
    appearance = synth.Appearance(ambient=0.05, snr_db=35.0)
    # The camera sees the code planes displaced by a fraction of a stripe (defocus, misregistration).
    shifted = replace(mapping, u=mapping.u + misregistration_px)
    planes = [{"kind": "gray", "axis": "x", "bit": b, "bits": bits} for b in range(bits)]
    images = synth.render_stack(planes, shifted, geometry, appearance, rng)
    inverted = synth.render_stack([dict(p, inverted=True) for p in planes], shifted, geometry, appearance, rng)
    frequency = 1 << (bits - 1)
    stack = synth.render_stack(synth.sinusoid_patterns([frequency], 4), mapping, geometry, appearance, rng)
    return images, inverted, phase_shift(stack).phase, mapping, geometry, shifted


def test_decode_gray_matches_pattern_convention() -> None:
    bits = 5
    images, inverted, _, _, geometry, shifted = _gray_scan(bits, 0.0)
    truth = gray_stripe_index(shifted.u, geometry.projector_width, bits)
    lit = shifted.lit
    with_inverse = decode_gray(images, inverted)
    assert np.issubdtype(with_inverse.dtype, np.integer)
    assert np.mean(with_inverse[lit] == truth[lit]) > 0.999
    default = decode_gray(images)
    assert np.mean(default[lit] == truth[lit]) > 0.99
    white = np.full(images.shape[1:], 0.5 * images.max())
    assert np.mean(decode_gray(images, threshold=white)[lit] == truth[lit]) > 0.99


def test_decode_gray_every_code_word() -> None:
    """Ideal planes of all 2**B stripes, including the all-zero and all-one code words."""
    bits = 4
    u = (np.arange(64) + 0.5)[None, :]
    planes = np.stack(
        [
            200.0 * ((gray_stripe_index(u, 64, bits) ^ (gray_stripe_index(u, 64, bits) >> 1)) >> (bits - 1 - b) & 1)
            + 10
            for b in range(bits)
        ]
    )
    expected = gray_stripe_index(u, 64, bits)
    np.testing.assert_array_equal(decode_gray(planes, 210.0 - planes + 10.0), expected)
    np.testing.assert_array_equal(decode_gray(planes, threshold=110.0), expected)
    np.testing.assert_array_equal(decode_gray(planes), expected)


def test_complementary_gray_fixes_period_edge_errors() -> None:
    """A code displaced by 1.5 projector px (period 57 px): plain Gray errs along every period edge."""
    bits = 5
    frequency = 1 << (bits - 1)
    images, inverted, phi, mapping, geometry, _ = _gray_scan(bits, 1.5)
    stripes = decode_gray(images, inverted)
    truth = synth.true_absolute_phase(mapping, geometry, frequency)
    lit = mapping.lit

    plain = unwrap_gray(phi, decode_gray(images[:-1], inverted[:-1]), bits - 1, frequency)
    plain_wrong = np.abs(plain.phase - truth)[lit] >= np.pi
    assert plain_wrong.mean() > 0.005, "plain Gray code should show period-edge errors"

    comp = unwrap_gray(phi, stripes, bits, frequency, complementary=True)
    good = lit & comp.valid
    assert good.sum() / lit.sum() > 0.99
    assert np.max(np.abs(comp.phase - truth)[good]) < 0.3


def test_plain_gray_without_misregistration() -> None:
    """Aligned code: plain Gray orders are right except where phase noise crosses a period edge."""
    bits = 4
    images, inverted, phi, mapping, geometry, _ = _gray_scan(bits + 1, 0.0)
    result = unwrap_gray(phi, decode_gray(images[:-1], inverted[:-1]), bits, 1 << bits)
    truth = synth.true_absolute_phase(mapping, geometry, 1 << bits)
    wrong = np.abs(result.phase - truth)[mapping.lit] >= np.pi
    assert wrong.mean() < 0.02


def test_gray_order_generalises_to_finer_codes() -> None:
    """2**bits = 4 x frequency: order = floor(stripe * f / 2**bits)."""
    u = _positions(1000)
    stripes = gray_stripe_index(u * 1000.0, 1000.0, 6)
    result = unwrap_gray(_wrap(TWO_PI * 16 * u), stripes, 6, 16)
    np.testing.assert_array_equal(result.orders, np.floor(16 * u).astype(int))


# ----------------------------------------------------------------------------- real capture


@pytest.mark.skipif(not (REAL_DATA / "slmaster-david-heterodyne").is_dir(), reason="shared real data not available")
def test_heterodyne_on_real_capture() -> None:
    """SLMaster's rendered bust, 4-step at 64, 58, 53 periods with phase_rad = -pi (rows 300..700)."""
    cv2 = pytest.importorskip("cv2")
    folder = REAL_DATA / "slmaster-david-heterodyne"
    frames = np.stack([cv2.imread(str(folder / f"{i}.png"), cv2.IMREAD_UNCHANGED)[300:700] for i in range(12)])
    results = [phase_shift(frames[4 * i : 4 * i + 4]) for i in range(3)]
    phases = [r.phase + np.pi for r in results]  # subtract the pattern's phase_rad = -pi
    unwrapped = unwrap_heterodyne(phases, [64, 58, 53])
    lit = results[0].modulation > 0.2 * np.percentile(results[0].modulation, 99)
    assert lit.mean() > 0.1
    good = lit & unwrapped.valid
    assert good.sum() / lit.sum() > 0.85
    # Absolute phase 2 pi 64 u / 1920 grows by about 0.21 rad per projector pixel along x and
    # must be continuous: order errors would show as jumps of 2 pi or more between neighbours.
    pairs = good[:, 1:] & good[:, :-1]
    steps = np.diff(unwrapped.phase, axis=1)[pairs]
    assert 0.1 < np.median(steps) < 0.4
    assert np.mean(np.abs(steps) > np.pi) < 0.002
    assert 0.0 <= unwrapped.phase[good].min() and unwrapped.phase[good].max() < TWO_PI * 64


@pytest.mark.skipif(not (REAL_DATA / "slmaster-eye").is_dir(), reason="shared real data not available")
def test_complementary_gray_on_real_capture() -> None:
    """SLMaster's eye relief: 12-step at 32 periods (phase_rad = -pi) and 5 + 1 complementary Gray
    planes without inverses, thresholded at the phase-shifting background A."""
    cv2 = pytest.importorskip("cv2")
    folder = REAL_DATA / "slmaster-eye" / "L"
    frames = np.stack([cv2.imread(str(folder / f"{i}.png"), cv2.IMREAD_UNCHANGED)[300:700] for i in range(18)])
    result = phase_shift(frames[:12])
    phi = result.phase + np.pi
    lit = result.modulation > 0.2 * np.percentile(result.modulation, 99)
    stripes = decode_gray(frames[12:], threshold=result.background)

    def jumps(unwrapped: UnwrapResult) -> float:
        good = lit & unwrapped.valid
        pairs = good[:, 1:] & good[:, :-1]
        return float(np.mean(np.abs(np.diff(unwrapped.phase, axis=1)[pairs]) > np.pi))

    assert jumps(unwrap_gray(phi, stripes >> 1, 5, 32)) > 0.005  # plain: period-edge errors
    assert jumps(unwrap_gray(phi, stripes, 6, 32, complementary=True)) < 0.0005


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda p: unwrap_two_frequency(p, p, 4, 8), "coprime"),
        (lambda p: unwrap_two_frequency(p, p, 8, 5), "f1 < f2"),
        (lambda p: unwrap_two_frequency(p, p[:2], 5, 8), "phi2"),
        (lambda p: unwrap_two_frequency(p, p, 5.5, 8), "f1"),
        (lambda p: unwrap_two_frequency(p[0], p[0], 5, 8), "phi1"),
        (lambda p: unwrap_three_frequency([p, p, p], [6, 10, 14]), "common divisor"),
        (lambda p: unwrap_three_frequency([p, p], [6, 10, 15]), "phis"),
        (lambda p: unwrap_three_frequency([p, p, p], [6, 15, 10]), "largest last"),
        (lambda p: unwrap_hierarchical([p, p], [2, 8]), "unit frequency"),
        (lambda p: unwrap_hierarchical([p, p, p], [1, 8, 4]), "increasing"),
        (lambda p: unwrap_hierarchical([p, p], [1, 8], max_residual=0.0), "max_residual"),
        (lambda p: unwrap_heterodyne([p, p], [16, 14]), "beat"),
        (lambda p: unwrap_heterodyne([p, p, p], [64, 58, 52]), "beats"),
        (lambda p: unwrap_heterodyne([p], [16]), "two or three"),
        (lambda p: unwrap_gray(p, np.zeros(p.shape, int), 4, 16, complementary=True), "bits"),
        (lambda p: unwrap_gray(p, np.zeros(p.shape), 4, 16), "stripes"),
        (lambda p: decode_gray(np.zeros((3, 4, 4)), np.zeros((2, 4, 4))), "inverted"),
        (lambda p: decode_gray(np.zeros((3, 4, 4)), threshold=np.zeros((5, 5))), "threshold"),
    ],
)
def test_bad_input_names_the_argument(call, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call(np.zeros((4, 5)))
