"""Real captures whose layouts need the code layouts: kamino410's mugs (Gray code under two frequencies, both axes).

kamino410-mugs (``../shared/real-data``, MIT): 3-step fringes of 200/3 and 100 display pixels on both
axes, OpenCV's GrayCodePattern of 100-px cells (5 column bits then 4 row bits, each plane followed by
its inverse), white and black. The code's cells resolve the beat of the two fringe sets (200 px, two
cells); both sets follow. There is no ground truth, so the sets are checked against each other: the
200/3-px set's unwrapped phase, in display pixels, against the 100-px set's resolved by the code
alone, on the pixels both keep. The projector's gamma leaves the 3-step phases a periodic error of a
few pixels (third harmonic: ~8 px at most on this capture); an order error moves a pixel by a whole
period (66.7 or 100 px). Measured on the crop below (correction none): the sets differ by 3.0 px
(x) and 3.3 px (y) in median, 8.0 px at the 99th percentile, and by an order on 0.04 % (x) and
0.07 % (y) of the pixels (1.25 % and 0.92 % when the 100-px set's cell is taken as decoded, without
asking the code's bits which side of a border a pixel is on).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from realdata import KAMINO, KAMINO_DISPLAY, KAMINO_PATTERNS, KAMINO_SHIFTS, needs_real_data

from rig.cli import main
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process

pytestmark = needs_real_data
CROP = "484,304,968,608"  # the middle quarter of the 1936 x 1216 frames, the mugs and the wall between them
# The 100-px set alone with the code: everything of that axis but the 200/3-px fringes skipped.
ONLY_100_PX = {
    "x": f"skip:3; sin:f=19.2,{KAMINO_SHIFTS}; skip:6; gray:bits=5,period=100,inverted=interleaved; skip:8; white; black",
    "y": f"skip:9; sin:f=10.8,{KAMINO_SHIFTS},axis=y; skip:10; gray:bits=4,period=100,inverted=interleaved,axis=y; "
    "white; black",
}
EXTENT = {"x": 1920.0, "y": 1080.0}


def _import(out: Path, spec: str) -> Path:
    argv = ["import", str(KAMINO), "--glob", "pat*.png", "--patterns", spec, *KAMINO_DISPLAY]
    assert main([*argv, "--crop", CROP, "-o", str(out)]) == 0
    return out


def _display_px(capture: Path, axis: str):
    """Unwrapped phase in display pixels along ``axis``, the kept pixels, and the phase stage's info."""
    result = process(capture, None, ProcessOptions(correction="none", axis=axis))
    unwrapped = result.object.unwrapped
    return unwrapped.phase * EXTENT[axis] / (2 * np.pi * unwrapped.frequency), unwrapped.valid, result.object.info


@pytest.fixture(scope="module")
def full(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _import(tmp_path_factory.mktemp("kamino") / "mugs", KAMINO_PATTERNS)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_finer_set_agrees_with_the_code_resolved_set(full: Path, tmp_path: Path, axis: str) -> None:
    """All four fringe sets and the Gray code: the 200/3-px set agrees with the 100-px set, both axes."""
    fine, fine_valid, info = _display_px(full, axis)
    assert info["code"]["resolves"] == ("beat 9.6" if axis == "x" else "beat 5.4")  # 200 px: two cells
    assert abs(info["phase_convention_offset_rad"]) < 0.2  # the cells' borders fall on the 100-px wraps
    coarse, coarse_valid, _ = _display_px(_import(tmp_path / "only100", ONLY_100_PX[axis]), axis)
    both = fine_valid & coarse_valid
    assert both.mean() > 0.4  # the mugs and the lit wall; shadows and the dark border drop out
    difference = (fine - coarse)[both]
    assert abs(np.median(difference)) < 0.5  # no offset between the sets (display px)
    # The 100-px set alone has one cell per period: its cells' borders are its phase wraps, and within a
    # pixel or two of them blur picks either side; the code's own bits say which (border_side).
    order_error = np.abs(difference) > 100 / 3  # half the finer period or more
    in_cell = (coarse[both] % 100) / 100
    border = np.minimum(in_cell, 1 - in_cell) < 0.03  # within 3 display px of a 100-px cell border
    assert np.percentile(np.abs(difference[~border]), 99) < 10.0  # gamma harmonics, under 1/6 of the finer period
    assert np.mean(order_error) < 0.002
