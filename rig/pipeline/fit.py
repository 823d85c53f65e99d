"""Does a calibration fit a capture? Every quantity the two share, checked before any processing.

A calibration made on one rig and a capture made (or imported) with other settings give a
plausible-looking but wrong 3-D result, so a mismatch is refused with one line naming the field,
both values, the likely cause and the fix:

* camera size: the calibration's ``camera_size`` (stereo) or its reference capture (reference
  plane, polynomial) against the capture's camera;
* projector extent along the fringe axis: phases are counted in fringes across the projector,
  so a capture imported without ``--projector-width`` decodes to wrong projector columns;
* fringe axis: the axes the calibration was fitted on (``fringe_axis``, or ``axes`` for a
  reference-plane model fitted on both) against the one processed;
* patterns and frequencies: the reference-plane capture must use the capture's patterns;
* units: lengths that are implausibly short for millimetres (a translation or distance written
  in metres);
* options: ``--no-undistort`` with a camera-projector model, whose triangulation undistorts every
  ray (:func:`refuse_kept_distortion`).
"""

from __future__ import annotations

from typing import Any

from calibration.errors import CalibrationError
from calibration.models import units_problem
from calibration.plane_axes import plane_axes
from calibration.stereo import STEREO
from calibration.store import Calibration
from rig.errors import CaptureError, ConfigError
from rig.pipeline.plan import ProcessOptions
from rig.store.capture import Capture, check_same_patterns


def _imported(capture: Capture) -> bool:
    return isinstance(capture.manifest.get("import"), dict)


def _size_fix(capture: Capture, flag: str, value: int) -> str:
    if _imported(capture):
        return f"the capture was likely imported without {flag} {value}; re-import it with {flag} {value}"
    return "the capture was likely made on another rig or with other projector settings; use that rig's calibration"


def check_fit(capture: Capture, calibration: Calibration, axis: str, reference: Capture | None = None) -> None:
    """Raise CalibrationError (one line: field, both values, likely cause, fix) if they do not fit."""
    where = calibration.where
    problem = units_problem(calibration)
    if problem is not None:
        raise CalibrationError(f"{where}: {problem}")
    fields: dict[str, Any] = calibration.to_dict()
    camera = fields.get("camera_size")
    if isinstance(camera, (list, tuple)) and len(camera) == 2:
        expected = (int(camera[0]), int(camera[1]))
        found = (capture.width, capture.height)
        if expected != found:
            raise CalibrationError(
                f"{capture.manifest_path}: camera: {found[0]}x{found[1]} does not fit {where} camera_size "
                f"{expected[0]}x{expected[1]}; likely cause: a cropped or downsampled capture (--crop, --downsample) "
                "or another camera; fix: process the full-size images, or calibrate at this size"
            )
    projector = fields.get("projector_size")
    if isinstance(projector, (list, tuple)) and len(projector) == 2:
        index = 0 if axis == "x" else 1
        expected_extent, found_extent = int(projector[index]), capture.projector_size[index]
        if expected_extent != found_extent:
            name, flag = ("width", "--projector-width") if axis == "x" else ("height", "--projector-height")
            raise CalibrationError(
                f"{capture.manifest_path}: projector {name}: {found_extent} px does not fit {where} projector_size "
                f"{projector[0]}x{projector[1]} (fringes are counted across the projector {name}, so every "
                f"depth would be wrong); {_size_fix(capture, flag, expected_extent)}"
            )
    fitted = plane_axes(calibration)
    if fitted and axis not in fitted:
        fitted_axis = next(iter(fitted))
        raise CalibrationError(
            f"{capture.manifest_path}: fringe axis: {axis} does not fit {where} fringe_axis {fitted_axis} "
            f"(the calibration was fitted on fringes along {fitted_axis}); fix: process with --axis {fitted_axis} "
            "if the capture has those fringes, else calibrate with fringes along " + axis
        )
    if reference is not None:
        try:
            check_same_patterns(reference, capture)
        except CaptureError as exc:
            raise CalibrationError(
                f"{where}: the reference capture does not fit this capture: {exc}; likely cause: the capture was "
                "made with other scan settings (frequencies, steps, sizes) than the calibration; fix: scan with "
                "the calibration's settings or calibrate again with these"
            ) from None


def refuse_kept_distortion(calibration: Calibration, options: ProcessOptions) -> None:
    """``--no-undistort`` with a camera-projector (stereo) calibration: refused (ConfigError).

    Its triangulation models the lens distortion of every camera and projector ray; the frames
    are never undistorted, so there is nothing that option could keep. Checked here so that
    ``rig process``, ``rig batch``, :func:`rig.api.process` and the console refuse alike.
    """
    if options.undistort is False and calibration.model == STEREO:
        raise ConfigError(
            f"--no-undistort: {calibration.where} is a camera-projector (stereo) calibration, whose triangulation "
            "models the lens distortion of every ray; leave --no-undistort out"
        )
