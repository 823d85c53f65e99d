"""Camera intrinsics and distortion from synthetic chessboard and ChArUco views of a known camera."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.camera import (
    BoardSpec,
    calibrate_camera,
    detect_board,
    undistort_map,
    undistort_pixels,
    undistort_points,
    undistort_stack,
)
from calibration.errors import CalibrationError
from mock_devices.board_synth import PinholeCamera, calibration_views

CAMERA = PinholeCamera.simple(320, 240, 300.0, (-0.2, 0.05, 0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def chessboard_views():
    return calibration_views(CAMERA, "chessboard", (9, 7), 30.0, count=10, distance_mm=450.0, seed=1)


def test_chessboard_recovers_intrinsics_and_distortion(chessboard_views):
    images, _ = chessboard_views
    result = calibrate_camera(images, BoardSpec("chessboard", (9, 7), 30.0))
    assert result.rms_px < 0.15
    assert len(result.views_used) == 10 and result.distortion_significant
    matrix = result.camera_matrix
    assert matrix[0, 0] == pytest.approx(300.0, rel=0.01)
    assert matrix[1, 1] == pytest.approx(300.0, rel=0.01)
    assert abs(matrix[0, 2] - 159.5) < 2.0 and abs(matrix[1, 2] - 119.5) < 2.0
    # distortion: compare what it does (pixel displacement at the corners), not the coefficients
    corners = np.array([[0.0, 0.0], [319.0, 0.0], [0.0, 239.0], [319.0, 239.0], [60.0, 200.0]])
    truth = undistort_points(corners, CAMERA.camera_matrix, CAMERA.distortion)
    found = undistort_points(corners, matrix, result.distortion)
    assert np.max(np.abs(found - truth)) * 300.0 < 1.5  # in pixels
    fields = result.as_fields()
    assert len(fields["camera_matrix"]) == 3 and len(fields["distortion"]) == 5


def test_a_lens_without_distortion_gets_none():
    straight = PinholeCamera.simple(320, 240, 300.0)
    images, _ = calibration_views(straight, "chessboard", (9, 7), 30.0, count=8, distance_mm=450.0, seed=4)
    result = calibrate_camera(images, BoardSpec("chessboard", (9, 7), 30.0))
    assert not result.distortion_significant and not np.any(result.distortion)
    assert result.camera_matrix[0, 0] == pytest.approx(300.0, rel=0.01)
    kept = calibrate_camera(images, BoardSpec("chessboard", (9, 7), 30.0), significance=None)
    assert np.any(kept.distortion)  # the unconstrained fit has noise in its coefficients


def test_charuco_views_calibrate_too():
    images, _ = calibration_views(CAMERA, "charuco", (9, 7), 30.0, marker_mm=21.0, count=8, distance_mm=420.0, seed=2)
    result = calibrate_camera(images, BoardSpec("charuco", (9, 7), 30.0, marker_mm=21.0))
    assert result.rms_px < 0.5
    assert result.camera_matrix[0, 0] == pytest.approx(300.0, rel=0.03)


def test_undistortion_straightens_the_board(chessboard_views):
    images, _ = chessboard_views
    board = BoardSpec("chessboard", (9, 7), 30.0)

    def homography_misfit(image: np.ndarray) -> float:
        found = detect_board(image, board)
        assert found is not None
        plane = found.object_points[:, :2].astype(np.float64)
        h, _ = cv2.findHomography(plane, found.image_points)
        mapped = cv2.perspectiveTransform(plane.reshape(-1, 1, 2), h).reshape(-1, 2)
        return float(np.sqrt(np.mean(np.sum((mapped - found.image_points) ** 2, axis=1))))

    view = images[3]
    corrected = undistort_stack(view, CAMERA.camera_matrix, CAMERA.distortion)
    assert corrected.shape == view.shape and corrected.dtype == view.dtype
    before, after = homography_misfit(view), homography_misfit(corrected)
    assert before > 0.15  # a distorted board is not a homography (0.22 px here) ...
    assert after < 0.06 and after < before / 4  # ... a straightened one is, to the corner noise
    stack = undistort_stack(np.stack(images[:2]), CAMERA.camera_matrix, CAMERA.distortion)
    assert np.array_equal(stack[1], undistort_stack(images[1], CAMERA.camera_matrix, CAMERA.distortion))


def test_too_few_views_are_refused(chessboard_views):
    images, _ = chessboard_views
    blank = np.full_like(images[0], 90)
    with pytest.raises(CalibrationError, match="found in 2 of 4 views, need at least 3"):
        calibrate_camera([images[0], blank, images[1], blank], BoardSpec("chessboard", (9, 7), 30.0))


def test_views_of_different_sizes_are_refused(chessboard_views):
    images, _ = chessboard_views
    with pytest.raises(CalibrationError, match="camera view 1: size"):
        calibrate_camera([images[0], images[1][:200]], BoardSpec("chessboard", (9, 7), 30.0))


def test_bad_board_specs_are_refused():
    with pytest.raises(CalibrationError, match="board kind"):
        BoardSpec("circles")
    with pytest.raises(CalibrationError, match="marker must be smaller"):
        BoardSpec("charuco", (5, 5), 20.0, marker_mm=25.0)


def test_points_and_maps_undistort_like_the_frames(chessboard_views):
    images, _ = chessboard_views
    board = BoardSpec("chessboard", (9, 7), 30.0)
    found = detect_board(images[1], board)
    in_corrected = detect_board(undistort_stack(images[1], CAMERA.camera_matrix, CAMERA.distortion), board)
    moved = undistort_pixels(found.image_points, CAMERA.camera_matrix, CAMERA.distortion)
    assert np.max(np.linalg.norm(moved - in_corrected.image_points, axis=1)) < 0.1
    # maps of the column and row index, undistorted, hold at each pixel where it came from
    rows, columns = np.indices((240, 320), dtype=np.float64)
    from_x = undistort_map(columns, CAMERA.camera_matrix, CAMERA.distortion)
    from_y = undistort_map(rows, CAMERA.camera_matrix, CAMERA.distortion)
    source = np.array([[from_x[100, 250], from_y[100, 250]], [from_x[30, 40], from_y[30, 40]]])
    assert np.allclose(
        undistort_pixels(source, CAMERA.camera_matrix, CAMERA.distortion), [[250, 100], [40, 30]], atol=0.01
    )
