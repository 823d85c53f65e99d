"""Is the phase convention the capture claims the one its images follow? Evidence from the data itself.

A capture from another rig states (or its importer guesses) how each sinusoid's phase is defined.
If the images follow another convention (a pattern phase of pi, a reversed shift) every wrapped
phase carries the same offset, and the result is wrong without any visible failure. Two kinds
of capture carry redundant evidence that reveals the offset:

* Gray code: the code words mark projector positions independently of the sinusoid. With a
  complementary code (2**bits = 2 f stripes) even stripes cover the first half of each period
  (phase in [0, pi)) and odd stripes the second; with a plain code (2**bits = f) the stripe
  boundaries fall on the phase wraps. The offset is the circular mean of the measured phase
  minus the phase the code says (half-period centres, or 0 at the boundaries).
* Heterodyne (two or three close frequencies): a common offset cancels in the beats, so the
  beat chain predicts the finest phase without it; the offset is the circular mean of the
  finest measured phase minus the prediction. A correct convention gives residuals at the
  noise level (circular mean near 0).

:func:`gray_offset` and :func:`heterodyne_offset` return an :class:`OffsetEstimate`;
:meth:`OffsetEstimate.suspicious` says whether it is strong enough evidence of a wrong convention.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class OffsetEstimate:
    """Circular mean ``offset`` (rad, in (-pi, pi]) of measured minus expected phase.

    ``concentration`` is the mean resultant length (1: every sample agrees, 0: no common offset);
    ``samples`` the number of pixels (or boundary pixel pairs) used.
    """

    offset: float
    concentration: float
    samples: int

    def suspicious(self, min_offset: float = np.pi / 4, min_concentration: float = 0.5, min_samples: int = 200) -> bool:
        """A consistent offset of more than ``min_offset`` over enough samples: the convention is likely wrong."""
        return self.samples >= min_samples and self.concentration >= min_concentration and abs(self.offset) > min_offset


def _circular_mean(angles: np.ndarray) -> OffsetEstimate:
    angles = angles[np.isfinite(angles)]
    if angles.size == 0:
        return OffsetEstimate(0.0, 0.0, 0)
    resultant = np.exp(1j * angles).mean()
    return OffsetEstimate(float(np.angle(resultant)), float(np.abs(resultant)), int(angles.size))


def gray_offset(
    phi: np.ndarray,
    stripes: np.ndarray,
    bits: int,
    frequency: float,
    valid: np.ndarray | None = None,
    axis: str = "x",
    cell_periods: float | None = None,
) -> OffsetEstimate:
    """Offset of the wrapped phase ``phi`` against a decoded Gray-code (or binary-code) stripe index.

    Parameters
    ----------
    phi : (H, W) wrapped phase at ``frequency`` (any 2 pi representation; periods start at 0).
    stripes : (H, W) int stripe index decoded from ``bits`` planes.
    bits, frequency : the code's planes and the sinusoid's fringe count.
    valid : (H, W) bool, optional: pixels to use (default every finite phase).
    axis : the fringe axis (codes with one cell per period compare neighbours along it).
    cell_periods : width of one code cell in periods of ``frequency``, at most 1; default
        ``frequency / 2**bits``, which must then be 1 (plain) or 1/2 (complementary).

    With one cell per period the cells' borders are the phase wraps: the phase of two
    neighbours across a border points at the offset. With smaller cells each cell's centre
    predicts the phase 2 pi ((s + 1/2) cell_periods mod 1), which the phase spreads around.
    """
    phi = np.asarray(phi, dtype=np.float64)
    s = np.asarray(stripes).astype(np.int64)
    use = np.isfinite(phi) if valid is None else np.asarray(valid, dtype=bool) & np.isfinite(phi)
    count = 1 << bits
    use &= (s >= 0) & (s < count)
    if cell_periods is None:
        if count not in (frequency, 2 * frequency):
            raise ValueError(
                f"bits: expected 2**bits == frequency or 2 * frequency, found bits = {bits}, frequency = {frequency}"
            )
        cell_periods = frequency / count
    if not 0.0 < cell_periods <= 1.0 + 1e-9:
        raise ValueError(f"cell_periods: expected a cell of at most one period, found {cell_periods}")
    if abs(cell_periods - 1.0) > 1e-6:  # several cells per period: each cell's centre
        centre = (s + 0.5) * cell_periods
        expected = TWO_PI * (centre - np.floor(centre))
        return _circular_mean((phi - expected)[use])
    along = 1 if axis == "x" else 0
    a = [slice(None), slice(None)]
    b = [slice(None), slice(None)]
    a[along], b[along] = slice(None, -1), slice(1, None)
    boundary = (s[tuple(a)] != s[tuple(b)]) & use[tuple(a)] & use[tuple(b)]
    # the two pixels straddle the wrap: the mean of their unit phasors points at the boundary's phase
    pair = np.exp(1j * phi[tuple(a)][boundary]) + np.exp(1j * phi[tuple(b)][boundary])
    return _circular_mean(np.angle(pair))


def _turns(phi: np.ndarray) -> np.ndarray:
    t = phi / TWO_PI
    return t - np.floor(t)


def heterodyne_offset(
    phis: Sequence[np.ndarray], frequencies: Sequence[int], valid: np.ndarray | None = None
) -> OffsetEstimate:
    """Offset common to every wrapped phase of a heterodyne set (two frequencies with beat 1, or three
    whose beats differ by 1), measured as the finest phase minus what the beat chain predicts."""
    if len(phis) != len(frequencies) or len(phis) not in (2, 3):
        raise ValueError(f"phis, frequencies: expected two or three of each, found {len(phis)} and {len(frequencies)}")
    order = sorted(range(len(frequencies)), key=lambda i: -int(frequencies[i]))
    fs = [int(frequencies[i]) for i in order]
    turns = [_turns(np.asarray(phis[i], dtype=np.float64)) for i in order]
    if len(fs) == 2:
        unit = _turns(TWO_PI * (turns[0] - turns[1]))
        wide, f_wide = unit, 1
    else:
        ab, bc = _turns(TWO_PI * (turns[0] - turns[1])), _turns(TWO_PI * (turns[1] - turns[2]))
        beat_ab, beat_bc = fs[0] - fs[1], fs[1] - fs[2]
        unit = _turns(TWO_PI * (ab - bc)) if beat_ab > beat_bc else _turns(TWO_PI * (bc - ab))
        wide, f_wide = (ab, beat_ab) if beat_ab > beat_bc else (bc, beat_bc)
        wide = np.rint(unit * f_wide - wide) + wide  # absolute turns of the wide beat
    predicted = wide * (fs[0] / f_wide)
    residual = TWO_PI * (turns[0] - predicted)
    use = np.isfinite(residual) if valid is None else np.asarray(valid, dtype=bool) & np.isfinite(residual)
    return _circular_mean(residual[use])
