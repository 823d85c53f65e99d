"""What a processing run gives back: :class:`ProcessResult` and the report (report.json's content).

Its own module so that the run (:mod:`rig.pipeline.run`), the file encoders
(:mod:`rig.store.result_files`) and the result store (:mod:`rig.store.results`) all import it
without importing each other.
"""

from __future__ import annotations

import platform
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration import models as calibration_models
from calibration.store import Calibration
from processing.geometry.uncertainty import summary as uncertainty_summary
from rig import __version__
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.state import SceneState
from rig.store import files as safe_files


@dataclass
class ProcessResult:
    """Everything `rig process` computed, ready to be written."""

    object: SceneState
    reference: SceneState | None
    calibration: Calibration | None
    options: ProcessOptions
    height: np.ndarray | None
    mask: np.ndarray
    timings: dict[str, Any]
    notes: list[str]
    point_grid: np.ndarray | None = None  # (H, W, 3) mm from the stereo model; else built on demand
    uncertainty: np.ndarray | None = None  # predicted height sigma (mm) per pixel, NaN where invalid

    def valid_sigma(self) -> np.ndarray | None:
        """Predicted sigma (N,) in mm of the valid pixels, in the order of :meth:`valid_points`; None if unknown."""
        return None if self.uncertainty is None else self.uncertainty[self.mask]

    @property
    def points(self) -> np.ndarray | None:
        """Points (H, W, 3) in mm, NaN where invalid; None without a calibration."""
        if self.point_grid is None and self.height is not None:
            assert self.calibration is not None
            grid = calibration_models.plane_points(self.calibration, self.height).reshape(*self.height.shape, 3)
            grid[~self.mask] = np.nan
            self.point_grid = grid
        return self.point_grid

    def valid_points(self) -> np.ndarray:
        """Points (N, 3) in mm of the valid pixels, in C order of ``mask`` (what points.ply holds)."""
        if self.point_grid is not None:
            return self.point_grid[self.mask]
        assert self.calibration is not None and self.height is not None
        return calibration_models.plane_points(self.calibration, self.height, self.mask)

    @property
    def report(self) -> dict[str, Any]:
        """report.json's content (without the files, which only the result store knows)."""
        return build_report(self)

    @property
    def phase(self) -> np.ndarray:
        assert self.object.unwrapped is not None
        return self.object.unwrapped.phase


def _methods(result: ProcessResult) -> dict[str, Any]:
    """report.json's ``methods``: what was asked and what was used."""
    obj, options = result.object, result.options
    assert obj.unwrapped is not None and obj.wrapped is not None
    return {
        "wrapped_phase": "phase-shifting" if obj.groups.sinusoids else "single-shot",
        "unwrap": obj.unwrapped.method,
        "unwrap_requested": options.unwrap,
        "absolute_phase": obj.unwrapped.absolute,
        "denoise": options.denoise,
        "correction": options.correction,
        # true: the frames; "rays": the stereo triangulation undistorts each ray; false: neither
        "undistorted": obj.info.get("undistorted", False),
        "fringe_axis": obj.info.get("axis_choice", {}).get("axis", obj.axis),  # x, y or both (rig.pipeline.axes)
        "axis_choice": obj.info.get("axis_choice", {}).get("why"),
        "frequencies": obj.wrapped.frequencies,
        "phase_frequency": obj.unwrapped.frequency,
        "min_modulation_ratio": obj.info.get("validity", {}).get("min_modulation_ratio"),
        "max_sigma_mm": options.max_sigma,
        "validity": obj.info.get("validity"),  # rig.pipeline.stages: the noise or the modulation-ratio rule
        "min_island_fraction": options.min_island_fraction,
        "params": options.params,
    }


def _height_figures(result: ProcessResult) -> dict[str, Any]:
    """report.json's height range, point count, model and quantity (height or depth)."""
    assert result.calibration is not None and result.height is not None
    valid_h = result.height[result.mask]
    valid_h = valid_h[np.isfinite(valid_h)]  # report.json is strict JSON: no NaN or Infinity
    height_mm = (
        {"min": float(np.min(valid_h)), "max": float(np.max(valid_h)), "median": float(np.median(valid_h))}
        if valid_h.size
        else None
    )
    # stereo without a plane gives distance from the camera, not height above a plane
    depth = result.calibration.model == "stereo" and result.calibration.to_dict().get("plane") is None
    sigma = None if result.uncertainty is None else uncertainty_summary(result.uncertainty, result.mask)
    return {
        "height_mm": height_mm,
        "uncertainty_mm": sigma,
        "points": int(np.count_nonzero(result.mask)),
        "calibration_model": result.calibration.model,
        "quantity": "depth" if depth else "height",
    }


def build_report(result: ProcessResult, staged_inputs: tuple[Path, Path] | None = None) -> dict[str, Any]:
    """The report of a processing run (report.json without its ``files`` and output timing).

    ``staged_inputs`` (staging, final): the inputs were written into a staging directory that is
    committed as ``final`` (``rig demo``); the report names them where they will be.
    """
    obj = result.object
    assert obj.unwrapped is not None and obj.wrapped is not None

    def where(path: Path | None) -> str | None:
        if path is None:
            return None
        return str(safe_files.committed_path(path, *staged_inputs) if staged_inputs else path)

    report: dict[str, Any] = {
        "program": f"fpp-rig {__version__}",
        "capture": where(obj.capture.path),
        "calibration": where(result.calibration.path if result.calibration is not None else None),
        "reference": where(result.reference.capture.path if result.reference is not None else None),
        "methods": _methods(result),
        "image": {"width": obj.capture.width, "height": obj.capture.height},
        "valid_fraction": float(result.mask.mean()),
        "notes": list(result.notes),
    }
    if "unresolved" in obj.info.get("correction", {}):  # share of the valid pixels whose orders nothing settled
        report["unresolved_fraction"] = obj.info["correction"]["unresolved"]["fraction"]
    if result.height is None:
        report["wrapped_frequencies"] = obj.wrapped.frequencies
    else:
        report.update(_height_figures(result))
    report["timings_s"] = dict(result.timings)
    report["stage_info"] = {"object": obj.info, **({"reference": result.reference.info} if result.reference else {})}
    report["versions"] = _versions()
    return report


def _versions() -> dict[str, str]:
    import cv2
    import scipy

    return {
        "fpp-rig": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "opencv": cv2.__version__,
    }
