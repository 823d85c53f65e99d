"""`rig verify` (VDI/VDE 2634-2): fits against analytic truth, the simulated procedure, sensitivity.

The end-to-end tests run a reduced procedure (fewer positions, a 256 x 192 camera) on the
simulated rig with its exact calibration; the CLI's default follows the guideline.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from rig.verify import fits, guideline, model
from rig.verify.artefacts import Artefacts, load_artefacts, parse_artefacts
from rig.verify.plan import VerificationPlan

SMALL_CAMERA = (256, 192)
SMALL_PROJECTOR = (228, 285)
ARTEFACTS_TOML = """
[sphere]
diameter_mm = 60.0
uncertainty_mm = 0.002
[ball_bar]
length_mm = 200.0
sphere_diameter_mm = 40.0
uncertainty_mm = 0.003
[plane]
length_mm = 300.0
width_mm = 80.0
flatness_mm = 0.002
uncertainty_mm = 0.002
[volume]
depth_mm = 150.0
"""
# What the reduced procedure on the 1.6 mm-pixel camera meets with margin (measured: PF 0.51, PS +0.08,
# SD -0.05, F 0.56 mm); an l0 1 % off moves SD by about 0.2 mm on the space diagonals.
SMALL_MPE = {"PF": 1.0, "PS": 0.15, "SD": 0.1, "F": 1.0}


def _cap_points(rng: np.random.Generator, centre: np.ndarray, radius: float, n: int, noise: float) -> np.ndarray:
    """Points on the upper cap of a sphere (polar angle < 70 deg), with Gaussian radial noise."""
    theta = np.arccos(rng.uniform(np.cos(np.radians(70)), 1.0, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    normal = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    return centre + normal * (radius + rng.normal(0, noise, n))[:, None]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_sphere_fit_recovers_centre_and_radius(seed: int) -> None:
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-100, 100, 3)
    points = _cap_points(rng, centre, 30.0, 5000, 0.02)
    fit = fits.fit_form("sphere", points)
    assert np.linalg.norm(fit.centre - centre) < 0.005
    assert fit.radius_mm == pytest.approx(30.0, abs=0.003)
    assert fit.excluded == int(np.floor(fits.EXCLUDED_FRACTION * (5000 - fit.trimmed)))
    # PF is the range of radial residuals: for 5000 normal draws about 7 sigma
    assert 5 * 0.02 < fit.form_range_mm < 9 * 0.02


def test_ransac_finds_the_sphere_among_a_plane_and_outliers() -> None:
    rng = np.random.default_rng(4)
    sphere = _cap_points(rng, np.array([20.0, -10.0, 60.0]), 25.0, 3000, 0.01)
    plane = np.column_stack([rng.uniform(-150, 150, 6000), rng.uniform(-100, 100, 6000), rng.normal(40, 0.01, 6000)])
    outliers = rng.uniform([-150, -100, 0], [150, 100, 100], (300, 3))
    cloud = np.vstack([sphere, plane, outliers])
    on = fits.find_sphere(cloud, 25.0, 1.0, rng)
    assert on[:3000].mean() > 0.99 and on[3000:9000].mean() < 0.02
    fit = fits.fit_form("sphere", cloud[on])
    assert fit.radius_mm == pytest.approx(25.0, abs=0.02)


def test_plane_fit_range_and_normal() -> None:
    rng = np.random.default_rng(5)
    u, v = rng.uniform(-100, 100, (2, 4000))
    normal = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
    a = np.cross(normal, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    offsets = rng.uniform(-0.05, 0.05, 4000)
    points = np.array([0, 0, 70.0]) + u[:, None] * a + v[:, None] * b + offsets[:, None] * normal
    fit = fits.fit_form("plane", points)
    assert abs(fit.normal @ normal) > 1 - 1e-8
    assert fit.form_range_mm == pytest.approx(0.1, abs=0.005)


def test_ray_cast_sphere_returns_to_a_sphere_through_the_point_formula() -> None:
    """Heights ray-cast for a pinhole at l0 become exactly the sphere through X = x p (l0 - h)/l0."""
    from calibration.models import plane_points
    from calibration.store import Calibration
    from mock_devices.artefacts import Sphere, ray_cast_heights

    rows, cols, pixel, l0 = 120, 160, 2.0, 1000.0
    centre = np.array([-40.0, 25.0, 70.0])
    h = ray_cast_heights(rows, cols, pixel, l0, [Sphere(tuple(centre), 30.0)])
    cal = Calibration(l0_mm=l0, d0_mm=250.0, f0_per_mm=0.0156, f0_frequency=8.0, pixel_mm=pixel)
    points = plane_points(cal, h, h > 0)
    assert len(points) > 500
    assert np.abs(np.linalg.norm(points - centre, axis=1) - 30.0).max() < 1e-9


def test_placements_follow_the_guideline_and_fit_the_volume() -> None:
    volume = guideline.Volume(348.0, 261.0, 150.0)
    assert volume.l0_mm == pytest.approx(np.sqrt(348.0**2 + 261.0**2 + 150.0**2))
    spheres = guideline.sphere_placements(volume, 60.0)
    bars = guideline.ball_bar_placements(volume, 200.0, 40.0)
    planes = guideline.plane_placements(volume, 300.0, 80.0)
    assert (len(spheres), len(bars), len(planes)) == (10, 7, 6)
    for bar in bars:
        a, b = (np.asarray(c) for c in bar.centres)
        assert np.linalg.norm(b - a) == pytest.approx(200.0)
    # the first four ball-bar positions lie along the volume's space diagonals
    diagonal = np.array([volume.width_mm, volume.length_mm, volume.depth_mm]) / volume.l0_mm
    assert abs(np.asarray(bars[0].along) @ diagonal) == pytest.approx(1.0)
    assert guideline.Placement.from_dict(bars[2].as_dict()) == bars[2]
    assert bars[2].prompt().startswith("ball bar, position 3 of 7: space diagonal")
    with pytest.raises(ValueError, match="does not fit"):
        guideline.sphere_placements(volume, 200.0)


def test_artefacts_file_errors_name_the_field(tmp_path: Path) -> None:
    from rig.errors import ConfigError

    (tmp_path / "a.toml").write_text(ARTEFACTS_TOML)
    assert load_artefacts(tmp_path / "a.toml").ball_bar_length_mm == 200.0
    data = {"sphere": {"diameter_mm": 60.0}, "ball_bar": {"length_mm": -1}}
    with pytest.raises(ConfigError, match=r"a.toml: \[sphere\] uncertainty_mm: expected a number"):
        parse_artefacts(data, "a.toml")
    with pytest.raises(ConfigError, match=r"\[spheres\]: unknown table"):
        parse_artefacts({"spheres": {}}, "a.toml")


# --------------------------------------------------------------------------- the simulated procedure


def _small_config(tmp: Path, simulated_rig_toml, snr_db: float) -> Path:
    path = tmp / f"rig-{snr_db:g}.toml"
    path.write_text(simulated_rig_toml(SMALL_PROJECTOR, SMALL_CAMERA, snr_db))
    return path


def _plan(spheres: int = 3, bars: int = 4, planes: int = 2) -> VerificationPlan:
    return VerificationPlan(spheres, bars, planes, dict(SMALL_MPE))


@pytest.fixture(scope="module")
def session(tmp_path_factory, simulated_rig_toml, exact_calibration):
    """A reduced verification of the small simulated rig with its exact calibration."""
    from rig.config import load_config
    from rig.verify.session import verify

    tmp = tmp_path_factory.mktemp("verify")
    config = _small_config(tmp, simulated_rig_toml, 40)
    cal = exact_calibration(config, tmp / "cal")
    (tmp / "artefacts.toml").write_text(ARTEFACTS_TOML)
    artefacts = load_artefacts(tmp / "artefacts.toml")
    result = verify(load_config(config), _plan(), artefacts, cal, tmp / "report")
    return tmp, cal, artefacts, result


def test_the_exact_calibration_passes_its_mpe(session) -> None:
    tmp, cal, _, result = session
    report = json.loads((tmp / "report" / "report.json").read_text())
    assert report["pass"] is True, report["summary"]
    for q in guideline.QUANTITIES:
        entry = report[q]
        assert entry["mpe_mm"] == SMALL_MPE[q] and entry["pass"] is True
        assert all(set(p) >= {"position", "where", "value_mm"} for p in entry["positions"])
        # with margin: the worst value stays within 60 % of the MPE
        assert abs(entry["worst_mm"]) < 0.6 * SMALL_MPE[q], (q, entry["worst_mm"])
    assert len(report["PF"]["positions"]) == 3 and len(report["SD"]["positions"]) == 4
    assert report["L0_mm"] == pytest.approx(report["volume"]["l0_mm"])
    assert report["calibration"]["path"] == str(cal)
    assert any("reduced procedure" in n for n in report["notes"])
    for name in (
        "positions.png",
        "residuals-sphere.png",
        "residuals-ball-bar.png",
        "residuals-plane.png",
        "history.png",
    ):
        assert (tmp / "report" / "figures" / name).stat().st_size > 1000
    history = (cal / "verification-history.jsonl").read_text().splitlines()
    assert json.loads(history[0])["worst_mm"]["SD"] == report["SD"]["worst_mm"]


def _calibration_off(cal: Path, target: Path, field: str, factor: float) -> Path:
    """A copy of ``cal`` whose ``field`` is ``factor`` times the true value (no history)."""
    shutil.copytree(cal, target, ignore=shutil.ignore_patterns("*.jsonl"))
    data = json.loads((target / "calibration.json").read_text())
    data[field] *= factor
    (target / "calibration.json").write_text(json.dumps(data))
    return target


@pytest.mark.parametrize("field", ["l0_mm", "f0_per_mm"])
def test_a_one_percent_calibration_error_moves_ps_and_sd_as_the_model_predicts(session, field) -> None:
    """Same captures, calibration with l0 (or the projector's fringe pitch f0) 1 % off: first-order model."""
    from rig.verify.session import compute, load_session, stored_captures

    tmp, cal, _, result = session
    off = _calibration_off(cal, tmp / f"cal-{field}", field, 1.01)
    l0 = json.loads((cal / "calibration.json").read_text())["l0_mm"]

    def move(points: np.ndarray) -> np.ndarray:
        if field == "l0_mm":
            return model.l0_displacement(points, 0.01)
        return model.f0_displacement(points, l0, 0.01)

    spots, artefacts, _ = load_session(tmp / "report")
    moved, failed = compute(stored_captures(tmp / "report", spots), off, artefacts)
    assert not failed and not result.failed
    before = {r.placement.name: r for r in result.results}
    for r in moved:
        base = before[r.placement.name]
        if r.placement.kind == "sphere":
            predicted = model.predicted_ps_change(base.fits[0], move(base.fits[0].points))
            change = r.values["PS"] - base.values["PS"]
        elif r.placement.kind == "ball-bar":
            f1, f2 = base.fits
            predicted = model.predicted_sd_change(f1, f2, (move(f1.points), move(f2.points)))
            change = r.values["SD"] - base.values["SD"]
            if field == "l0_mm":  # dSD = e dz^2 / L
                assert predicted == pytest.approx(0.01 * (f2.centre[2] - f1.centre[2]) ** 2 / 200.0, rel=0.1)
        else:
            continue
        assert abs(predicted) > 0.05 or r.placement.kind == "ball-bar"
        assert change == pytest.approx(predicted, rel=0.1, abs=0.01), r.placement.name


def test_cli_from_with_l0_off_prints_fail_naming_the_quantity(session, capsys) -> None:
    from rig.cli import main

    tmp, cal, _, _ = session
    off = _calibration_off(cal, tmp / "cal-off-cli", "l0_mm", 1.01)
    mpe = ",".join(str(SMALL_MPE[q]) for q in guideline.QUANTITIES)
    code = main(
        [
            "verify",
            "--from",
            str(tmp / "report"),
            "--calibration",
            str(off),
            "-o",
            str(tmp / "off"),
            "--mpe-mm",
            mpe,
            "-q",
        ]
    )
    out, err = capsys.readouterr()
    assert code == 2
    assert out.startswith("FAIL") and "SD" in out
    assert "SD fails: worst +" in err and "recalibrate" in err
    report = json.loads((tmp / "off" / "report.json").read_text())
    assert report["pass"] is False and report["SD"]["pass"] is False and report["drift"]["advice"] == "recalibrate"


def test_drift_warns_when_a_quantity_moves_by_half_its_mpe(session) -> None:
    from rig.verify.history import drift

    _, _, _, result = session
    report = json.loads(json.dumps(result.report))
    first = {"created": "2000-01-01", "calibration_sha256": report["calibration"]["sha256"], "worst_mm": {}}
    first["worst_mm"] = {q: report[q]["worst_mm"] for q in guideline.QUANTITIES}
    first["worst_mm"]["SD"] = report["SD"]["worst_mm"] - 0.6 * SMALL_MPE["SD"]
    trend = drift([first], report)
    assert trend.recalibrate and any(w.startswith("SD moved by +") for w in trend.warnings)
    assert not drift([], report).warnings


def test_a_noisier_camera_grows_pf(session, tmp_path, simulated_rig_toml) -> None:
    from rig.config import load_config
    from rig.verify.session import verify

    tmp, cal, artefacts, result = session
    noisy = _small_config(tmp_path, simulated_rig_toml, 25)
    other = verify(load_config(noisy), _plan(3, 0, 0), artefacts, cal, tmp_path / "noisy")
    quiet_pf = np.median([r.values["PF"] for r in result.results if "PF" in r.values])
    noisy_pf = np.median([r.values["PF"] for r in other.results if "PF" in r.values])
    assert noisy_pf > 1.5 * quiet_pf


def test_cli_user_errors_are_one_line(tmp_path, capsys) -> None:
    from rig.cli import main

    good = tmp_path / "good.toml"
    good.write_text(ARTEFACTS_TOML)
    (tmp_path / "empty").mkdir()
    args = ["verify", "--calibration", str(tmp_path), "--from", str(tmp_path / "empty"), "--artefacts", str(good)]
    assert main(args) == 1  # captures of a real rig: the MPE must be declared
    assert "--mpe-mm: missing: declare the rig's maximum permissible errors" in capsys.readouterr().err
    assert main([*args, "--mpe-mm", "1,1,1,1"]) == 1
    assert "no session.json and no capture (capture.json) in it or below it" in capsys.readouterr().err
    bad = tmp_path / "a.toml"
    bad.write_text("[sphere]\ndiameter_mm = 'big'\n")
    assert main(["verify", "--calibration", str(tmp_path), "--artefacts", str(bad)]) == 1
    assert "[sphere] diameter_mm: expected a number" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["verify", "--calibration", "c", "--mpe-mm", "1,2"])
    assert "expected four values PF,PS,SD,F" in capsys.readouterr().err


