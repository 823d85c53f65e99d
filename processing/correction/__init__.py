"""Corrections of an unwrapped phase: wrong fringe orders, phase errors, shadows and specks.

Every method takes the absolute and the wrapped phase and returns the corrected phase with what it
did; :data:`CORRECTIONS` (``registry``) names them and :func:`correct` runs one by name
(``auto`` picks per capture, :func:`correct_auto`).

Main entry points:

- :func:`correct` / :data:`CORRECTIONS` (``registry``), with the method type
  :class:`CorrectionMethod` (``method``).
- :func:`vote_row_orders` (``voting``): Ding's fringe-order vote along rows;
  :func:`pool_region_orders` (``region_orders``): the same vote over 2-D fringe regions.
- :func:`correct_orders_rpca` (``orders``) and :func:`correct_phase_rpca` (``phase_rpca``): fringe
  orders and phase errors corrected by robust PCA.
- :func:`fill_shadows` and :func:`valid_mask` (``shadow_fill``), :func:`island_mask` (``islands``):
  what the corrections do with invalid pixels.
- :func:`undersampled_for_spatial_methods` (``sampling``): whether spatial corrections may run.
- :func:`keep_temporally_supported` (``temporal_evidence``): order changes weighed against the
  capture's lower frequencies.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from processing._lazy import lazy_exports

if TYPE_CHECKING:
    from processing.correction.islands import island_mask
    from processing.correction.method import CorrectionMethod
    from processing.correction.orders import correct_orders_rpca
    from processing.correction.phase_rpca import correct_phase_rpca
    from processing.correction.region_orders import pool_region_orders
    from processing.correction.registry import CORRECTIONS, correct, correct_auto
    from processing.correction.sampling import fringe_step_rad, undersampled_for_spatial_methods
    from processing.correction.shadow_fill import fill_shadows, valid_mask
    from processing.correction.temporal_evidence import keep_temporally_supported
    from processing.correction.voting import vote_row_orders

_SOURCES = {
    "CORRECTIONS": "registry",
    "correct": "registry",
    "correct_auto": "registry",
    "CorrectionMethod": "method",
    "vote_row_orders": "voting",
    "pool_region_orders": "region_orders",
    "correct_orders_rpca": "orders",
    "correct_phase_rpca": "phase_rpca",
    "fill_shadows": "shadow_fill",
    "valid_mask": "shadow_fill",
    "island_mask": "islands",
    "fringe_step_rad": "sampling",
    "undersampled_for_spatial_methods": "sampling",
    "keep_temporally_supported": "temporal_evidence",
}

__all__ = [
    "CORRECTIONS",
    "CorrectionMethod",
    "correct",
    "correct_auto",
    "correct_orders_rpca",
    "correct_phase_rpca",
    "fill_shadows",
    "fringe_step_rad",
    "island_mask",
    "keep_temporally_supported",
    "pool_region_orders",
    "undersampled_for_spatial_methods",
    "valid_mask",
    "vote_row_orders",
]

__getattr__, __dir__ = lazy_exports(__name__, _SOURCES)
