"""Projector-camera (stereo) model: triangulation against a pinhole simulation, the OpenCV YAML
import, and the real SLMaster eye capture."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from realdata import EYE, import_eye, import_eye_calibration, process_eye

from calibration.camera import BoardSpec
from calibration.errors import CalibrationError
from calibration.opencv_yaml import import_opencv_calibration
from calibration.stereo import StereoModel, board_phase_view, calibrate_stereo, fit_plane, triangulate
from mock_devices import synth
from mock_devices.stereo_synth import board_session, calibration_fields, demo_rig, demo_scene, trace
from processing.phase_shift import phase_shift
from processing.temporal import decode_gray, unwrap_gray, unwrap_hierarchical

FREQUENCIES = (1, 8, 64)
STEPS = 6


@pytest.fixture(scope="module")
def simulated():
    rig = demo_rig(160, 128)
    truth, mapping = trace(rig, demo_scene())
    return rig, truth, mapping, StereoModel.from_fields(calibration_fields(rig))


def test_exact_phase_triangulates_to_the_scene(simulated):
    rig, truth, mapping, model = simulated
    phase = 2 * np.pi * FREQUENCIES[-1] * mapping.u / rig.projector.width
    points = triangulate(model, np.where(mapping.lit, phase, np.nan), FREQUENCIES[-1])
    error = np.linalg.norm(points - truth, axis=2)[mapping.lit]
    assert np.isfinite(error).all()
    assert error.max() < 1e-4
    # the projector's distortion matters: ignoring it costs millimetres
    rough = triangulate(model, np.where(mapping.lit, phase, np.nan), FREQUENCIES[-1], iterations=0)
    assert np.nanmax(np.linalg.norm(rough - truth, axis=2)) > 1.0


def test_rendered_fringes_reproduce_the_object_within_0_2_mm_rms(simulated):
    rig, truth, mapping, model = simulated
    geometry = synth.RigGeometry(
        camera_width=rig.camera.width,
        camera_height=rig.camera.height,
        projector_width=rig.projector.width,
        projector_height=rig.projector.height,
    )
    appearance = synth.Appearance(gain=200.0, ambient=0.05, snr_db=30.0, bit_depth=8)
    frames = synth.render_stack(
        synth.sinusoid_patterns(FREQUENCIES, STEPS), mapping, geometry, appearance, np.random.default_rng(0)
    )
    results = [phase_shift(frames[i * STEPS : (i + 1) * STEPS]) for i in range(len(FREQUENCIES))]
    unwrapped = unwrap_hierarchical([r.phase for r in results], list(FREQUENCIES))
    mask = unwrapped.valid & mapping.lit
    points = triangulate(model, np.where(mask, unwrapped.phase, np.nan), FREQUENCIES[-1])
    error = np.linalg.norm(points - truth, axis=2)[mask]
    assert mask.mean() > 0.95
    assert float(np.sqrt(np.mean(error**2))) < 0.2
    # heights above the background plane: the big sphere stands 40 mm out of it
    plane = fit_plane(points, mask & (truth[..., 2] > 599.0))
    assert plane[:3] @ np.array([0, 0, -1.0]) > 0.999 and plane[3] == pytest.approx(600.0, abs=0.2)
    heights = StereoModel.from_fields({**calibration_fields(rig), "plane": plane.tolist()}).heights(points)
    assert float(np.nanmax(heights)) == pytest.approx(40.0, abs=0.5)


def rigid_rms(found: np.ndarray, truth: np.ndarray) -> float:
    """RMS distance after the best rigid alignment (a calibrated camera frame is itself estimated)."""
    a, b = found - found.mean(axis=0), truth - truth.mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(u @ vt))
    rotation = u @ np.diag([1.0, 1.0, d]) @ vt
    return float(np.sqrt(np.mean(np.sum((a @ rotation - b) ** 2, axis=1))))


def test_stereo_calibrated_from_board_views_reproduces_the_object():
    rig = demo_rig(320, 256)
    geometry = synth.RigGeometry(
        camera_width=320, camera_height=256, projector_width=rig.projector.width, projector_height=rig.projector.height
    )
    rng = np.random.default_rng(1)
    views = []
    for image, mapping in board_session(rig, count=8, seed=3):
        appearance = synth.Appearance(reflectivity=image / 220.0, gain=200.0, ambient=0.05, snr_db=30.0, bit_depth=8)
        stacks = [
            synth.render_stack(synth.sinusoid_patterns(FREQUENCIES, 4, axis=axis), mapping, geometry, appearance, rng)
            for axis in ("x", "y")
        ]
        view = board_phase_view(image, BoardSpec("chessboard", (9, 7), 30.0), stacks[0], stacks[1], FREQUENCIES, 4)
        assert view is not None
        views.append(view)
    result = calibrate_stereo(views, (320, 256), (rig.projector.width, rig.projector.height), flags=cv2.CALIB_FIX_K3)
    model = result.model
    assert result.rms_px < 0.2
    assert model.camera_matrix[0, 0] == pytest.approx(rig.camera.matrix[0, 0], rel=0.005)
    assert model.projector_matrix[0, 0] == pytest.approx(rig.projector.matrix[0, 0], rel=0.005)
    assert model.baseline_mm == pytest.approx(float(np.linalg.norm(rig.translation_mm)), rel=0.005)
    truth, mapping = trace(rig, demo_scene())
    phase = np.where(mapping.lit, 2 * np.pi * FREQUENCIES[-1] * mapping.u / rig.projector.width, np.nan)
    points = triangulate(model, phase, FREQUENCIES[-1])
    valid = np.isfinite(points[..., 2])
    assert valid.mean() > 0.95
    heights_true = 600.0 - truth[..., 2]
    on = valid & (heights_true > 0.5)  # the spheres: shape after rigid alignment
    assert rigid_rms(points[on], truth[on]) < 0.2
    assert rigid_rms(points[valid], truth[valid]) < 0.3  # the whole view, corners beyond the boards included
    # heights above the background plane, as measured by the calibrated model, match the sphere
    plane = fit_plane(points, valid & (heights_true < 0.01))
    heights = points @ plane[:3] + plane[3]
    assert float(np.sqrt(np.mean((heights[on] - heights_true[on]) ** 2))) < 0.2


def test_fields_round_trip_and_validation(simulated):
    rig, _, _, model = simulated
    again = StereoModel.from_fields(model.as_fields())
    assert np.array_equal(again.rotation, model.rotation) and again.projector_size == model.projector_size
    fields = calibration_fields(rig)
    with pytest.raises(CalibrationError, match="rotation: not a rotation matrix"):
        StereoModel.from_fields({**fields, "rotation": (2 * np.eye(3)).tolist()})
    with pytest.raises(CalibrationError, match="translation_mm: missing"):
        StereoModel.from_fields({k: v for k, v in fields.items() if k != "translation_mm"})
    with pytest.raises(CalibrationError, match="distortion: expected 0, 4, 5"):
        StereoModel.from_fields({**fields, "distortion": [0.1, 0.2, 0.3]})
    with pytest.raises(CalibrationError, match="does not match the calibrated camera 160x128"):
        triangulate(model, np.zeros((10, 10)), 8)


def test_bad_opencv_files_are_refused(tmp_path):
    with pytest.raises(CalibrationError, match="missing"):
        import_opencv_calibration(tmp_path / "none.yml", (1920, 1080))
    partial = tmp_path / "partial.yml"
    fs = cv2.FileStorage(str(partial), cv2.FILE_STORAGE_WRITE)
    fs.write("M1", np.eye(3))
    fs.release()
    with pytest.raises(CalibrationError, match="partial.yml: D1: missing"):
        import_opencv_calibration(partial, (1920, 1080))


STEREO_CALIBRATE_NAMES = {  # calibration.json key -> node, per layout of cv2.stereoCalibrate's results
    "K": ("K1", "D1", "K2", "D2", "R", "T"),
    "M": ("M1", "D1", "M2", "D2", "R", "T"),
    "arguments": ("cameraMatrix1", "distCoeffs1", "cameraMatrix2", "distCoeffs2", "R", "T"),
}
MODEL_KEYS = ("camera_matrix", "distortion", "projector_matrix", "projector_distortion", "rotation", "translation_mm")


def _write_storage(path, nodes):
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for name, value in nodes.items():
        storage.write(name, np.asarray(value, dtype=np.float64))
    storage.release()
    return path


@pytest.mark.parametrize("layout", sorted(STEREO_CALIBRATE_NAMES))
def test_stereo_calibrate_layouts_import_the_same_model(simulated, tmp_path, layout):
    """Issue 21: the names cv2.stereoCalibrate's results are saved under, camera first, projector second."""
    rig, _, _, model = simulated
    truth = calibration_fields(rig)
    nodes = dict(zip(STEREO_CALIBRATE_NAMES[layout], (truth[k] for k in MODEL_KEYS)))
    width, height = truth["camera_size"]
    projector = tuple(truth["projector_size"])
    with_size = _write_storage(tmp_path / "with-size.yml", {**nodes, "imageSize": [width, height]})
    without = _write_storage(tmp_path / "without-size.yml", nodes)
    for fields in (
        import_opencv_calibration(with_size, projector),
        import_opencv_calibration(without, projector, camera_size=(width, height)),
    ):
        imported = StereoModel.from_fields(fields)
        for key in MODEL_KEYS:
            assert np.allclose(np.asarray(fields[key]).ravel(), np.asarray(truth[key]).ravel(), rtol=0, atol=1e-12)
        assert imported.camera_size == model.camera_size and imported.projector_size == model.projector_size
        assert fields["imported_from"]["layout"] == "OpenCV FileStorage " + "/".join(STEREO_CALIBRATE_NAMES[layout])
    with pytest.raises(CalibrationError, match=r"camera size: expected one of the keys S, imageSize"):
        import_opencv_calibration(without, projector)
    with pytest.raises(CalibrationError, match=r"differs from --camera-size"):
        import_opencv_calibration(with_size, projector, camera_size=(width + 1, height))
    partial = _write_storage(tmp_path / "partial.yml", {k: v for k, v in nodes.items() if k != "T"})
    with pytest.raises(CalibrationError, match=r"partial.yml: T: missing \(expected keys .*; found .*R\)"):
        import_opencv_calibration(partial, projector)


