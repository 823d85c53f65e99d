"""`rig calibrate` on the simulated rig, then `rig scan --process`; --from; prompts; bad sessions.

The simulated rig's true geometry (l0 = 1000 mm, d0 = 250 mm, f0 = 0.015625 /mm at 8 fringes,
pixel 1.6 mm) is what the session must find, unattended, from its own captures.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
from cli_steps import calibrate_on_plane, scan_and_process

from calibration.errors import CalibrationError
from calibration.models import height_from_phase
from calibration.store import read_calibration
from rig.calibrate.operator import ConsoleOperator, StageCommand
from rig.calibrate.session import CalibrationPlan, acquire, compute
from rig.cli import main
from rig.config import load_config
from rig.errors import CaptureError, ConfigError
from rig.hardware.simulated import geometry_from_config, scene_height
from rig.store.capture import read_capture, write_capture


@pytest.fixture(scope="module")
def rig_text(simulated_rig_toml):
    """The rig these tests calibrate: a gamma-1.8 projector, a 30 dB camera."""
    return simulated_rig_toml((456, 570), (256, 192), snr_db=30, gamma=1.8)


BOARD = "chessboard:7x5:30"


@pytest.fixture(scope="module")
def session(tmp_path_factory, rig_text):
    root = tmp_path_factory.mktemp("calibrate")
    config = root / "rig.toml"
    config.write_text(rig_text, encoding="utf-8")
    code = main(
        [
            "calibrate",
            "--config",
            str(config),
            "-o",
            str(root / "cal"),
            "--board",
            BOARD,
            "--board-views",
            "4",
            "--gamma",
            "9",
            "-q",
        ]
    )
    assert code == 0
    return root, config


def test_unattended_session_recovers_the_simulated_geometry(session):
    root, config = session
    cal = read_calibration(root / "cal")
    assert cal.model == "reference-plane" and cal.reference == "reference"
    assert cal.f0_frequency == 32.0
    assert cal.l0_mm == pytest.approx(1000.0, rel=0.005)
    assert cal.d0_mm == pytest.approx(250.0, rel=0.005)
    assert cal.per_mm(8.0) == pytest.approx(0.015625, rel=0.005)
    assert cal.pixel_mm == pytest.approx(409.6 / 256, rel=0.005)
    extra = cal.extra
    assert extra["heights_mm"] == [25.0, 50.0, 100.0, 150.0]
    assert max(abs(r) for r in extra["residuals_mm"]) < 0.1
    assert set(extra["uncertainty"]) == {"l0_mm", "d0_mm", "f0_per_mm"}
    assert extra["reprojection_rms_px"] < 0.2 and len(extra["camera_matrix"]) == 3
    assert extra["gamma"]["gamma"] == pytest.approx(1.8, rel=0.03)
    lut = np.load(root / "cal" / extra["gamma_lut"])
    assert lut.shape == (256,) and lut[128] == pytest.approx(0.5 ** (1 / 1.8), abs=0.02)
    for label in ("plane-at-25mm", "plane-at-150mm"):
        assert read_capture(root / "cal" / "planes" / label).scene == label


def test_simulated_board_views_are_acquired_through_the_drivers(session):
    """Issue 9: the board views come through projector, trigger and camera like any scan (the
    simulated camera sees the board's albedo under the projector's white), not written directly."""
    root, _ = session
    for name in ("plane", "view-01", "view-04"):
        capture = read_capture(root / "cal" / "board" / name)
        # under the projector's white, then its black (room light only: where the projector lights the board)
        assert capture.complete and capture.patterns == [{"kind": "flat", "level": 1.0}, {"kind": "flat", "level": 0.0}]
        manifest = json.loads(capture.manifest_path.read_text())
        assert manifest["devices"]["camera"] == "simulated camera" and "simulation" in manifest
        image = capture.load_frame(0).astype(np.float64)
        # a printed board under white light: dark squares near the ambient floor, white ones near full scale
        assert np.percentile(image, 5) < 0.3 * np.percentile(image, 95)
        assert capture.load_frame(1).mean() < 0.3 * image.mean()


def test_scan_then_process_matches_the_virtual_scene(session, rig_text):
    root, config = session
    # scans go through the measured LUT, as the calibration captures did
    scan_config = root / "rig-lut.toml"
    scan_config.write_text(
        rig_text.replace("[camera]", f'gamma_lut = "{root / "cal" / "gamma-lut.npy"}"\n[camera]'), encoding="utf-8"
    )
    scan_and_process(scan_config, root / "obj", root / "cal", root / "out")
    height = np.load(root / "out" / "height.npy")
    rig_config = load_config(config)
    truth = scene_height(rig_config, "object", geometry_from_config(rig_config))
    valid = np.isfinite(height)
    assert valid.mean() > 0.95
    error = height[valid] - truth[valid]
    assert float(np.sqrt(np.mean(error**2))) < 0.5
    top = valid & (truth > truth.max() - 5)  # the hemisphere's top, ~100 mm up: no bias there either
    assert abs(float(np.median(height[top] - truth[top]))) < 0.2


def test_recompute_from_stored_captures_with_another_model(session, capsys):
    root, _ = session
    assert (
        main(
            [
                "calibrate",
                "--from",
                str(root / "cal"),
                "--model",
                "polynomial",
                "--degree",
                "3",
                "-o",
                str(root / "poly"),
                "--json",
                "-q",
            ]
        )
        == 0
    )
    printed = json.loads(capsys.readouterr().out)
    assert printed["model"] == "polynomial"
    poly = read_calibration(root / "poly")
    # the reference capture travels with the calibration: references are relative and inside (issue 10)
    assert poly.reference == "reference" and (root / "poly" / "reference" / "capture.json").is_file()
    assert (root / "poly" / "polynomial.npy").is_file()
    # same captures, both models: heights of the 100 mm plane agree with it
    reference = read_calibration(root / "cal")
    from rig.calibrate.session import _absolute_phase

    plane, frequency, _, _ = _absolute_phase(root / "cal" / "planes" / "plane-at-100mm")
    ref_phase, _, _, _ = _absolute_phase(root / "cal" / "reference")
    for cal in (reference, poly):
        height = height_from_phase(cal, plane, ref_phase, frequency)
        assert float(np.nanmedian(height)) == pytest.approx(100.0, abs=0.05)
    # recomputing in place reproduces the stored calibration
    again = compute(root / "cal")
    assert again.calibration.l0_mm == pytest.approx(reference.l0_mm, rel=1e-9)


def test_operator_is_prompted_for_every_step(tmp_path, rig_text):
    config = tmp_path / "rig.toml"
    config.write_text(rig_text, encoding="utf-8")
    prompts: list[str] = []
    plan = CalibrationPlan(heights_mm=(20.0, 40.0, 60.0), board=None, pixel_mm=1.6)
    acquire(load_config(config), plan, tmp_path / "cal", ConsoleOperator(ask=prompts.append))
    assert prompts == [
        "move the plane to the reference position (0 mm), press Enter ",
        "move the plane to 20 mm, press Enter ",
        "move the plane to 40 mm, press Enter ",
        "move the plane to 60 mm, press Enter ",
    ]
    result = compute(tmp_path / "cal")
    assert result.calibration.l0_mm == pytest.approx(1000.0, rel=0.02)

    def no_console(_message: str) -> str:
        raise EOFError

    with pytest.raises(ConfigError, match="needs an operator at the console"):
        ConsoleOperator(ask=no_console).plane(20.0)


def test_stage_command_moves_a_motorised_stage(tmp_path):
    log = tmp_path / "stage.log"
    script = f"import sys; open({str(log)!r}, 'a').write(sys.argv[1] + '\\n')"
    stage = StageCommand(f"{sys.executable} -c {json.dumps(script)} {{height_mm}}")
    operator = ConsoleOperator(ask=lambda _m: pytest.fail("no prompt expected with a stage"), stage=stage)
    operator.plane(25.0)
    operator.plane(0.0)
    assert log.read_text().split() == ["25.0", "0.0"]
    with pytest.raises(ConfigError, match="moving to 5 mm failed \\(exit 3\\)"):
        StageCommand(f"{sys.executable} -c 'import sys; sys.exit(3)' {{height_mm}}").move(5.0)
    with pytest.raises(ConfigError, match="placeholder"):
        StageCommand("stage-move 10")


def test_bad_sessions_give_one_line_errors(session, tmp_path, capsys):
    root, config = session
    assert main(["calibrate", "--config", str(config), "--heights", "25,50", "-o", str(tmp_path / "x")]) == 1
    assert "need at least 3 plane heights" in capsys.readouterr().err
    assert main(["calibrate", "--from", str(tmp_path)]) == 1
    assert "not a calibration session" in capsys.readouterr().err
    # a plane captured with other patterns than the reference
    broken = tmp_path / "broken"
    import shutil

    shutil.copytree(root / "cal", broken)
    plane = broken / "planes" / "plane-at-50mm"
    capture = read_capture(plane)
    frames = capture.load_frames()
    patterns = [dict(p, frequency=16 if p["frequency"] == 32 else p["frequency"]) for p in capture.patterns]
    shutil.rmtree(plane)
    write_capture(plane, frames, patterns, {"width": 456, "height": 570}, scene="plane-at-50mm")
    assert main(["calibrate", "--from", str(broken), "-q"]) == 1
    err = capsys.readouterr().err
    assert "plane-at-50mm: pattern 8 frequency = 16 but" in err and "Traceback" not in err
    # a plane whose label carries no height
    shutil.rmtree(plane)
    write_capture(plane, frames, capture.patterns, {"width": 456, "height": 570}, scene="some-plane")
    with pytest.raises(CalibrationError, match="scene 'some-plane': expected 'plane-at-<height>mm'"):
        compute(broken)
    assert (
        main(
            [
                "calibrate",
                "--import-opencv",
                str(tmp_path / "none.yml"),
                "--projector-size",
                "1920x1080",
                "-o",
                str(tmp_path / "st"),
            ]
        )
        == 1
    )
    assert "none.yml: missing" in capsys.readouterr().err


def test_stereo_session_recomputed_from_stored_poses(tmp_path):
    """A projector-camera session on disk (board poses with fringes along x and y, and the
    reference plane), as a real pinhole rig would leave it, rendered by mock_devices.stereo_synth."""
    from mock_devices import synth
    from mock_devices.stereo_synth import Scene, board_session, demo_rig, demo_scene, trace
    from rig.calibrate.session import stereo_patterns

    rig = demo_rig(320, 256)
    projector = {"width": rig.projector.width, "height": rig.projector.height}
    geometry = synth.RigGeometry(
        camera_width=320, camera_height=256, projector_width=rig.projector.width, projector_height=rig.projector.height
    )
    config = load_config(None)
    patterns = stereo_patterns(config)
    rng = np.random.default_rng(5)
    cal = tmp_path / "cal"
    for index, (image, mapping) in enumerate(board_session(rig, count=6, seed=11), start=1):
        appearance = synth.Appearance(reflectivity=image / 220.0, gain=200.0, ambient=0.05, snr_db=30.0, bit_depth=8)
        frames = [image] + list(synth.render_stack(patterns[1:], mapping, geometry, appearance, rng))
        write_capture(cal / "stereo" / f"pose-{index:02d}", frames, patterns, projector, scene=f"board-pose-{index}")
    appearance = synth.Appearance(gain=200.0, ambient=0.05, snr_db=30.0, bit_depth=8)
    scan = config.scan.patterns()
    _, plane_map = trace(rig, Scene(plane_distance=600.0))
    write_capture(
        cal / "reference",
        synth.render_stack(scan, plane_map, geometry, appearance, rng),
        scan,
        projector,
        scene="reference",
    )
    (cal / "session.json").write_text(json.dumps(CalibrationPlan(model="stereo", board=None, board_views=6).to_json()))
    assert main(["calibrate", "--from", str(cal), "--board", "chessboard:9x7:30", "-q"]) == 0
    stereo = read_calibration(cal)
    assert stereo.model == "stereo" and stereo.extra["reprojection_rms_px"] < 0.2
    assert stereo.extra["plane"][3] == pytest.approx(600.0, rel=0.003)
    # heights of the simulated object above the measured reference plane
    truth, mapping = trace(rig, demo_scene())
    phase = np.where(mapping.lit, 2 * np.pi * 64 * mapping.u / rig.projector.width, np.nan)
    height = height_from_phase(stereo, phase, None, 64)
    on = np.isfinite(height) & (600.0 - truth[..., 2] > 0.5)
    assert float(np.sqrt(np.mean((height[on] - (600.0 - truth[..., 2])[on]) ** 2))) < 0.3
    # the simulated rig cannot run a stereo session itself: it says why
    with pytest.raises(ConfigError, match="not a\npinhole|not a pinhole"):
        acquire(config, CalibrationPlan(model="stereo", board_views=3), tmp_path / "sim")


def test_gamma_ripple_removed_in_processing(tmp_path, rig_text):
    """A gamma-2.2 projector under 3-step phase shifting, not pre-corrected: the ripple table the
    calibration learnt on the reference plane takes the waves out of the object's heights."""
    from rig.pipeline import gamma_correction
    from rig.pipeline import run as pipeline
    from rig.pipeline.plan import ProcessOptions

    config = tmp_path / "rig.toml"
    config.write_text(
        rig_text.replace("steps = 4", "steps = 3")
        .replace("gamma = 1.8", "gamma = 2.2")
        .replace("snr_db = 30", "snr_db = 40")
    )
    assert calibrate_on_plane(config, tmp_path / "cal", 1.6) == 0
    assert read_calibration(tmp_path / "cal").extra["phase_error"]["ripple_rms_rad"] > 0.05
    assert main(["scan", "--config", str(config), "-o", str(tmp_path / "obj")]) == 0
    rig_config = load_config(config)
    truth = scene_height(rig_config, "object", geometry_from_config(rig_config))
    errors = {}
    for correction in ("none", gamma_correction.NAME):
        result = pipeline.process(tmp_path / "obj", tmp_path / "cal", ProcessOptions(correction=correction))
        valid = np.isfinite(result.height)
        errors[correction] = float(np.sqrt(np.mean((result.height[valid] - truth[valid]) ** 2)))
    assert errors[gamma_correction.NAME] < errors["none"] / 2
    # and from the command line
    assert (
        main(
            [
                "process",
                str(tmp_path / "obj"),
                "--calibration",
                str(tmp_path / "cal"),
                "--correction",
                "gamma-table",
                "-o",
                str(tmp_path / "out"),
                "-q",
            ]
        )
        == 0
    )
    height = np.load(tmp_path / "out" / "height.npy")
    valid = np.isfinite(height)
    assert float(np.sqrt(np.mean((height[valid] - truth[valid]) ** 2))) == pytest.approx(
        errors[gamma_correction.NAME], rel=1e-6
    )


