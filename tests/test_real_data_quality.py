"""Every good pixel kept, no speck kept: the heterodyne set against its peer's own threshold, the eye's
background islands, and the same properties on seeded synthetic maps.

The peer is SLMaster's ThreeFrequencyHeterodynePattern: a pixel is valid when the modulation of
the first 4-step group, 2/N |sum_k I_k exp(i 2 pi k / N)|, exceeds its test's confidenceThreshold
of 30 grey levels. Real-data tests skip cleanly without ``../shared/real-data``.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from realdata import REAL_DATA, import_eye, import_eye_calibration, needs_real_data, process_eye

from processing.correction.islands import island_mask
from processing.unwrap.neighbour_rescue import rescue
from rig.cli import main
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process

PEER_THRESHOLD = 30.0  # SLMaster test/testThreeFrequencyHeterodynePattern.cpp, testUnwrap


# ------------------------------------------------------------------ synthetic


def _ramp(shape: tuple[int, int] = (60, 80), slope: float = 0.3) -> np.ndarray:
    rows, cols = np.indices(shape, dtype=np.float64)
    return slope * cols + 0.02 * rows + 5.0


def test_rescue_takes_back_right_slivers_and_leaves_wrong_orders_out() -> None:
    phase = _ramp()
    rng = np.random.default_rng(3)
    phase += rng.normal(0, 0.03, phase.shape)
    valid = np.ones(phase.shape, dtype=bool)
    valid[10:50, 30:32] = False  # a 2 px vertical sliver, right phase
    valid[10:50, 50] = False  # a 1 px sliver ...
    phase[20:30, 50] += 2 * np.pi  # ... part of it with a wrong order
    candidates = valid.copy()
    candidates[10:50, 30:32] = candidates[10:50, 50] = True
    out = rescue(phase, valid, candidates)
    assert out[10:50, 30:32].all()
    assert out[10:20, 50].all() and out[30:50, 50].all()
    assert not out[20:30, 50].any()
    unlit = valid.copy()  # not candidates (no modulation): never taken back
    assert not rescue(phase, unlit, valid)[10:50, 30:32].any()


def test_rescue_refuses_across_a_depth_step() -> None:
    phase = _ramp()
    phase[:, 40:] += 3.0  # a step: neighbours do not lie on one plane
    valid = np.ones(phase.shape, dtype=bool)
    valid[:, 39:41] = False
    out = rescue(phase, valid, np.ones_like(valid))
    assert not out[:, 39:41].all()


def test_island_mask_drops_small_regions_only() -> None:
    valid = np.zeros((200, 200), dtype=bool)
    valid[50:150, 50:150] = True  # the object, 10 000 px
    valid[0:15, 0:3] = True  # a strip at the border, 45 px (under 0.5 % of 10 000)
    valid[180:185, 180:185] = True  # a blob, 25 px
    valid[20:60, 170:195] = True  # a second object of 1 000 px: 10 % of the largest, kept
    islands = island_mask(valid)
    assert islands[0:15, 0:3].all() and islands[180:185, 180:185].all()
    assert not islands[50:150, 50:150].any() and not islands[20:60, 170:195].any()
    assert not island_mask(valid, 0.0).any()
    with pytest.raises(ValueError, match="min_fraction"):
        island_mask(valid, 2.0)


def test_island_regions_same_with_opencv_and_scipy() -> None:
    """Both labelings find the same 8-connected regions: same region sizes per pixel (diagonal links count)."""
    from processing.correction.islands import _regions

    valid = np.random.default_rng(4).random((120, 90)) < 0.45
    valid[10:12, 10:12] = False
    valid[10, 10] = valid[11, 11] = True  # a diagonal pair: one region under 8-connectivity
    sizes = []
    for opencv in (True, False):
        labels, count = _regions(valid, opencv=opencv)
        counts = np.bincount(labels.ravel(), minlength=count)
        assert counts.shape[0] == count
        size_map = np.where(valid, counts[labels], 0)
        sizes.append(size_map)
    np.testing.assert_array_equal(sizes[0], sizes[1])
    assert island_mask(valid[::-1].T, 0.3).shape == (90, 120)  # a non-contiguous view works too


# ------------------------------------------------------------------ real data


def _peer_valid(folder: Path) -> np.ndarray:
    frames = np.stack([cv2.imread(str(folder / f"{k}.png"), cv2.IMREAD_GRAYSCALE).astype(np.float64) for k in range(4)])
    k = np.arange(4)[:, None, None]
    sin = (frames * np.sin(2 * np.pi * k / 4)).sum(axis=0)
    cos = (frames * np.cos(2 * np.pi * k / 4)).sum(axis=0)
    return 2.0 / 4 * np.hypot(sin, cos) > PEER_THRESHOLD


@needs_real_data
def test_heterodyne_coverage_matches_the_peers_threshold(tmp_path, capsys) -> None:
    folder = REAL_DATA / "slmaster-david-heterodyne"
    out = tmp_path / "david"
    assert (
        main(
            [
                "import",
                str(folder),
                "--patterns",
                "sin:f=64/58/53,steps=4,phase=pi",
                "--projector-width",
                "1920",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    peer = _peer_valid(folder)
    result = process(out)
    ours = result.mask
    coverage = np.count_nonzero(ours & peer) / np.count_nonzero(peer)
    assert coverage >= 0.98, coverage  # 0.925 when residual-rejected slivers stayed out
    assert np.count_nonzero(ours & ~peer) < 0.03 * np.count_nonzero(ours)  # no background let in
    steps = np.diff(result.phase, axis=1)
    steps = steps[np.isfinite(steps)]
    assert np.mean(np.abs(steps) > np.pi) < 1e-3  # the pixels taken back carry the right order
    assert np.mean(steps > 0) > 0.99
    vertical = np.diff(result.phase, axis=0)
    assert np.mean(np.abs(vertical[np.isfinite(vertical)]) > np.pi) < 2e-3
    off = process(out, options=ProcessOptions(params={"neighbour_rescue": False}))
    assert np.count_nonzero(off.mask & peer) / np.count_nonzero(peer) < 0.95  # the off switch gives the old mask


@needs_real_data
def test_no_floating_specks_on_the_eye(tmp_path, capsys) -> None:
    import_eye_calibration(tmp_path / "cal")
    import_eye(tmp_path / "eye", "--projector-width", "1920")
    result = process(tmp_path / "eye", tmp_path / "cal")
    assert result.height is not None and result.points is not None
    depth = result.height[result.mask]
    assert 690 < depth.min() and depth.max() < 800, (depth.min(), depth.max())  # the plaque: 727 mm median
    cols = np.nonzero(result.mask)[1]
    assert cols.min() > 100  # the strip at image columns 0-7 (depth ~1 330 mm) is gone
    assert not island_mask(result.mask).any()
    assert any("isolated islands" in note for note in result.notes)
    kept = process(tmp_path / "eye", tmp_path / "cal", ProcessOptions(min_island_fraction=0.0))
    assert np.nanmax(kept.height) > 1200  # the off switch keeps them
    capsys.readouterr()
    process_eye(tmp_path, "--correction", "none", "-q")
    err = capsys.readouterr().err
    assert "692" in err or "693" in err, err  # summary range starts at the plaque, not at 636 mm
