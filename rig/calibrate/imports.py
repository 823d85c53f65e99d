"""Calibrations made elsewhere, written as this product's calibration directory: an OpenCV
FileStorage projector-camera calibration becomes a ``stereo`` calibration.json (the file format
and the layouts read are :mod:`calibration.opencv_yaml`'s). ``rig calibrate --import-opencv`` and
the console's import both call :func:`import_opencv`.
"""

from __future__ import annotations

import os
from pathlib import Path

from rig.errors import OutputError
from rig.store import files


def import_opencv(
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    projector_size: tuple[int, int],
    camera_size: tuple[int, int] | None = None,
    pixel_centre: float = 0.5,
    overwrite: bool = False,
) -> Path:
    """Write ``output/calibration.json`` (model ``stereo``) from the FileStorage file ``source``; its path.

    The target is checked before the file is read and written atomically (a staging sibling
    renamed into place): a file that does not fit leaves nothing behind.
    """
    from calibration.opencv_yaml import import_opencv_calibration
    from calibration.store import Calibration, write_calibration

    output = Path(output)
    files.check_writable(output, ("calibration",), overwrite, OutputError)
    fields = import_opencv_calibration(source, projector_size, pixel_centre=pixel_centre, camera_size=camera_size)
    fields.pop("model")
    with files.staged_directory(output, ("calibration",), overwrite, OutputError) as staging:
        write_calibration(staging, Calibration(model="stereo", extra=fields))
    return output / "calibration.json"
