"""From phase to geometry: height maps, point clouds and triangle meshes.

Main entry points:

- :func:`phase_to_height` and :func:`height_to_phase` (``height``): the reference-plane phase-height
  model; :func:`point_cloud` turns a height map into points.
- :func:`grid_triangles` (``mesh``): triangles over the valid pixel grid, without bridging jumps.
- :func:`phase_sigma` and :func:`height_sigma` (``uncertainty``): each pixel's predicted standard
  deviation from the capture's own noise (:func:`noise_sigma`).
- :func:`plane_heights` (``plane_model``): the reference-plane model's heights, their sigma and
  the valid mask in one blocked pass.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from processing._lazy import lazy_exports

if TYPE_CHECKING:
    from processing.geometry.height import height_to_phase, phase_to_height, point_cloud
    from processing.geometry.mesh import grid_triangles
    from processing.geometry.plane_model import plane_heights
    from processing.geometry.uncertainty import height_sigma, noise_sigma, phase_sigma

_SOURCES = {
    "height_to_phase": "height",
    "phase_to_height": "height",
    "point_cloud": "height",
    "grid_triangles": "mesh",
    "plane_heights": "plane_model",
    "height_sigma": "uncertainty",
    "noise_sigma": "uncertainty",
    "phase_sigma": "uncertainty",
}

__all__ = [
    "grid_triangles",
    "height_sigma",
    "height_to_phase",
    "noise_sigma",
    "phase_sigma",
    "phase_to_height",
    "plane_heights",
    "point_cloud",
]

__getattr__, __dir__ = lazy_exports(__name__, _SOURCES)
