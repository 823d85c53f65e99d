"""Code layouts on a seeded simulation: plain binary codes, cells of a given width, a code under several frequencies.

Each capture is rendered from processing.projection.patterns (the definition every layer follows)
on a hemisphere with a dark band (reflectivity 0.1: the bits there are ~10 % of the bright part's
contrast), then processed by ``rig process``'s pipeline. The truth is the projector column each
pixel sees, so the unwrapped phase is checked against 2 pi f u / W: the fringe order is right where
|error| < pi (one order off is 2 pi). The three threshold sources of the bits are each used: the
inverse planes, the white and black frames, and the fringe mean A (neither at hand).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from mock_devices import synth
from processing.phase.shifting import phase_shift
from processing.projection.patterns import Gray, gray_intensity
from processing.unwrap import temporal
from rig.errors import CaptureError, ConfigError, ProcessingError
from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process
from rig.store.importer import parse_spec

PROJECTOR_WIDTH = 912  # the demo rig's projector (synth.RigGeometry)
SEEDS = (5, 23)  # developed on seed 5; 23 is a second draw of the noise


def _code_planes(kind: str, bits: int, period_px: float | None, thresholds: str) -> list[dict[str, Any]]:
    """Code planes, most significant first, with their inverses interleaved or white/black frames after."""
    extra = {} if period_px is None else {"period_px": period_px}
    planes = []
    for bit in range(bits):
        planes.append({"kind": kind, "axis": "x", "bit": bit, "bits": bits, **extra})
        if thresholds == "inverse":
            planes.append({"kind": kind, "axis": "x", "bit": bit, "bits": bits, "inverted": True, **extra})
    if thresholds == "white-black":
        planes += [{"kind": "flat", "level": 1.0}, {"kind": "flat", "level": 0.0}]
    return planes


def _scan(tmp_path: Path, frequencies: tuple[float, ...], planes: list[dict[str, Any]], seed: int, scale: int = 1):
    reflectivity = np.ones((120 * scale, 160 * scale))
    reflectivity[:, 100 * scale : 140 * scale] = 0.1
    scan = simulate_scan(
        "hemisphere",
        geometry=demo_geometry(160 * scale, 120 * scale),
        patterns=synth.sinusoid_patterns(frequencies, 4) + planes,
        appearance=synth.Appearance(reflectivity=reflectivity, ambient=0.05, gain=220.0, snr_db=38.0),
        seed=seed,
    )
    return scan, write_simulated_scan(scan, tmp_path / "scan")


def _order_errors(tmp_path: Path, frequencies: tuple[float, ...], planes: list[dict[str, Any]], seed: int):
    """(share of lit pixels kept, share of kept pixels whose order is wrong, the phase stage's info)."""
    scan, paths = _scan(tmp_path, frequencies, planes, seed)
    # the dark band's modulation is ~10 % of the bright part's: kept by a lower ratio than the default 0.2
    result = process(paths.capture, None, ProcessOptions(correction="none", min_modulation_ratio=0.04))
    unwrapped = result.object.unwrapped
    assert unwrapped.method == "gray" and unwrapped.frequency == max(frequencies)
    truth = 2 * np.pi * max(frequencies) * scan.object_map.u / PROJECTOR_WIDTH
    lit = scan.object_map.lit
    keep = unwrapped.valid & lit
    wrong = np.abs(unwrapped.phase - truth) > np.pi
    return keep.sum() / lit.sum(), np.mean(wrong[keep]), result.object.info


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("thresholds", ["inverse", "white-black", "fringe-mean"])
def test_binary_code_orders(tmp_path: Path, thresholds: str, seed: int) -> None:
    """``binary`` planes (cell s carries s): 6 bits complementary to 32 fringes (two cells per period)."""
    kept, wrong, info = _order_errors(tmp_path, (32,), _code_planes("binary", 6, None, thresholds), seed)
    assert info["code"]["kind"] == "binary" and info["code"]["cells_per_period"] == 2.0
    assert kept > 0.95, kept
    assert wrong < 0.002, wrong


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("kind", ["gray", "binary"])
def test_cells_of_a_given_width(tmp_path: Path, kind: str, seed: int) -> None:
    """``period_px``: 6 bits of 20-px cells (1280 px, more than the 912-px projector) under 40-px fringes,
    912 / 40 = 22.8 fringes: no projector size has to be made up for the cells to be 2**bits."""
    kept, wrong, info = _order_errors(tmp_path, (22.8,), _code_planes(kind, 6, 20, "inverse"), seed)
    assert info["code"]["cell_px"] == 20 and info["code"]["resolves"] == "frequency 22.8"
    assert kept > 0.95, kept
    assert wrong < 0.002, wrong


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("thresholds", ["inverse", "fringe-mean"])
def test_code_under_two_frequencies(tmp_path: Path, thresholds: str, seed: int) -> None:
    """kamino410's layout scaled down: 40-px Gray cells under 40-px and 80/3-px fringes (22.8 and 34.2
    fringes). Their beat (80 px, two cells) is what the code resolves; 22.8 and 34.2 follow."""
    kept, wrong, info = _order_errors(tmp_path, (22.8, 34.2), _code_planes("gray", 5, 40, thresholds), seed)
    assert info["code"]["resolves"] == "beat 11.4" and info["code"]["cells_per_period"] == pytest.approx(2.0)
    assert info["code"]["margin_periods"] == pytest.approx(0.25)
    assert kept > 0.95, kept
    assert wrong < 0.002, wrong


def test_code_under_a_finer_frequency_alone(tmp_path: Path) -> None:
    """Periods of several cells: 8 plain Gray bits over the projector (3.56-px cells) under 64 and 96
    fringes (4 and 2.67 cells per period): the highest frequency with two cells or more is resolved."""
    kept, wrong, info = _order_errors(tmp_path, (64, 96), _code_planes("gray", 8, None, "inverse"), SEEDS[0])
    assert info["code"]["resolves"] == "frequency 96"
    assert kept > 0.95 and wrong < 0.002, (kept, wrong)


def test_rung_choice() -> None:
    """What the code resolves: a captured period or a beat with two cells or more, else one with one cell."""
    assert temporal.code_rung([19.2, 28.8], 100 / 1920).frequency == pytest.approx(9.6)  # kamino410: the beat
    plain = temporal.code_rung([16], 1 / 16)
    assert plain.aligned and plain.pair == (0,)
    complementary = temporal.code_rung([16], 1 / 32)
    assert complementary.cells_per_period == 2.0 and not complementary.aligned
    assert temporal.code_rung([40, 41], 1 / 16).frequency == 1  # periods of 0.4 cells, but their beat spans 16
    with pytest.raises(ValueError, match="wider than every fringe period"):
        temporal.code_rung([40, 60], 1 / 16)


def test_unwrap_coded_analytic() -> None:
    """Exact inputs: every order of the highest frequency right, including on the cells' borders."""
    width = 1920.0
    u = (np.arange(1920) + 0.5)[None, :].repeat(2, axis=0)
    freqs = [19.2, 28.8]
    phis = [np.angle(np.exp(2j * np.pi * f * u / width)) for f in freqs]
    stripes = np.floor(u / 100).astype(np.int64)
    result = temporal.unwrap_coded(phis, freqs, stripes, 100 / width)
    assert result.valid.all()
    np.testing.assert_allclose(result.phase, 2 * np.pi * 28.8 * u / width, atol=1e-9)
    # a stripe decoded one cell off at a border: the beat's two cells per period absorb it
    stripes[:, 300] -= 1  # u = 300.5 sits 0.5 px past the border at 300
    again = temporal.unwrap_coded(phis, freqs, stripes, 100 / width)
    np.testing.assert_allclose(again.phase, result.phase, atol=1e-9)


def test_binary_and_period_in_the_spec() -> None:
    """``binary:bits=N`` and ``period=P`` in `rig import`'s spec; column then row codes, OpenCV style."""
    patterns = parse_spec("binary:bits=3,period=100; gray:bits=2,inverted=interleaved,period=100,axis=y; white; black")
    assert [p.to_dict() for p in patterns[:1]] == [
        {"kind": "binary", "axis": "x", "bit": 0, "bits": 3, "inverted": False, "period_px": 100}
    ]
    assert [(p["kind"], p["axis"], p["bit"], p.get("inverted", False)) for p in patterns[3:7]] == [
        ("gray", "y", 0, False),
        ("gray", "y", 0, True),
        ("gray", "y", 1, False),
        ("gray", "y", 1, True),
    ]
    with pytest.raises(ConfigError, match=r"period: expected a positive number, found '-4'"):
        parse_spec("gray:bits=3,period=-4")


def test_layouts_that_cannot_work(tmp_path: Path) -> None:
    """One clear line: cells wider than every period and beat; cells that do not cover the projector."""
    wide = _code_planes("gray", 5, 60, "inverse")  # 60-px cells under 45.6-px and 22.8-px fringes, beat 45.6 px
    _, paths = _scan(tmp_path / "wide", (20, 40), wide, SEEDS[0])
    with pytest.raises(ProcessingError, match=r"cells \(60 px\) are wider than every fringe period") as error:
        process(paths.capture, None, ProcessOptions(correction="none", unwrap="gray"))
    assert "\n" not in str(error.value)
    short = _code_planes("gray", 4, 20, "inverse")  # 16 cells of 20 px: 320 of 912 px
    _, paths = _scan(tmp_path / "short", (22.8,), short, SEEDS[0])
    with pytest.raises(ProcessingError, match=r"16 cells of 20 px cover 320 px; expected at least the projector's 912"):
        process(paths.capture, None, ProcessOptions(correction="none"))


def test_mixed_codes_on_one_axis_are_refused(tmp_path: Path) -> None:
    planes = _code_planes("gray", 3, None, "none") + [{"kind": "binary", "axis": "x", "bit": 0, "bits": 3}]
    _, paths = _scan(tmp_path, (8,), planes[:2] + planes[3:], SEEDS[0])
    with pytest.raises(CaptureError, match=r"patterns\[6\]\.kind: expected 'gray' like the other code planes along x"):
        process(paths.capture, None, ProcessOptions(correction="none"))


@pytest.mark.parametrize("seed", SEEDS)
def test_plain_code_borders_blurred(tmp_path: Path, seed: int) -> None:
    """One cell per period (5 Gray bits, 32 fringes): the cells' borders are the phase wraps, so a phase a
    little off the code, or blur, puts the two on different sides of a border for the pixels next to it.
    The code's bits say which border a pixel sits on (:func:`temporal.border_side`); with it, far fewer
    orders are off than with the cell as decoded."""
    # 640 x 480: a 28.5-px fringe period spans ~20 camera pixels, the blur (sigma 1.2 px) a few of them
    scan, _ = _scan(tmp_path, (32,), _code_planes("gray", 5, None, "inverse"), seed, scale=4)
    frames = np.stack([cv2.GaussianBlur(f.astype(np.float64), (0, 0), 1.2) for f in scan.object_frames])
    planes, inverse = frames[4::2], frames[5::2]
    # the phase a little off the code (0.1 rad, half a projector pixel here): a projector's gamma, a lens,
    # a registration does as much; near each border the phase has then wrapped where the code has not
    phi = phase_shift(frames[:4]).phase + 0.1
    stripes = temporal.decode_stripes(planes, inverse)
    truth = 2 * np.pi * 32 * scan.object_map.u / PROJECTOR_WIDTH
    inner = scan.object_map.lit & (np.abs(np.gradient(scan.object_map.u, axis=1)) < 20)  # not across a shadow edge
    side = temporal.border_side(planes, stripes, inverse)
    wrong = {}
    for name, border in (("as decoded", None), ("border side", side)):
        result = temporal.unwrap_coded([phi], [32], stripes, 1 / 32, side=border)
        wrong[name] = np.mean(np.abs(result.phase - truth)[inner] > np.pi)
    assert wrong["as decoded"] > 0.003, wrong  # measured 0.54 %: the pixels next to each border
    assert wrong["border side"] < 0.1 * wrong["as decoded"], wrong  # measured 0.001 %


def test_border_side_reads_integer_frames_as_numbers() -> None:
    """Plain Gray planes of 16-px cells, blurred by a 4-px box: next to each border the bit that changes there
    fades, and border_side names that border. 8-bit planes give the same sides as the same values in float (a
    plane darker than its inverse must not wrap around in uint8 arithmetic)."""
    u = (np.arange(1024) + 0.5) / 4.0  # 0.25-px samples across a 256-px axis
    box = np.ones(16) / 16.0

    def blurred(level: np.ndarray) -> np.ndarray:
        return np.convolve(np.pad(level, 8, mode="edge"), box, mode="same")[8:-8]

    planes = [Gray(bit=b, bits=4) for b in range(4)]
    normal = np.stack([20 + 200 * blurred(gray_intensity(p, u, 256.0)) for p in planes])[:, None, :]
    inverse = np.stack([20 + 200 * blurred(1 - gray_intensity(p, u, 256.0)) for p in planes])[:, None, :]
    normal8, inverse8 = np.rint(normal).astype(np.uint8), np.rint(inverse).astype(np.uint8)
    stripes = temporal.decode_stripes(normal8, inverse8)[0]
    sides = temporal.border_side(normal8, stripes[None, :], inverse8)[0]
    np.testing.assert_array_equal(sides, temporal.border_side(normal, stripes[None, :], inverse)[0])
    within = u % 16
    cell = np.floor(u / 16).astype(int)
    right = (within > 15.25) & (cell < 15) & (stripes == cell)  # the bit there under half its contrast
    left = (within < 0.75) & (cell > 0) & (stripes == cell)
    assert right.any() and left.any()
    assert np.all(sides[right] == 1) and np.all(sides[left] == -1)
    assert np.all(sides[(within > 3) & (within < 13)] == 0)  # away from the blur: no border named