def test_artefact_defaults_meet_the_guideline_for_the_simulated_rig() -> None:
    from rig.verify.plan import size_notes

    volume = guideline.volume_of_view(1024, 768, 0.4, 1000.0, 150.0)
    assert size_notes(volume, Artefacts()) == []
    assert size_notes(volume, Artefacts(sphere_diameter_mm=20.0))[0].startswith("sphere diameter 20 mm outside")


def test_from_plain_captures_named_after_their_artefact(session, tmp_path, capsys) -> None:
    """Captures taken outside a session (a real rig's, say) give their figures by name alone."""
    from rig.cli import main

    tmp, cal, _, result = session
    shutil.copytree(tmp / "report" / "captures" / "sphere-01", tmp_path / "plain" / "sphere-a")
    shutil.copytree(tmp / "report" / "captures" / "plane-01", tmp_path / "plain" / "plane-b")
    args = ["verify", "--from", str(tmp_path / "plain"), "--calibration", str(cal), "-o", str(tmp_path / "out")]
    args += ["--mpe-mm", ",".join(str(SMALL_MPE[q]) for q in guideline.QUANTITIES)]
    assert main([*args, "-q"]) == 1  # no session.json: the artefacts' values must be given
    assert "give the artefacts' calibrated values (--artefacts)" in capsys.readouterr().err
    assert main([*args, "--artefacts", str(tmp / "artefacts.toml"), "-q"]) == 2
    out, err = capsys.readouterr()
    assert out.startswith("FAIL") and "SD fails: no position measured" in err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    before = {r.placement.name: r.values for r in result.results}
    assert report["PF"]["positions"][0]["value_mm"] == pytest.approx(before["sphere-01"]["PF"], abs=1e-9)
    assert report["F"]["positions"][0]["value_mm"] == pytest.approx(before["plane-01"]["F"], abs=1e-9)
    assert report["PF"]["pass"] and report["F"]["pass"] and not report["pass"]


