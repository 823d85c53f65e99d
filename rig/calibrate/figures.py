"""What a calibration session found, to be looked at: the board detections of each board view with
their reprojection errors, the plane residuals and flatness per height, and the projector gamma
curve, read from the calibration directory (calibration.json, session.json and the session's
captures; nothing is written).

The reprojection error of a view is measured here: the board's pose in that view is solved with the
calibration's own intrinsics (``cv2.solvePnP``), the corners are projected back, and the residual
of each corner is the detected minus the projected position (pixels).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from calibration.camera import BoardSpec, detect_board, lit_corners
from calibration.errors import CalibrationError
from rig.calibrate.session import BOARD_DIR, SESSION_FILE, CalibrationPlan
from rig.store.capture import read_capture

ARROW_GAIN = 20.0  # residual arrows are drawn this many times their length


def summary(directory: Path) -> dict[str, Any]:
    """The figures calibration.json holds (plane residuals and flatness, gamma, camera fit) and the board views kept."""
    cal = json.loads((directory / "calibration.json").read_text())
    heights = cal.get("heights_mm") or []
    board = directory / BOARD_DIR
    views = sorted(p.name for p in board.iterdir() if (p / "capture.json").is_file()) if board.is_dir() else []
    return {
        "model": cal.get("model"),
        "planes": {
            "heights_mm": heights,
            "residuals_mm": cal.get("residuals_mm"),
            "flatness_rms_mm": cal.get("plane_flatness_rms_mm"),
        }
        if heights
        else None,
        "gamma": cal.get("gamma"),
        "camera": {"reprojection_rms_px": cal.get("reprojection_rms_px"), "image_size": cal.get("camera_image_size")}
        if "camera_matrix" in cal
        else None,
        "board_views": views,
    }


def _board(directory: Path) -> BoardSpec:
    plan = CalibrationPlan.load(directory / SESSION_FILE)
    if plan.board is None:
        raise CalibrationError(f"{directory / SESSION_FILE}: this session used no board")
    return plan.board


def board_view(directory: Path, view: str) -> tuple[np.ndarray, dict[str, Any]]:
    """A board view (8-bit BGR) with its detected corners drawn (green lit, grey unlit) and, with
    the calibration's intrinsics, each lit corner's reprojection residual as a red arrow
    (:data:`ARROW_GAIN` times its length); and the figures of the view."""
    if view not in summary(directory)["board_views"]:
        raise FileNotFoundError(f"{BOARD_DIR}/{view}: not a board view of this calibration")
    capture = read_capture(directory / BOARD_DIR / view)
    white, dark = capture.load_frame(0), capture.load_frame(1)
    shift = max(capture.bit_depth - 8, 0)
    picture = cv2.cvtColor(np.asarray(white >> shift, dtype=np.uint8), cv2.COLOR_GRAY2BGR)
    found = detect_board(white, _board(directory), name=f"{BOARD_DIR}/{view}")
    figures: dict[str, Any] = {"view": view, "found": found is not None}
    if found is None:
        return picture, figures
    lit = lit_corners(found, white, dark)
    points = found.image_points
    figures.update(corners=int(len(points)), lit=int(lit.sum()))
    cal = json.loads((directory / "calibration.json").read_text())
    if "camera_matrix" in cal and int(lit.sum()) >= 4:
        matrix = np.asarray(cal["camera_matrix"], dtype=np.float64)
        distortion = np.asarray(cal.get("distortion", [0, 0, 0, 0, 0]), dtype=np.float64)
        objects = found.object_points[lit].astype(np.float64)
        ok, rvec, tvec = cv2.solvePnP(objects, points[lit], matrix, distortion)
        if ok:
            projected = cv2.projectPoints(objects, rvec, tvec, matrix, distortion)[0].reshape(-1, 2)
            residuals = points[lit] - projected
            lengths = np.linalg.norm(residuals, axis=1)
            figures.update(rms_px=float(np.sqrt(np.mean(lengths**2))), max_px=float(lengths.max()))
            for start, r in zip(points[lit], residuals):
                end = start + ARROW_GAIN * r
                cv2.arrowedLine(picture, _pt(start), _pt(end), (40, 40, 230), 1, tipLength=0.3)
    for point, is_lit in zip(points, lit):
        cv2.circle(picture, _pt(point), 3, (60, 200, 60) if is_lit else (150, 150, 150), 1)
    return picture, figures


def _pt(xy: np.ndarray) -> tuple[int, int]:
    return int(round(float(xy[0]))), int(round(float(xy[1])))