def test_a_file_of_unknown_names_is_refused_naming_its_keys(tmp_path):
    path = _write_storage(tmp_path / "other.yml", {"camera_K": np.eye(3), "proj_K": np.eye(3)})
    with pytest.raises(
        CalibrationError,
        match=r"other.yml: expected the keys of one of the layouts .*K1 D1 K2 D2 R T.*"
        r"; found camera_K, proj_K",
    ):
        import_opencv_calibration(path, (1920, 1080))


@pytest.mark.skipif(not EYE.is_dir(), reason="shared real data not present")
def test_real_eye_capture_becomes_a_point_cloud():
    # SLMaster's phase is 2 pi f k / W at projector column k: OpenCV's pixel centre, so pixel_centre 0
    fields = import_opencv_calibration(EYE / "caliInfo.yml", (1920, 1024), pixel_centre=0.0)
    model = StereoModel.from_fields(fields)
    assert model.camera_size == (1280, 1024) and model.baseline_mm == pytest.approx(109.4, abs=0.1)
    frames = np.stack([cv2.imread(str(EYE / "L" / f"{i}.png"), cv2.IMREAD_GRAYSCALE) for i in range(18)]).astype(
        np.float32
    )
    shifted = phase_shift(frames[:12])
    # the rig's periods start at -pi (phase_rad = pi); 6 complementary Gray planes for 32 periods
    wrapped = np.mod(shifted.phase + np.pi, 2 * np.pi)
    stripes = decode_gray(frames[12:], threshold=shifted.background)
    unwrapped = unwrap_gray(wrapped, stripes, 6, 32, complementary=True)
    mask = unwrapped.valid & (shifted.modulation > 10)
    points = triangulate(model, np.where(mask, unwrapped.phase, np.nan), 32, extent=1920)
    z = points[..., 2]
    valid = np.isfinite(z)
    assert valid.sum() > 150_000
    low, high = np.percentile(z[valid], [5, 95])
    assert 650 < low < high < 800 and high - low < 100  # a ~10 cm plaque about 0.7 m away
    # the points are consistent with the projector: reprojected, they land on the measured column
    rvec, _ = cv2.Rodrigues(model.rotation)
    sample = np.argwhere(valid)[::97]
    projected, _ = cv2.projectPoints(
        points[sample[:, 0], sample[:, 1]].reshape(-1, 1, 3),
        rvec,
        model.translation_mm,
        model.projector_matrix,
        model.projector_distortion,
    )
    column = unwrapped.phase[sample[:, 0], sample[:, 1]] * 1920 / (2 * np.pi * 32)
    assert np.max(np.abs(projected.reshape(-1, 2)[:, 0] - column)) < 0.01
    # a surface, not scatter: depth differs from its 5x5 median by little on most pixels
    filled = np.where(valid, z, np.nanmedian(z)).astype(np.float32)
    local = np.abs(filled - cv2.medianBlur(filled, 5))[valid]
    assert np.median(local) < 0.5  # 0.22 mm here


@pytest.mark.skipif(not EYE.is_dir(), reason="shared real data not present")
def test_eye_capture_through_the_command_line(tmp_path, capsys):
    """rig import + rig calibrate --import-opencv + rig process: the real capture becomes points.ply."""
    import json

    import_eye(tmp_path / "eye", "--projector-width", "1920", "--projector-height", "1024")
    import_eye_calibration(tmp_path / "cal")
    process_eye(tmp_path, "-q")
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["calibration_model"] == "stereo" and report["points"] > 150_000
    assert 690 < report["height_mm"]["median"] < 760  # depth of the plaque, mm from the camera
    header = (tmp_path / "out" / "points.ply").read_bytes()[:300].decode("ascii", "replace")
    assert header.startswith("ply") and f"element vertex {report['points']}" in header
