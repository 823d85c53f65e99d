"""The speckle-embedded pattern of thesis ch. 2.3: the three speckle rules, seeding, and the pattern maths."""

import numpy as np
import pytest

from processing.projection.patterns import pattern_image, pattern_intensity, sinusoid_intensity
from processing.projection.speckle import check_speckle_rules, speckle_dots, speckle_field


@pytest.mark.parametrize("dot_px", [1, 2, 3])
@pytest.mark.parametrize("seed", [0, 7])
def test_field_follows_the_three_rules(dot_px, seed):
    field = speckle_field(200, 150, seed, dot_px=dot_px)
    assert field.shape == (150, 200)
    assert check_speckle_rules(field, dot_px) == []
    # One white dot in every 3x3-dot cell: 1/9 of the whole cells' pixels are white.
    whole = 9 * dot_px
    rows, cols = (150 // whole) * whole, (200 // whole) * whole
    assert field[:rows, :cols].mean() == pytest.approx(1 / 9)


def test_dot_grid_rules_hold_exactly_on_a_large_grid():
    dots = speckle_dots(120, 90, seed=3)
    cells = dots.reshape(120, 3, 90, 3).sum(axis=(1, 3))
    assert np.all(cells == 1)
    padded = np.pad(dots, 1)
    neighbours = sum(
        padded[1 + dy : 1 + dy + dots.shape[0], 1 + dx : 1 + dx + dots.shape[1]]
        for dy in (-1, 0, 1)
        for dx in (-1, 0, 1)
        if dy or dx
    )
    assert not np.any(dots & (neighbours > 0))
    # The draw is random: every one of the nine positions is used.
    positions = np.argwhere(dots) % 3
    assert len({tuple(p) for p in positions}) == 9


def test_seed_reproduces_and_changes_the_field():
    a = speckle_field(90, 90, 11)
    assert np.array_equal(a, speckle_field(90, 90, 11))
    assert not np.array_equal(a, speckle_field(90, 90, 12))


def test_checker_reports_each_rule():
    field = speckle_field(54, 54, 1, dot_px=3)
    broken_block = field.copy()
    white = np.argwhere(field == 1)[0]
    broken_block[tuple(white)] = 0  # part of a white dot goes dark: rule 1
    assert any(v.startswith("rule 1") for v in check_speckle_rules(broken_block, 3))

    empty_cell = field.copy()
    empty_cell[0:9, 0:9] = 0  # a whole cell without its dot: rule 2
    assert any(v.startswith("rule 2") for v in check_speckle_rules(empty_cell, 3))

    touching = np.zeros((54, 54))
    touching[0:3, 0:3] = 1
    touching[3:6, 3:6] = 1  # diagonal neighbours in the dot grid: rule 3 (and rule 2)
    problems = check_speckle_rules(touching, 3)
    assert any(v.startswith("rule 3") for v in problems)
    assert check_speckle_rules(np.full((9, 9), 0.5), 3) == ["values: expected only 0 and 1"]


@pytest.mark.parametrize("bad", [{"width": 0}, {"height": -3}, {"dot_px": 0}, {"seed": 1.5}])
def test_bad_arguments_name_the_argument(bad):
    kwargs = {"width": 30, "height": 30, "seed": 0, "dot_px": 3} | bad
    name = next(iter(bad))
    with pytest.raises(ValueError, match=name):
        speckle_field(**kwargs)


def test_pattern_is_scaled_sinusoid_plus_speckle_inside_unit_range():
    size = (96, 72)
    pattern = {
        "kind": "speckle-sinusoid",
        "axis": "x",
        "frequency": 4,
        "steps": 1,
        "step": 0,
        "seed": 5,
        "dot_px": 2,
        "speckle_gain": 0.25,
    }
    image = pattern_image(pattern, size)
    assert image.min() >= 0.0 and image.max() <= 1.0
    u = np.arange(size[0]) + 0.5
    v = np.arange(size[1]) + 0.5
    uu, vv = np.meshgrid(u, v)
    fringe = sinusoid_intensity(pattern, uu, size[0])
    z = speckle_field(size[0], size[1], 5, dot_px=2)
    np.testing.assert_allclose(image, 0.75 * fringe + 0.25 * z, atol=1e-6)
    # Sampled at the projector pixel containing (u, v): a shift inside a pixel changes nothing
    # of the speckle term.
    shifted = pattern_intensity(pattern, uu + 0.3, vv + 0.4, size) - 0.75 * sinusoid_intensity(
        pattern, uu + 0.3, size[0]
    )
    np.testing.assert_allclose(shifted, 0.25 * z, atol=1e-9)


def test_pattern_refuses_gain_outside_unit_range():
    pattern = {"kind": "speckle-sinusoid", "frequency": 4, "steps": 1, "step": 0, "speckle_gain": 1.5}
    with pytest.raises(ValueError, match="speckle_gain"):
        pattern_image(pattern, (32, 32))
