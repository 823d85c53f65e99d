"""Import a projector-camera calibration from an OpenCV FileStorage file (YAML, XML or JSON).

Four layouts of node names are read (:data:`LAYOUTS`); the file's keys choose one:

- SLMaster's ``caliInfo.yml``: ``M1``/``D1`` camera matrix and distortion, ``M4``/``D4`` projector
  matrix and distortion, ``Rlp``/``Tlp`` rotation and translation (mm) from the camera to the
  projector, ``S`` the camera size (width, height);
- the names ``cv2.stereoCalibrate``'s results are usually saved under, camera first and projector
  second: ``K1 D1 K2 D2 R T``, ``M1 D1 M2 D2 R T`` (OpenCV's stereo_calib sample) or its argument
  names ``cameraMatrix1 distCoeffs1 cameraMatrix2 distCoeffs2 R T``. ``R``/``T`` take points from
  the camera's frame to the projector's (``T`` in the units of the board given to the
  calibration: millimetres). The camera size is read from ``S``, ``imageSize`` or ``image_size``
  when the file has one, else it comes from the caller.

The file does not say the projector's resolution; it comes from the caller (the capture's
``projector`` entry, or the command line). A file matching no layout is refused with one line
naming the keys it holds.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from calibration.errors import CalibrationError
from calibration.stereo import STEREO, StereoModel

# layout name -> {calibration.json key: FileStorage node}
LAYOUTS: dict[str, dict[str, str]] = {
    "SLMaster": {
        "camera_matrix": "M1",
        "distortion": "D1",
        "projector_matrix": "M4",
        "projector_distortion": "D4",
        "rotation": "Rlp",
        "translation_mm": "Tlp",
        "camera_size": "S",
    },
    "stereoCalibrate K1 D1 K2 D2 R T": {
        "camera_matrix": "K1",
        "distortion": "D1",
        "projector_matrix": "K2",
        "projector_distortion": "D2",
        "rotation": "R",
        "translation_mm": "T",
    },
    "stereoCalibrate M1 D1 M2 D2 R T": {
        "camera_matrix": "M1",
        "distortion": "D1",
        "projector_matrix": "M2",
        "projector_distortion": "D2",
        "rotation": "R",
        "translation_mm": "T",
    },
    "stereoCalibrate cameraMatrix1 distCoeffs1 cameraMatrix2 distCoeffs2 R T": {
        "camera_matrix": "cameraMatrix1",
        "distortion": "distCoeffs1",
        "projector_matrix": "cameraMatrix2",
        "projector_distortion": "distCoeffs2",
        "rotation": "R",
        "translation_mm": "T",
    },
}
SIZE_NODES = ("S", "imageSize", "image_size")  # where a layout without "camera_size" finds it, if anywhere


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


def read_filestorage(path: str | os.PathLike[str]) -> tuple[str, dict[str, np.ndarray]]:
    """The layout of an OpenCV FileStorage file and its matrices by calibration.json key (the
    camera size too when the file holds one); CalibrationError naming a missing node."""
    path = Path(path)
    storage = _open_storage(path)
    try:
        keys = tuple(storage.root().keys())
        layout = _layout_of(keys, path)
        names = LAYOUTS[layout]
        expected = tuple(names.values())
        found = {key: _read_node(storage, name, path, expected, keys) for key, name in names.items()}
        size_node = next((name for name in SIZE_NODES if name in keys), None)
        if "camera_size" not in found and size_node is not None:
            found["camera_size"] = _read_node(storage, size_node, path, expected, keys)
        return layout, found
    finally:
        storage.release()


def _open_storage(path: Path) -> Any:
    """An open ``cv2.FileStorage`` of a file that starts as one; one-line errors for everything else."""
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
    return storage


def _layout_of(keys: tuple[str, ...], path: Path) -> str:
    """The layout sharing the most node names with ``keys`` (the first of equals); none shared: refused."""
    shared = {name: len(set(nodes.values()) & set(keys)) for name, nodes in LAYOUTS.items()}
    best = max(shared, key=lambda name: shared[name])  # max keeps the first of equals
    if shared[best] == 0:
        layouts = "; ".join(" ".join(nodes.values()) for nodes in LAYOUTS.values())
        raise CalibrationError(f"{path}: expected the keys of one of the layouts {layouts}; found {_listed(keys)}")
    return best


def _listed(keys: tuple[str, ...]) -> str:
    return ", ".join(keys[:20]) + (" ..." if len(keys) > 20 else "") if keys else "no keys"


def _read_node(storage: Any, name: str, path: Path, names: tuple[str, ...], keys: tuple[str, ...]) -> np.ndarray:
    """One matrix (an ``opencv-matrix`` map or a sequence of numbers) of an open FileStorage."""
    try:
        node = storage.getNode(name)
        if node.empty():
            raise CalibrationError(f"{path}: {name}: missing (expected keys {', '.join(names)}; found {_listed(keys)})")
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
    path: str | os.PathLike[str],
    projector_size: tuple[int, int],
    pixel_centre: float = 0.5,
    camera_size: tuple[int, int] | None = None,
) -> dict[str, Any]:
    """calibration.json fields (model ``stereo``) from an OpenCV FileStorage file in one of :data:`LAYOUTS`.

    Parameters
    ----------
    path : path
        The FileStorage file (e.g. SLMaster's ``caliInfo.yml``, or ``cv2.stereoCalibrate``'s results).
    projector_size : (width, height)
        Projector resolution in pixels (the pattern extent the phase refers to).
    pixel_centre : float
        Where OpenCV's pixel k sits in the product's projector coordinate (0.5: centres at k + 0.5).
    camera_size : (width, height), optional
        The camera's resolution, for a file that does not hold it (``S``, ``imageSize``); a
        size in the file must agree.
    """
    layout, nodes = read_filestorage(path)
    fields: dict[str, Any] = {"model": STEREO}
    for key, value in nodes.items():
        fields[key] = (
            value.reshape(3, 3).tolist() if key.endswith("matrix") or key == "rotation" else value.ravel().tolist()
        )
    fields["camera_size"] = _camera_size(fields.get("camera_size"), camera_size, path)
    fields["projector_size"] = [int(v) for v in projector_size]
    fields["pixel_centre"] = float(pixel_centre)
    names = " ".join(LAYOUTS[layout].values())
    fields["imported_from"] = {"file": Path(path).name, "layout": f"OpenCV FileStorage {names.replace(' ', '/')}"}
    StereoModel.from_fields(fields, where=str(path))
    return fields


def _camera_size(stored: list[float] | None, given: tuple[int, int] | None, path: str | os.PathLike[str]) -> list[int]:
    """The camera size the file holds, or the one given; refused when neither, or when they differ."""
    if stored is None:
        if given is None:
            raise CalibrationError(
                f"{path}: the camera size: expected one of the keys {', '.join(SIZE_NODES)} or --camera-size WxH, found neither"
            )
        return [int(v) for v in given]
    size = [int(round(v)) for v in stored]
    if given is not None and size != [int(v) for v in given]:
        raise CalibrationError(
            f"{path}: camera size {size[0]}x{size[1]} differs from --camera-size {given[0]}x{given[1]}"
        )
    return size
