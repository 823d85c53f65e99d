"""Wrapped phase from fringe images: N-step phase shifting, Fourier-transform profilometry (FTP),
and checks that a capture follows the phase convention it claims.

Main entry points:

- :func:`phase_shift` (``shifting``): wrapped phase, background and modulation of an N-step stack;
  :func:`wrapped_phase` for the phase alone, :func:`shadow_mask` and :func:`quality_map` to judge it.
- :func:`ftp_phase` (``ftp``; :func:`ftp_amplitude` its amplitude alone, float32): wrapped phase of a single fringe image, around a carrier found by
  :func:`detect_carrier`.
- :func:`fuse_exposures` (``exposure_fusion``): frames of several exposures fused per pixel by
  inverse-variance weights (saturated frames left out), with the camera's :func:`noise_model`.
- :func:`heterodyne_offset`, :func:`gray_offset` (``convention``): the phase offset a capture's
  images carry against its stated convention.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from processing._lazy import lazy_exports

if TYPE_CHECKING:
    from processing.phase.convention import OffsetEstimate, gray_offset, heterodyne_offset
    from processing.phase.exposure_fusion import FusedExposures, NoiseModel, fuse_exposures, noise_model
    from processing.phase.ftp import FringeParts, detect_carrier, ftp_amplitude, ftp_fringe_parts, ftp_phase
    from processing.phase.shifting import PhaseShiftResult, phase_shift, quality_map, shadow_mask, wrapped_phase

_SOURCES = {
    "PhaseShiftResult": "shifting",
    "phase_shift": "shifting",
    "quality_map": "shifting",
    "shadow_mask": "shifting",
    "wrapped_phase": "shifting",
    "FringeParts": "ftp",
    "detect_carrier": "ftp",
    "ftp_amplitude": "ftp",
    "ftp_fringe_parts": "ftp",
    "ftp_phase": "ftp",
    "OffsetEstimate": "convention",
    "gray_offset": "convention",
    "heterodyne_offset": "convention",
    "FusedExposures": "exposure_fusion",
    "NoiseModel": "exposure_fusion",
    "fuse_exposures": "exposure_fusion",
    "noise_model": "exposure_fusion",
}

__all__ = [
    "FringeParts",
    "FusedExposures",
    "NoiseModel",
    "OffsetEstimate",
    "PhaseShiftResult",
    "detect_carrier",
    "ftp_amplitude",
    "ftp_fringe_parts",
    "ftp_phase",
    "fuse_exposures",
    "gray_offset",
    "heterodyne_offset",
    "noise_model",
    "phase_shift",
    "quality_map",
    "shadow_mask",
    "wrapped_phase",
]

__getattr__, __dir__ = lazy_exports(__name__, _SOURCES)
