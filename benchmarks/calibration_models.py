"""Figures for docs/calibration.md: how well each calibration model measures simulated objects.

Two simulated rigs, each calibrated from its own captures of a plane at known heights:

1. the ideal reference-plane rig of the thesis (mock_devices.synth: eq. 1.15 holds exactly),
   512 x 384 camera, 4-step sinusoids at 1 / 8 / 64 fringes; object: a 25.000 mm gauge block and
   the thesis' sphere cap (R 300 mm, 100 mm high);
2. a pinhole projector-camera rig (mock_devices.stereo_synth: camera and projector with
   intrinsics, lens distortion and a 14 degree toe-in, where eq. 1.15 does not hold), 320 x 256
   camera, 6-step at 1 / 8 / 64; object: a sphere standing 40 mm out of the plane at 600 mm.

Models: reference-plane (l0, d0, f0 fitted: 1/dPhi linear in 1/h), per-pixel polynomial
(degree 3), stereo (triangulation with the rig's true parameters, and with parameters calibrated
from 8 simulated board views with fringes in both axes). Phases come from rendered 8-bit
fringes at the given SNR; fringe orders from temporal unwrapping. Prints parameter errors and the
height error on the object (RMS and 99th percentile of |error| over pixels > 0.5 mm high).

    python benchmarks/calibration_models.py [--snr-db 30] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calibration.errors import CalibrationError  # noqa: E402
from calibration.geometry import fit_f0, fit_l0_d0  # noqa: E402
from calibration.polynomial import fit_polynomial  # noqa: E402
from calibration.stereo import StereoModel, board_phase_view, calibrate_stereo, fit_plane, triangulate  # noqa: E402
from mock_devices import scenes, stereo_synth, synth  # noqa: E402
from processing.geometry.height import phase_to_height  # noqa: E402
from processing.phase.shifting import phase_shift  # noqa: E402
from processing.unwrap.temporal import unwrap_hierarchical  # noqa: E402

FREQUENCIES = (1, 8, 64)
HEIGHTS = (25.0, 50.0, 100.0, 150.0)


def unwrap(frames: np.ndarray, steps: int) -> np.ndarray:
    phases = [phase_shift(frames[i * steps : (i + 1) * steps]).phase for i in range(len(FREQUENCIES))]
    result = unwrap_hierarchical(phases, list(FREQUENCIES))
    return np.where(result.valid, result.phase, np.nan)


def error_stats(height: np.ndarray, truth: np.ndarray) -> str:
    on = (truth > 0.5) & np.isfinite(height)
    e = np.abs(height[on] - truth[on])
    return f"RMS {np.sqrt(np.mean(e**2)):.3f} mm, p99 {np.percentile(e, 99):.3f} mm, mean {np.mean(height[on] - truth[on]):+.3f} mm"


def ideal_rig(snr_db: float, seed: int) -> None:
    g = synth.RigGeometry(
        l0_mm=1000.0,
        d0_mm=250.0,
        f0_per_mm=0.015625,
        f0_frequency=8.0,
        pixel_mm=0.8,
        camera_width=512,
        camera_height=384,
    )
    app = synth.Appearance(gain=200.0, ambient=0.1, snr_db=snr_db, bit_depth=8)
    rng = np.random.default_rng(seed)
    patterns = synth.sinusoid_patterns(FREQUENCIES, 4)

    def phase(height: np.ndarray) -> np.ndarray:
        mapping = synth.projector_coordinates(height, g)
        return np.where(mapping.lit, unwrap(synth.render_stack(patterns, mapping, g, app, rng), 4), np.nan)

    ref = phase(np.zeros(g.camera_shape))
    deltas = [phase(np.full(g.camera_shape, h)) - ref for h in HEIGHTS]
    f0 = fit_f0(ref, g.pixel_mm)
    fit = fit_l0_d0(HEIGHTS, deltas, f0.f0_per_mm, f0_std_per_mm=f0.f0_std_per_mm)
    f0_true = g.per_mm(64)
    print(
        f"ideal rig, {snr_db:g} dB: f0 {100 * (f0.f0_per_mm / f0_true - 1):+.3f} %, "
        f"l0 {100 * (fit.l0_mm / g.l0_mm - 1):+.3f} % (+-{100 * fit.l0_std_mm / g.l0_mm:.3f}), "
        f"d0 {100 * (fit.d0_mm / g.d0_mm - 1):+.3f} % (+-{100 * fit.d0_std_mm / g.d0_mm:.3f}), "
        f"residual RMS {fit.residual_rms_mm:.4f} mm"
    )
    poly = fit_polynomial(HEIGHTS, deltas, 64, degree=3)
    block = np.zeros(g.camera_shape)
    block[120:264, 160:352] = 25.0
    cap = scenes.sphere_cap(g.camera_height, g.camera_width, g.pixel_mm, 300.0, 100.0)
    for name, truth in (("gauge block 25 mm", block), ("sphere cap 100 mm", cap)):
        obj = phase(truth)
        h_ref = phase_to_height(obj - ref, fit.l0_mm, fit.d0_mm, f0.f0_per_mm)
        h_poly = poly.height(obj - ref)
        line = f"  {name}: reference-plane {error_stats(h_ref, truth)}; polynomial {error_stats(h_poly, truth)}"
        if truth is block:
            top = h_ref[130:254, 170:342]
            line += f"; block top mean {np.nanmean(top):.4f} mm"
        print(line)


def pinhole_rig(snr_db: float, seed: int) -> None:
    rig = stereo_synth.demo_rig(320, 256)
    g = synth.RigGeometry(
        camera_width=320, camera_height=256, projector_width=rig.projector.width, projector_height=rig.projector.height
    )
    app = synth.Appearance(gain=200.0, ambient=0.05, snr_db=snr_db, bit_depth=8)
    rng = np.random.default_rng(seed)
    patterns = synth.sinusoid_patterns(FREQUENCIES, 6)
    plane_mm = 600.0

    def phase(scene: stereo_synth.Scene) -> tuple[np.ndarray, np.ndarray]:
        points, mapping = stereo_synth.trace(rig, scene)
        frames = synth.render_stack(patterns, mapping, g, app, rng)
        return np.where(mapping.lit, unwrap(frames, 6), np.nan), points

    ref, _ = phase(stereo_synth.Scene(plane_distance=plane_mm))
    deltas = [phase(stereo_synth.Scene(plane_distance=plane_mm - h))[0] - ref for h in HEIGHTS]
    obj, points = phase(stereo_synth.demo_scene())
    truth = plane_mm - points[..., 2]
    pixel_mm = plane_mm / rig.camera.matrix[0, 0]
    f0 = fit_f0(ref, pixel_mm)
    try:
        fit_l0_d0(HEIGHTS, deltas, f0.f0_per_mm)
        flag = "accepted"
    except CalibrationError as exc:
        flag = f"refused: {exc}"
    fit = fit_l0_d0(HEIGHTS, deltas, f0.f0_per_mm, flatness_tolerance_mm=None)
    print(f"pinhole rig, {snr_db:g} dB: reference-plane fit {flag}")
    print(f"  plane flatness with eq. 1.15 (RMS mm per height): {', '.join(f'{s:.2f}' for s in fit.flatness_rms_mm)}")
    h_ref = phase_to_height(obj - ref, fit.l0_mm, fit.d0_mm, f0.f0_per_mm)
    poly = fit_polynomial(HEIGHTS, deltas, 64, degree=3)
    h_poly = poly.height(obj - ref)
    model = StereoModel.from_fields({**stereo_synth.calibration_fields(rig), "plane": [0.0, 0.0, -1.0, plane_mm]})
    recovered = triangulate(model, obj, 64)
    h_stereo = model.heights(recovered)
    lit = np.isfinite(recovered[..., 2])
    rms_3d = np.sqrt(np.nanmean(np.sum((recovered - points) ** 2, axis=2)[lit]))
    print(f"  sphere 40 mm: reference-plane {error_stats(h_ref, truth)}")
    print(f"  sphere 40 mm: polynomial (fit residual {poly.residual_rms_mm:.3f} mm) {error_stats(h_poly, truth)}")
    print(
        f"  sphere 40 mm: stereo (true parameters) {error_stats(h_stereo, truth)}; 3-D point RMS {rms_3d:.3f} mm over the view"
    )
    calibrated = calibrated_stereo(rig, g, snr_db, seed)
    recovered = triangulate(calibrated.model, obj, 64)
    background = (truth < 0.01) & np.isfinite(recovered[..., 2])
    plane = fit_plane(recovered, background)
    h_cal = recovered @ plane[:3] + plane[3]
    print(
        f"  stereo calibrated from 8 board views (stereoCalibrate RMS {calibrated.rms_px:.3f} px, baseline "
        f"{100 * (calibrated.model.baseline_mm / np.linalg.norm(rig.translation_mm) - 1):+.3f} %): "
        f"sphere 40 mm {error_stats(h_cal, truth)}"
    )


def calibrated_stereo(rig, g, snr_db: float, seed: int):
    import cv2

    from calibration.camera import BoardSpec

    rng = np.random.default_rng(seed + 1)
    views = []
    for image, mapping in stereo_synth.board_session(rig, count=8, seed=seed + 3):
        app = synth.Appearance(reflectivity=image / 220.0, gain=200.0, ambient=0.05, snr_db=snr_db, bit_depth=8)
        stacks = [
            synth.render_stack(synth.sinusoid_patterns(FREQUENCIES, 4, axis=axis), mapping, g, app, rng)
            for axis in ("x", "y")
        ]
        view = board_phase_view(image, BoardSpec("chessboard", (9, 7), 30.0), stacks[0], stacks[1], FREQUENCIES, 4)
        if view is not None:
            views.append(view)
    return calibrate_stereo(
        views, (g.camera_width, g.camera_height), (g.projector_width, g.projector_height), flags=cv2.CALIB_FIX_K3
    )


def camera(seed: int) -> None:
    from calibration.camera import BoardSpec, calibrate_camera, undistort_points
    from mock_devices.board_synth import PinholeCamera, calibration_views

    truth = PinholeCamera.simple(640, 480, 600.0, (-0.2, 0.05, 0.0, 0.0, 0.0))
    for kind, marker in (("chessboard", None), ("charuco", 21.0)):
        images, _ = calibration_views(
            truth, kind, (9, 7), 30.0, marker_mm=marker, count=10, distance_mm=450.0, seed=seed
        )
        result = calibrate_camera(images, BoardSpec(kind, (9, 7), 30.0, marker))
        m = result.camera_matrix
        grid = np.array([[x, y] for x in (0.0, 319.5, 639.0) for y in (0.0, 239.5, 479.0)])
        shift = np.abs(
            undistort_points(grid, m, result.distortion) - undistort_points(grid, truth.camera_matrix, truth.distortion)
        )
        print(
            f"camera 640x480, {kind}, 10 views: reprojection RMS {result.rms_px:.3f} px, "
            f"fx {100 * (m[0, 0] / 600 - 1):+.2f} %, principal point off by ({m[0, 2] - 319.5:+.2f}, {m[1, 2] - 239.5:+.2f}) px, "
            f"distortion model off by <= {600 * shift.max():.2f} px over the image"
        )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--snr-db", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    camera(args.seed)
    ideal_rig(args.snr_db, args.seed)
    pinhole_rig(args.snr_db, args.seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
