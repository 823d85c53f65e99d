"""`auto` against its peers on the study's hard cases: low SNR and isolated objects with many wrong orders."""

from __future__ import annotations

import numpy as np
import pytest

from mock_devices import scenes
from processing.correction.phase_rpca import order_breaks, phase_noise_sigma
from processing.correction.registry import correct
from processing.geometry.height import nmse
from rig.study.experiments import RIG, heights, oracle_phase, two_frequency_capture

SIZE = 192
# auto may lose to the better of vote and rpca-phase by at most this factor (measured: it wins on
# every case below, by 3.3x to 6900x).
FACTOR = 1.5
# Dense order errors (a quarter to a third of the pixels) at 320 px, where fringe regions are wide
# enough to pool: auto within this factor of the true orders' NMSE_h (measured 1.27 at 18 dB,
# 1.05 at 16 dB; at 1000 px 0.3-0.5).
ORACLE_FACTOR = 2.0
CASES = ["isolated-18dB", "sphere-cap-10dB", "sphere-cap-25dB", "isolated-18dB-320px", "isolated-16dB-320px"]


def _case(name: str):
    size = 320 if name.endswith("320px") else SIZE
    geometry = RIG.geometry(size)
    if name.startswith("isolated"):
        height = scenes.isolated_objects(size, size, geometry.pixel_mm)
        frequencies, snr, seed = (18, 25), float(name.split("-")[1].removesuffix("dB")), 4600
    else:
        height = scenes.sphere_cap(size, size, geometry.pixel_mm)
        snr = float(name.split("-")[2].removesuffix("dB"))
        frequencies, seed = (5, 8), 4500 + int(snr)
    rng = np.random.default_rng(seed)
    obj = two_frequency_capture(height, geometry, frequencies, 6, snr, rng)
    ref = two_frequency_capture(np.zeros_like(height), geometry, frequencies, 6, snr, rng)
    return height, geometry, obj, ref, frequencies[1]


@pytest.fixture(scope="module", params=CASES)
def scores(request) -> dict[str, float]:
    height, geometry, obj, ref, f = _case(request.param)
    mask = obj.lit & ref.lit
    out = {
        "oracle": nmse(heights(oracle_phase(obj), oracle_phase(ref), geometry, f), height, mask),
        "case": request.param,
    }
    for method in ("none", "vote", "rpca-phase", "auto"):
        po, pr = (correct(method, c.phase, c.wrapped, mask=c.lit)[0] for c in (obj, ref))
        out[method] = nmse(heights(po, pr, geometry, f), height, mask)
    return out


def test_auto_is_not_worse_than_the_better_of_vote_and_rpca_phase(scores: dict) -> None:
    if scores["case"].endswith("25dB"):  # no wrong order: auto must not lose to plain ch. 4 or to none
        assert scores["auto"] <= min(scores["none"], scores["rpca-phase"])
        return
    assert scores["none"] > 1.0  # the case has many wrong orders
    assert scores["auto"] <= FACTOR * min(scores["vote"], scores["rpca-phase"])
    assert scores["auto"] < scores["none"] / 100


def test_auto_is_near_the_true_orders_on_dense_errors(scores: dict) -> None:
    if not scores["case"].endswith("320px"):
        pytest.skip("fringe regions of 10 px at 192 px are too narrow to pool (measured 4.7x the oracle)")
    assert scores["auto"] <= ORACLE_FACTOR * scores["oracle"]


def test_phase_noise_sigma_ignores_order_errors() -> None:
    rng = np.random.default_rng(3)
    truth = np.add.outer(np.linspace(0.0, 3.0, 120), np.linspace(0.0, 90.0, 150))
    noisy = truth + rng.normal(0.0, 0.1, truth.shape)
    wrong = rng.random(truth.shape) < 0.25  # a quarter of the orders wrong, by 1 to 3 periods
    noisy[wrong] += 2.0 * np.pi * rng.integers(1, 4, wrong.sum())
    assert phase_noise_sigma(noisy) == pytest.approx(0.1, rel=0.1)


def test_order_breaks_count_the_spikes_of_wrong_orders() -> None:
    phase = np.add.outer(np.zeros(20), np.arange(30) * 2.5)  # steep but continuous: no break
    valid = np.ones(phase.shape, dtype=bool)
    assert order_breaks(phase, valid) == 0
    phase[10, 15] += 2.0 * np.pi  # 3 second differences along the row, 3 along the column
    assert order_breaks(phase, valid) == 6
