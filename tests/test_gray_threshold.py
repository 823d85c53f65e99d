"""Gray decoding on a dark surface: the per-pixel threshold (the fringe mean A) holds at low contrast.

A band of reflectivity 0.1 (modulation ~10 % of the bright part's) is scanned with 5 complementary
Gray planes and 4-step fringes at 16 periods, no inverse planes and no flat frames. Its heights must
be right where the pixels are kept (``--max-sigma``): 97 % of them within 6 predicted sigma (a wrong
order is about 100 sigma off), the rest at the predicted noise. One image-wide level reads most of the
band's bits as 0 (the comparison below shows it fails there).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mock_devices import synth
from processing.unwrap import temporal
from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process

BITS, FREQUENCY = 5, 16


def _dark_band_scan(tmp_path: Path):
    reflectivity = np.ones((120, 160))
    reflectivity[:, 100:140] = 0.1
    gray = [{"kind": "gray", "axis": "x", "bit": b, "bits": BITS} for b in range(BITS)]
    scan = simulate_scan(
        "hemisphere",
        geometry=demo_geometry(160, 120),
        patterns=synth.sinusoid_patterns((FREQUENCY,), 4) + gray,
        appearance=synth.Appearance(reflectivity=reflectivity, ambient=0.1, gain=200.0, snr_db=40.0),
        seed=31,
    )
    return scan, write_simulated_scan(scan, tmp_path / "scan")


def test_gray_orders_hold_on_a_dark_band(tmp_path: Path) -> None:
    scan, paths = _dark_band_scan(tmp_path)
    result = process(paths.capture, paths.calibration, ProcessOptions(max_sigma=4.0, correction="none"))
    assert result.object.unwrapped.method == "gray" and result.height is not None
    assert result.uncertainty is not None
    band = np.zeros_like(result.mask)
    band[:, 102:138] = True
    keep = result.mask & scan.lit & band
    assert keep.sum() > 0.8 * (scan.lit & band).sum()
    error = np.abs(result.height[keep] - scan.height_mm[keep]) / result.uncertainty[keep]
    assert np.sqrt(np.mean(np.square(error[error < 6]))) < 1.5  # the noise predicted
    assert np.mean(error < 6) > 0.97  # a wrong order is ~100 sigma off


def test_one_image_wide_level_misreads_the_dark_band() -> None:
    """The comparison: decode_gray's own level against the fringe mean on the same dark planes."""
    rng = np.random.default_rng(4)
    width = 256
    columns = np.arange(width)
    stripes = columns * (1 << BITS) // width
    code = stripes ^ (stripes >> 1)
    reflectivity = np.where(columns < 192, 1.0, 0.1)
    planes = np.stack([((code >> (BITS - 1 - b)) & 1) * 200.0 * reflectivity for b in range(BITS)])
    planes = np.repeat(planes[:, None, :], 8, axis=1) + 10.0 + rng.normal(0, 1.0, (BITS, 8, width))
    mean_level = np.broadcast_to(10.0 + 100.0 * reflectivity, (8, width))
    dark = slice(200, 250)
    assert np.all(temporal.decode_gray(planes, threshold=mean_level)[:, dark] == stripes[dark])
    assert np.mean(temporal.decode_gray(planes)[:, dark] == stripes[dark]) < 0.9
