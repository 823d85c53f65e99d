"""Robust PCA and what builds on it: low-rank plus sparse decomposition, fringe-image denoising.

Main entry points:

- :func:`rpca_ialm` and :func:`rpca_adm` (``rpca``): M = L + S by inexact augmented Lagrange
  multipliers or alternating directions, returning :class:`RPCAResult`.
- :func:`rpca_denoise_stack` and :func:`rpca_denoise_frame` (``frames``): fringe images denoised
  frame by frame before phase shifting.
- :func:`singular_value_threshold` (``svd``): the shrinkage step, by full or subspace SVD.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from processing._lazy import lazy_exports

if TYPE_CHECKING:
    from processing.denoise.frames import rpca_denoise_frame, rpca_denoise_stack
    from processing.denoise.rpca import RPCAResult, rpca_adm, rpca_ialm
    from processing.denoise.svd import SVD_METHODS, singular_value_threshold

_SOURCES = {
    "RPCAResult": "rpca",
    "rpca_adm": "rpca",
    "rpca_ialm": "rpca",
    "rpca_denoise_frame": "frames",
    "rpca_denoise_stack": "frames",
    "SVD_METHODS": "svd",
    "singular_value_threshold": "svd",
}

__all__ = [
    "RPCAResult",
    "SVD_METHODS",
    "rpca_adm",
    "rpca_denoise_frame",
    "rpca_denoise_stack",
    "rpca_ialm",
    "singular_value_threshold",
]

__getattr__, __dir__ = lazy_exports(__name__, _SOURCES)
