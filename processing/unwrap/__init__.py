"""Absolute (or spatially continuous) phase from wrapped phases.

Main entry points:

- temporal methods (``temporal``), one per pattern family, all returning :class:`UnwrapResult`:
  :func:`unwrap_two_frequency`, :func:`unwrap_three_frequency`, :func:`unwrap_hierarchical`,
  :func:`unwrap_heterodyne`, :func:`unwrap_gray` (with :func:`decode_gray`); ``TEMPORAL_METHODS``
  names them.
- :func:`unwrap_spatial` and :func:`unwrap_quality_guided` (``spatial``): relative phase from one
  wrapped map, for captures without a second frequency.
- :func:`single_shot_unwrap` (``single_shot``): absolute phase of one speckle-embedded fringe image
  against a reference from :func:`prepare_reference`.
- ``fused_pass.fringe_pass``: wrapped phases, mask and temporal unwrapping of a whole capture in one
  blockwise float32 pass (:class:`FringePass`).
- :func:`rescue` (``neighbour_rescue``): re-admit well-modulated pixels a temporal method rejected.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from processing._lazy import lazy_exports

if TYPE_CHECKING:
    from processing.unwrap.fused_pass import FringePass
    from processing.unwrap.neighbour_rescue import rescue
    from processing.unwrap.single_shot import (
        SingleShotReference,
        SingleShotResult,
        prepare_reference,
        single_shot_unwrap,
    )
    from processing.unwrap.spatial import unwrap_quality_guided, unwrap_spatial
    from processing.unwrap.temporal import (
        TEMPORAL_METHODS,
        UnwrapResult,
        decode_gray,
        unwrap_gray,
        unwrap_heterodyne,
        unwrap_hierarchical,
        unwrap_three_frequency,
        unwrap_two_frequency,
    )

_SOURCES = {
    "TEMPORAL_METHODS": "temporal",
    "UnwrapResult": "temporal",
    "decode_gray": "temporal",
    "unwrap_gray": "temporal",
    "unwrap_heterodyne": "temporal",
    "unwrap_hierarchical": "temporal",
    "unwrap_three_frequency": "temporal",
    "unwrap_two_frequency": "temporal",
    "unwrap_quality_guided": "spatial",
    "unwrap_spatial": "spatial",
    "SingleShotReference": "single_shot",
    "SingleShotResult": "single_shot",
    "prepare_reference": "single_shot",
    "single_shot_unwrap": "single_shot",
    "FringePass": "fused_pass",
    "rescue": "neighbour_rescue",
}

__all__ = [
    "FringePass",
    "SingleShotReference",
    "SingleShotResult",
    "TEMPORAL_METHODS",
    "UnwrapResult",
    "decode_gray",
    "prepare_reference",
    "rescue",
    "single_shot_unwrap",
    "unwrap_gray",
    "unwrap_heterodyne",
    "unwrap_hierarchical",
    "unwrap_quality_guided",
    "unwrap_spatial",
    "unwrap_three_frequency",
    "unwrap_two_frequency",
]

__getattr__, __dir__ = lazy_exports(__name__, _SOURCES)
