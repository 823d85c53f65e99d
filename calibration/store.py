"""calibration.json: read, validate and write rig calibrations (capture-format.md v1).

A calibration lives in a directory holding ``calibration.json``. The ``model`` names how heights
are computed: ``"reference-plane"`` (thesis eq. 1.15 with l0, d0, f0 and a reference-plane
capture) is checked here; other models (``"polynomial"``, ``"stereo"``, ...) are carried as they
are, their own keys validated by the code that implements them. Unknown keys are always kept,
so rewriting a file never loses what another tool recorded.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from calibration.errors import CalibrationError
from calibration.jsonfile import check_committed_input, read_json, write_json_atomic

FORMAT = "fpp-calibration"
VERSION = 1
FILENAME = "calibration.json"
REFERENCE_PLANE = "reference-plane"

# Keys the reference-plane model needs, with the check each must pass.
_REFERENCE_PLANE_NUMBERS = {
    "l0_mm": "positive",
    "d0_mm": "non-zero",
    "f0_per_mm": "positive",
    "f0_frequency": "positive",
    "pixel_mm": "positive",
}
_KNOWN = ("format", "version", "model", *_REFERENCE_PLANE_NUMBERS, "reference", "created_utc")


@dataclass
class Calibration:
    """A rig calibration. ``extra`` holds every key of calibration.json not named by a field.

    ``path`` is the calibration directory once read or written (relative ``reference`` paths
    are resolved against it).
    """

    model: str = REFERENCE_PLANE
    l0_mm: float | None = None
    d0_mm: float | None = None
    f0_per_mm: float | None = None
    f0_frequency: float | None = None
    pixel_mm: float | None = None
    reference: str | None = None
    created_utc: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    def per_mm(self, frequency: float) -> float:
        """Fringe frequency on the reference plane (cycles/mm) of a sinusoid with ``frequency`` fringes."""
        if self.f0_per_mm is None or self.f0_frequency is None:
            raise CalibrationError(f"{self.where}: f0_per_mm / f0_frequency: missing for model {self.model!r}")
        return self.f0_per_mm * float(frequency) / self.f0_frequency

    @property
    def where(self) -> str:
        return str(self.path / FILENAME) if self.path is not None else FILENAME

    @property
    def reference_path(self) -> Path | None:
        """The reference-plane capture, resolved against the calibration directory."""
        if self.reference is None:
            return None
        ref = Path(self.reference)
        return ref if self.path is None else self.path / ref

    def to_dict(self) -> dict[str, Any]:
        """calibration.json content: the known fields (those set) followed by the extra keys."""
        out: dict[str, Any] = {"format": FORMAT, "version": VERSION, "model": self.model}
        for key in ("l0_mm", "d0_mm", "f0_per_mm", "f0_frequency", "pixel_mm", "reference", "created_utc"):
            value = getattr(self, key)
            if value is not None:
                out[key] = value
        for key, value in self.extra.items():
            out.setdefault(key, value)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], path: Path | None = None) -> Calibration:
        """Validate a parsed calibration.json (see :func:`validate`) and build the dataclass."""
        where = str(path / FILENAME) if path is not None else FILENAME
        validate(data, where)
        known = {key: data.get(key) for key in ("l0_mm", "d0_mm", "f0_per_mm", "f0_frequency", "pixel_mm")}
        return cls(
            model=data["model"],
            **{key: (float(value) if value is not None else None) for key, value in known.items()},
            reference=data.get("reference"),
            created_utc=data.get("created_utc"),
            extra={key: value for key, value in data.items() if key not in _KNOWN},
            path=path,
        )


def _number(where: str, data: Mapping[str, Any], key: str, rule: str) -> None:
    value = data.get(key)
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if ok and rule == "positive":
        ok = float(value) > 0  # type: ignore[arg-type]  # a finite int or float here
    elif ok and rule == "non-zero":
        ok = value != 0
    if not ok:
        raise CalibrationError(f"{where}: {key}: expected a {rule} finite number, found {value!r}")


def _check_reference(where: str, reference: Any) -> None:
    """``reference`` is relative to the calibration directory and stays inside it (capture-format.md)."""
    if reference is None:
        return
    if not isinstance(reference, str) or not reference:
        raise CalibrationError(f"{where}: reference: expected a relative path, found {reference!r}")
    posix = PurePosixPath(reference.replace("\\", "/"))
    if posix.is_absolute() or (len(reference) > 1 and reference[1] == ":") or ".." in posix.parts or "\0" in reference:
        raise CalibrationError(
            f"{where}: reference: expected a path relative to the calibration directory, inside it, found {reference!r}"
        )


# (matrix, distortion) keys of the pinhole cameras a calibration may hold (the projector is an inverse camera)
_CAMERA_KEYS = (("camera_matrix", "distortion"), ("projector_matrix", "projector_distortion"))
DISTORTION_SIZES = (0, 4, 5, 8, 12, 14)  # OpenCV's lens models
_MAX_CONDITION = 1e12  # beyond this a camera matrix cannot be inverted to any useful precision


def _check_camera_matrix(where: str, key: str, value: Any) -> None:
    """A pinhole matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]]: finite, fx, fy > 0, invertible."""
    try:
        matrix = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        matrix = np.zeros(0)
    if matrix.shape != (3, 3):
        found = f"shape {matrix.shape}" if matrix.size else repr(value)[:60]
        raise CalibrationError(
            f"{where}: {key}: expected a 3x3 matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]], found {found}"
        )
    if not np.isfinite(matrix).all():
        raise CalibrationError(f"{where}: {key}: expected finite numbers, found NaN or infinity")
    if not (matrix[0, 0] > 0 and matrix[1, 1] > 0):
        raise CalibrationError(
            f"{where}: {key}: expected focal lengths fx, fy > 0, found {matrix[0, 0]:g}, {matrix[1, 1]:g}"
        )
    if matrix[1, 0] != 0 or not np.array_equal(matrix[2], [0.0, 0.0, 1.0]):
        raise CalibrationError(
            f"{where}: {key}: expected the form [[fx, s, cx], [0, fy, cy], [0, 0, 1]], found rows 2 and 3 "
            f"{matrix[1].tolist()}, {matrix[2].tolist()}"
        )
    condition = float(np.linalg.cond(matrix))
    if not condition < _MAX_CONDITION:
        raise CalibrationError(f"{where}: {key}: expected an invertible matrix, found condition number {condition:.3g}")


def _check_distortion(where: str, key: str, value: Any) -> None:
    """OpenCV distortion coefficients: 0, 4, 5, 8, 12 or 14 finite numbers."""
    try:
        coefficients = np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise CalibrationError(f"{where}: {key}: expected a list of numbers, found {repr(value)[:60]}") from None
    if coefficients.size not in DISTORTION_SIZES:
        raise CalibrationError(
            f"{where}: {key}: expected 0, 4, 5, 8, 12 or 14 OpenCV coefficients, found {coefficients.size}"
        )
    if not np.isfinite(coefficients).all():
        raise CalibrationError(f"{where}: {key}: expected finite coefficients, found NaN or infinity")


def _check_cameras(where: str, data: Mapping[str, Any]) -> None:
    """Camera and projector intrinsics, where present: checked when read, not found as an empty map later."""
    for matrix_key, distortion_key in _CAMERA_KEYS:
        if matrix_key in data:
            _check_camera_matrix(where, matrix_key, data[matrix_key])
        if distortion_key in data:
            _check_distortion(where, distortion_key, data[distortion_key])


def validate(data: Any, where: str = FILENAME) -> None:
    """Check a parsed calibration.json; raise CalibrationError naming the field on the first problem."""
    if not isinstance(data, Mapping):
        raise CalibrationError(f"{where}: top level: expected a JSON object, found {type(data).__name__}")
    if data.get("format") != FORMAT:
        raise CalibrationError(f"{where}: format: expected {FORMAT!r}, found {data.get('format')!r}")
    if data.get("version") != VERSION:
        raise CalibrationError(
            f"{where}: version: expected {VERSION} (the version this program reads), found {data.get('version')!r}"
        )
    model = data.get("model")
    if not isinstance(model, str) or not model:
        raise CalibrationError(f"{where}: model: expected a model name such as {REFERENCE_PLANE!r}, found {model!r}")
    if model == REFERENCE_PLANE:
        for key, rule in _REFERENCE_PLANE_NUMBERS.items():
            _number(where, data, key, rule)
        reference = data.get("reference")
        if not isinstance(reference, str) or not reference:
            raise CalibrationError(
                f"{where}: reference: expected the path of the reference-plane capture, found {reference!r}"
            )
    else:  # other models validate their own keys; the shared numbers must still be sane if present
        for key, rule in _REFERENCE_PLANE_NUMBERS.items():
            if key in data:
                _number(where, data, key, rule)
    _check_reference(where, data.get("reference"))
    _check_cameras(where, data)


def read_calibration(path: str | os.PathLike[str]) -> Calibration:
    """Read a calibration directory (or its calibration.json) and validate it."""
    path = Path(path)
    if path.is_file() or path.suffix == ".json":
        directory, file = path.parent, path
    else:
        directory, file = path, path / FILENAME
    check_committed_input(directory, "calibration", CalibrationError)
    data = read_json(file, CalibrationError, "missing (not a calibration directory?)")
    return Calibration.from_dict(data, path=directory)


def write_calibration(path: str | os.PathLike[str], calibration: Calibration) -> Path:
    """Write ``calibration`` as ``path/calibration.json`` (directory created), atomically.

    ``created_utc`` is filled in when unset. Returns the file written.
    """
    directory = Path(path)
    if directory.name == FILENAME:
        directory = directory.parent
    if calibration.created_utc is None:
        calibration.created_utc = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    data = calibration.to_dict()
    validate(data, str(directory / FILENAME))
    directory.mkdir(parents=True, exist_ok=True)
    target = directory / FILENAME
    write_json_atomic(target, data)
    calibration.path = directory
    return target