def test_example_artefacts_are_the_simulated_rigs() -> None:
    example = load_artefacts(Path(__file__).parent.parent / "examples" / "artefacts.toml")
    assert {**example.__dict__, "source": ""} == {**Artefacts().__dict__, "source": ""}


def test_operator_is_prompted_and_stop_leaves_nothing(session, tmp_path) -> None:
    from rig.config import load_config
    from rig.events import Cancelled, CancelToken, Reporter
    from rig.verify.operator import PromptOperator
    from rig.verify.session import verify

    tmp, cal, artefacts, _ = session
    history = (cal / "verification-history.jsonl").read_text()
    prompts: list[str] = []
    token = CancelToken()

    def ask(message: str) -> None:
        prompts.append(message)
        if len(prompts) == 2:
            token.cancel()  # the operator presses Stop during the second position

    with pytest.raises(Cancelled):
        verify(
            load_config(tmp / "rig-40.toml"),
            _plan(2, 1, 1),
            artefacts,
            cal,
            tmp_path / "stopped",
            PromptOperator(ask),
            Reporter("verify", cancel=token),
        )
    assert prompts == [
        "sphere, position 1 of 2: low, near corner -x -y, press Enter ",
        "sphere, position 2 of 2: low, corner +x -y, press Enter ",
    ]
    assert list(tmp_path.iterdir()) == []  # no report, no staging directory
    assert (cal / "verification-history.jsonl").read_text() == history


