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

# What OpenCV raises for a file it cannot parse. cv2.error: the documented type; node reads raise it
# (a matrix whose data does not fit rows x cols, an unknown dt), and older OpenCV 4 releases raise
# it from the constructor too. SystemError: the FileStorage constructor on a syntax error in
# OpenCV 4.10, 4.14 and 5.0 alike ("returned a result with an exception set", the cv2.error as its
# __cause__). tests/test_hardening_edges.py runs the same files under each OpenCV it is given.
OPENCV_ERRORS: tuple[type[BaseException], ...] = (cv2.error, SystemError)


def _opencv_message(exc: BaseException) -> str:
    """The last line of OpenCV's message (or of its cause's), without the source location."""
    cause = exc.__cause__ if isinstance(exc, SystemError) and exc.__cause__ is not None else exc
    lines = str(cause).strip().splitlines() or [type(cause).__name__]
    return lines[-1].split(" error: ", 1)[-1][:200]


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
        raise CalibrationError(
            f"{path}: expected an OpenCV FileStorage file (starting with %YAML, <?xml or {{), found {head[:16]!r}"
        )
    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except OPENCV_ERRORS as exc:
        raise CalibrationError(f"{path}: not an OpenCV FileStorage file ({_opencv_message(exc)})") from None
    if not storage.isOpened():
        raise CalibrationError(f"{path}: cannot be opened as an OpenCV FileStorage file")
    try:
        return {name: _read_node(storage, name, path, names) for name in names}
    finally:
        storage.release()


def _read_node(storage: Any, name: str, path: Path, names: tuple[str, ...]) -> np.ndarray:
    """One matrix (an ``opencv-matrix`` map or a sequence of numbers) of an open FileStorage."""
    try:
        node = storage.getNode(name)
        if node.empty():
            raise CalibrationError(f"{path}: {name}: missing (expected keys {', '.join(names)})")
        if node.isMap():
            matrix = node.mat()
        elif node.isSeq() and all(node.at(i).isReal() or node.at(i).isInt() for i in range(node.size())):
            matrix = np.array([node.at(i).real() for i in range(node.size())])
        else:
            matrix = None
    except OPENCV_ERRORS as exc:
        raise CalibrationError(f"{path}: {name}: not a readable matrix ({_opencv_message(exc)})") from None
    if matrix is None:
        raise CalibrationError(f"{path}: {name}: expected a matrix or a list of numbers")
    return np.asarray(matrix, dtype=np.float64)


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
        fields[key] = (
            value.reshape(3, 3).tolist() if key.endswith("matrix") or key == "rotation" else value.ravel().tolist()
        )
    fields["camera_size"] = [int(round(v)) for v in fields["camera_size"]]
    fields["projector_size"] = [int(v) for v in projector_size]
    fields["pixel_centre"] = float(pixel_centre)
    fields["imported_from"] = {"file": Path(path).name, "layout": "OpenCV FileStorage M1/D1/M4/D4/Rlp/Tlp/S"}
    StereoModel.from_fields(fields, where=str(path))
    return fields