def test_gauge_block_measured_through_the_whole_product(session, tmp_path, rig_text):
    """rig calibrate (the session above) then rig scan --process of a 25.000 mm gauge block at 30 dB."""
    root, _ = session
    config = tmp_path / "rig.toml"
    config.write_text(
        rig_text.replace('scene = "hemisphere"', 'scene = "gauge-block"').replace(
            "[camera]", f'gamma_lut = "{root / "cal" / "gamma-lut.npy"}"\n[camera]'
        )
    )
    scan_and_process(config, tmp_path / "block", root / "cal", tmp_path / "out")
    height = np.load(tmp_path / "out" / "height.npy")
    rig_config = load_config(config)
    truth = scene_height(rig_config, "object", geometry_from_config(rig_config))
    from scipy import ndimage

    top = ndimage.binary_erosion(truth == 25.0, iterations=3)  # away from the edges and their shadow
    assert np.isfinite(height[top]).all()
    assert abs(float(np.mean(height[top])) - 25.0) < 0.1
    plane = ndimage.binary_erosion(truth == 0.0, iterations=3) & np.isfinite(height)
    assert abs(float(np.mean(height[plane]))) < 0.1


def test_overwrite_replaces_only_calibration_directories(tmp_path):
    precious = tmp_path / "thesis"
    precious.mkdir()
    (precious / "chapter1.tex").write_text("...")
    plan = CalibrationPlan(board=None, pixel_mm=1.6)
    with pytest.raises(CaptureError, match="already exists and is not empty"):
        acquire(load_config(None), plan, precious)
    with pytest.raises(CaptureError, match="not a calibration directory"):
        acquire(load_config(None), plan, precious, overwrite=True)
    assert (precious / "chapter1.tex").is_file()
