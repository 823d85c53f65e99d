"""processing.correction.phase_rpca.order_breaks_since: the whole map's order breaks, recounted near the changes."""

from __future__ import annotations

import numpy as np
import pytest

from processing.correction import phase_rpca
from processing.correction.phase_rpca import order_breaks, order_breaks_since


@pytest.mark.parametrize("seed", range(6))
def test_the_recount_equals_the_whole_map_count(seed: int) -> None:
    rng = np.random.default_rng(seed)
    rows, cols = rng.integers(3, 60, size=2)
    x = np.arange(cols)[None, :] * rng.uniform(0.1, 2.5)
    previous = x + 0.3 * np.arange(rows)[:, None] + rng.normal(0.0, 0.4, (rows, cols))
    previous += 2 * np.pi * (rng.random((rows, cols)) < 0.1) * rng.integers(-2, 3, (rows, cols))
    valid = rng.random((rows, cols)) > 0.15
    previous[~valid & (rng.random((rows, cols)) < 0.5)] = np.nan  # whatever lies outside the mask is never read
    phase = previous.copy()
    changes = rng.random((rows, cols)) < 0.02  # at borders and corners too
    changes[0, 0] = changes[-1, -1] = True
    phase[changes] += 2 * np.pi * rng.integers(-3, 4, int(changes.sum()))
    phase[rng.random((rows, cols)) < 0.01] = np.nan  # NaN inside the mask never counts
    assert order_breaks_since(phase, previous, order_breaks(previous, valid), valid) == order_breaks(phase, valid)


def test_a_map_that_differs_widely_is_counted_whole(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(7)
    previous = rng.normal(0.0, 2.0, (20, 30))
    phase = previous + 2 * np.pi * (rng.random(previous.shape) < 0.5)
    valid = np.ones(previous.shape, dtype=bool)
    calls = []
    monkeypatch.setattr(phase_rpca, "order_breaks", lambda p, v: calls.append(1) or order_breaks(p, v))
    assert order_breaks_since(phase, previous, order_breaks(previous, valid), valid) == order_breaks(phase, valid)
    assert calls  # half the map differs: the whole-map count
    calls.clear()
    phase = previous.copy()
    phase[3, 4] += 2 * np.pi
    assert order_breaks_since(phase, previous, order_breaks(previous, valid), valid) == order_breaks(phase, valid)
    assert not calls  # one pixel differs: recounted near it
