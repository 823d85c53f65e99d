"""Fringe projection profilometry in numpy: from fringe images to phase, height and meshes.

Pure array code, no I/O and nothing of the application; grouped by concern:

- :mod:`processing.phase`: wrapped phase (phase shifting, FTP, phase-convention checks);
- :mod:`processing.unwrap`: absolute phase (temporal, spatial, single-shot, the fused pass);
- :mod:`processing.correction`: fringe-order and phase-error corrections, shadows and specks;
- :mod:`processing.denoise`: robust PCA and fringe-image denoising;
- :mod:`processing.geometry`: height maps, point clouds, meshes;
- :mod:`processing.projection`: the pattern model the projector renders.

Each subpackage's ``__init__`` lists its public API; names are imported from their modules on first
use, so ``import processing.phase`` stays cheap. Shared internals live here: ``angles``
(phase wrapping), ``concurrency`` (running independent work side by side), ``_validate`` and
``_blockwise``.
"""

__all__ = ["correction", "denoise", "geometry", "phase", "projection", "unwrap"]
