"""The thesis' Table 4.1 simulation protocol, shared by the RPCA benchmark and the correction tests.

Sphere cap R = 300 mm, 100 mm high; two frequencies f1 = 5, f2 = 8, six-step phase shifting,
white Gaussian noise at 15 dB SNR on every fringe image; reference plane and object rendered by
:mod:`rig.hardware.synthesis` with the synthesiser's default rig (l0 = 1000 mm, d0 = 250 mm,
f0 = 1/64 cycles/mm at 8 fringes, 410 x 307 mm field of view at any resolution, projector
footprint 1.25x the view). Wrapped phase by :mod:`processing.phase.shifting`, orders by
:func:`processing.unwrap.temporal.unwrap_two_frequency`; heights by eq. 1.15 at f2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mock_devices import synth
from processing.geometry.height import nmse, phase_to_height
from processing.phase.shifting import phase_shift
from processing.unwrap.temporal import unwrap_two_frequency
from rig.hardware.synthesis import demo_geometry, simulate_scan

TWO_PI = 2.0 * np.pi


@dataclass
class PhaseMaps:
    """One scene's phases at the high frequency f2."""

    absolute: np.ndarray  # unwrapped, with whatever order errors the noise caused
    wrapped: np.ndarray  # measured, in [-pi, pi)
    orders: np.ndarray  # as unwrap_two_frequency returns them
    truth: np.ndarray  # true absolute phase (NaN where unlit)
    mask: np.ndarray  # lit and unwrapped

    def oracle(self) -> np.ndarray:
        """The measured wrapped phase with the true fringe orders."""
        return self.wrapped + TWO_PI * np.rint((self.truth - self.wrapped) / TWO_PI)

    def order_errors(self) -> int:
        wrong = np.rint((self.absolute - self.truth) / TWO_PI) != 0
        return int(np.count_nonzero(wrong & self.mask))


@dataclass
class ProtocolCase:
    reference: PhaseMaps
    object: PhaseMaps
    height_mm: np.ndarray
    geometry: synth.RigGeometry

    @property
    def mask(self) -> np.ndarray:
        return self.reference.mask & self.object.mask

    def height(self, object_phase: np.ndarray, reference_phase: np.ndarray) -> np.ndarray:
        g = self.geometry
        return phase_to_height(object_phase - reference_phase, g.l0_mm, g.d0_mm, g.f0_per_mm)

    def nmse_h(self, object_phase: np.ndarray, reference_phase: np.ndarray) -> float:
        """NMSE of the heights (thesis eq. 2.18) over pixels valid in both scenes."""
        return nmse(self.height(object_phase, reference_phase), self.height_mm, self.mask)


def _phase_maps(
    frames: np.ndarray,
    mapping: synth.ProjectorMap,
    geometry: synth.RigGeometry,
    frequencies: tuple[int, int],
    steps: int,
) -> PhaseMaps:
    f1, f2 = frequencies
    phi1 = phase_shift(frames[:steps]).phase
    phi2 = phase_shift(frames[steps:]).phase
    unwrapped = unwrap_two_frequency(phi1, phi2, f1, f2)
    mask = mapping.lit & unwrapped.valid
    return PhaseMaps(
        absolute=np.where(mask, unwrapped.phase, np.nan),
        wrapped=phi2,
        orders=unwrapped.orders,
        truth=synth.true_absolute_phase(mapping, geometry, f2),
        mask=mask,
    )


def table41_case(
    width: int = 1000,
    height: int = 1000,
    snr_db: float = 15.0,
    seed: int = 0,
    scene: str = "sphere-cap",
    frequencies: tuple[int, int] = (5, 8),
    steps: int = 6,
) -> ProtocolCase:
    """Simulate the Table 4.1 protocol at ``width`` x ``height`` (the thesis: 1000 x 1000)."""
    geometry = demo_geometry(width, height)
    patterns = synth.sinusoid_patterns(frequencies, steps)
    scan = simulate_scan(scene, geometry, patterns, synth.Appearance(snr_db=snr_db), seed=seed)
    return ProtocolCase(
        reference=_phase_maps(scan.reference_frames, scan.reference_map, geometry, frequencies, steps),
        object=_phase_maps(scan.object_frames, scan.object_map, geometry, frequencies, steps),
        height_mm=scan.height_mm,
        geometry=geometry,
    )