def test_history_appends_whole_lines_and_refuses_a_link(tmp_path: Path) -> None:
    from rig.errors import OutputError
    from rig.store import files
    from rig.verify.history import HISTORY_FILE, read_history

    path = tmp_path / HISTORY_FILE
    files.append_line(path, '{"created": "2", "worst_mm": {}}', OutputError)
    files.append_line(path, '{"created": "1", "worst_mm": {}}', OutputError)
    path.write_text(path.read_text() + "torn{\n")
    assert [e["created"] for e in read_history(tmp_path)] == ["1", "2"]  # oldest first, the torn line skipped
    with pytest.raises(OutputError, match="one line"):
        files.append_line(path, "a\nb", OutputError)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / HISTORY_FILE).symlink_to(path)
    with pytest.raises(OutputError, match="symbolic link"):
        files.append_line(tmp_path / "elsewhere" / HISTORY_FILE, "{}", OutputError)


def test_cli_runs_the_simulated_procedure_unattended(session, tmp_path, capsys) -> None:
    from rig.cli import main

    tmp, cal, _, _ = session
    mpe = ",".join(str(SMALL_MPE[q]) for q in guideline.QUANTITIES)
    args = ["verify", "--config", str(tmp / "rig-40.toml"), "--calibration", str(cal), "--artefacts"]
    args += [str(tmp / "artefacts.toml"), "--mpe-mm", mpe, "--spheres", "1", "-o", str(tmp_path / "cli"), "-q"]
    assert main(args) == 0
    out, err = capsys.readouterr()
    assert out.startswith("PASS  PF ") and out.rstrip().endswith(" mm") and "!" not in out
    assert "reduced procedure: sphere at 1 positions, the guideline asks at least 10" in err
    report = json.loads((tmp_path / "cli" / "report.json").read_text())
    assert [len(report[q]["positions"]) for q in guideline.QUANTITIES] == [1, 1, 7, 6]
    assert (tmp_path / "cli" / "report.md").read_text().startswith("# Verification (VDI/VDE 2634 Part 2)")
    assert main(args) == 1  # the report exists: not replaced without --overwrite
    assert f"{tmp_path / 'cli'}: already exists" in capsys.readouterr().err
