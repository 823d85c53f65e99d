"""Import a projector-camera calibration from an OpenCV FileStorage file (YAML or XML).

The layout is the one SLMaster and similar tools write (``caliInfo.yml``): ``M1``/``D1`` camera
matrix and distortion, ``M4``/``D4`` projector matrix and distortion, ``Rlp``/``Tlp`` rotation and
translation (mm) from the camera to the projector, ``S`` the camera size (width, height). The
file does not say the projector's resolution; it comes from the caller (the capture's
``projector`` entry, or the command line).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from calibration.errors import CalibrationError
from calibration.stereo import STEREO, StereoModel

# calibration.json key <- FileStorage node
LAYOUT = {
    "camera_matrix": "M1",
    "distortion": "D1",
    "projector_matrix": "M4",
    "projector_distortion": "D4",
    "rotation": "Rlp",
    "translation_mm": "Tlp",
    "camera_size": "S",
}


# How an OpenCV FileStorage file starts (YAML, XML, JSON): anything else is refused before OpenCV parses it.
FILESTORAGE_HEADS = (b"%YAML", b"<?xml", b"{")


def read_filestorage(path: str | os.PathLike[str], names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Matrices ``names`` of an OpenCV FileStorage file; CalibrationError naming a missing one."""
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"{path}: missing (expected an OpenCV FileStorage .yml/.xml calibration)")
    try:
        with open(path, "rb") as handle:
            head = handle.read(64).lstrip()
    except OSError as exc:
        raise CalibrationError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if not head.startswith(FILESTORAGE_HEADS):
        raise CalibrationError(f"{path}: expected an OpenCV FileStorage file (starting with %YAML, <?xml or {{), found {head[:16]!r}")
    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except Exception as exc:  # cv2.error in OpenCV 4; OpenCV 5 raises SystemError and others for the same file
        message = (str(exc).strip().splitlines() or [type(exc).__name__])[-1]
        raise CalibrationError(f"{path}: not an OpenCV FileStorage file ({message})") from None
    if not storage.isOpened():
        raise CalibrationError(f"{path}: cannot be opened as an OpenCV FileStorage file")
    try:
        out = {}
        for name in names:
            node = storage.getNode(name)
            if node.empty():
                raise CalibrationError(f"{path}: {name}: missing (expected keys {', '.join(names)})")
            matrix = node.mat() if node.isMap() else None
            if matrix is None:
                if node.isSeq():
                    matrix = np.array([node.at(i).real() for i in range(node.size())])
                else:
                    raise CalibrationError(f"{path}: {name}: expected a matrix")
            out[name] = np.asarray(matrix, dtype=np.float64)
        return out
    finally:
        storage.release()


def import_opencv_calibration(
    path: str | os.PathLike[str], projector_size: tuple[int, int], pixel_centre: float = 0.5
) -> dict[str, Any]:
    """calibration.json fields (model ``stereo``) from an M1/D1/M4/D4/Rlp/Tlp/S FileStorage file.

    Parameters
    ----------
    path : path
        The FileStorage file (e.g. SLMaster's ``caliInfo.yml``).
    projector_size : (width, height)
        Projector resolution in pixels (the pattern extent the phase refers to).
    pixel_centre : float
        Where OpenCV's pixel k sits in the product's projector coordinate (0.5: centres at k + 0.5).
    """
    nodes = read_filestorage(path, tuple(LAYOUT.values()))
    fields: dict[str, Any] = {"model": STEREO}
    for key, name in LAYOUT.items():
        value = nodes[name]
        fields[key] = value.reshape(3, 3).tolist() if key.endswith("matrix") or key == "rotation" else value.ravel().tolist()
    fields["camera_size"] = [int(round(v)) for v in fields["camera_size"]]
    fields["projector_size"] = [int(v) for v in projector_size]
    fields["pixel_centre"] = float(pixel_centre)
    fields["imported_from"] = {"file": Path(path).name, "layout": "OpenCV FileStorage M1/D1/M4/D4/Rlp/Tlp/S"}
    StereoModel.from_fields(fields, where=str(path))
    return fields
