"""Live view: single frames on the camera's software trigger, and what an operator reads off them.

While nothing is being acquired, a front-end (the console) shows the camera continuously so the
operator can set exposure, check saturation and focus and place the object. :func:`grab_frame`
takes one frame with a software trigger; :func:`frame_figures` measures it: the saturated fraction
and mask (pixels at full scale), a 256-bin histogram, a sharpness figure, and — while a fringe is
projected — the fringe modulation map from that one frame (Fourier-transform profilometry), thresholded the way
the processing pipeline keeps a pixel's phase (:func:`processing.phase.shifting.shadow_mask`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from drivers.camera import Camera, TriggerMode, TriggerSource
from processing.phase.ftp import ftp_amplitude
from processing.phase.shifting import shadow_mask

HISTOGRAM_BINS = 256


def grab_frame(camera: Camera, timeout_s: float = 1.0) -> np.ndarray:
    """One frame on the software trigger (the camera is switched to it and started if needed)."""
    if not camera.is_started:
        if camera.trigger_source is not TriggerSource.SOFTWARE or camera.trigger_mode is not TriggerMode.ONCE:
            camera.set_trigger(TriggerSource.SOFTWARE, TriggerMode.ONCE)
        camera.start()
    camera.trigger()
    return camera.fetch(timeout_s).image


@dataclass
class FrameFigures:
    """What one live frame says about exposure, focus and (under a fringe) phase quality."""

    mean: float  # mean level as a fraction of full scale
    saturated_fraction: float  # pixels at full scale
    saturated: np.ndarray  # (H, W) bool
    histogram: list[int]  # HISTOGRAM_BINS counts over 0 .. full scale
    focus: float  # variance of the Laplacian of the frame scaled to 0 .. 255
    modulation: np.ndarray | None  # (H, W) fringe amplitude as a fraction of full scale (fringe shown)
    valid: np.ndarray | None  # (H, W) bool: pixels whose phase the pipeline would keep
    valid_fraction: float | None
    levels: np.ndarray  # (H, W) uint8: the frame scaled to 0 .. 255, as the figures read it


def frame_figures(image: np.ndarray, max_value: int, fringe_axis: str | None = None) -> FrameFigures:
    """Figures of one live frame of a camera whose full scale is ``max_value``.

    ``fringe_axis`` ("x" or "y"): a sinusoidal fringe along that axis is projected, so the
    modulation map is computed too (None: no fringe, no map).
    """
    img = np.asarray(image)
    saturated = img >= max_value
    scale = 255.0 / max_value
    levels = img if img.dtype == np.uint8 and max_value == 255 else np.clip(img * scale, 0, 255).astype(np.uint8)
    histogram = np.bincount(levels.ravel(), minlength=HISTOGRAM_BINS)[:HISTOGRAM_BINS]
    focus = float(cv2.Laplacian(levels, cv2.CV_32F).var())
    modulation = valid = valid_fraction = None
    if fringe_axis in ("x", "y"):
        amplitude = ftp_amplitude(levels, axis=1 if fringe_axis == "x" else 0)
        modulation = amplitude / np.float32(255.0)
        valid = shadow_mask(amplitude)
        valid_fraction = float(valid.mean())
    return FrameFigures(
        mean=float(levels.mean()) / 255.0,
        saturated_fraction=float(saturated.mean()),
        saturated=saturated,
        histogram=[int(c) for c in histogram],
        focus=focus,
        modulation=modulation,
        valid=valid,
        valid_fraction=valid_fraction,
        levels=levels,
    )
