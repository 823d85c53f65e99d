"""Issue 10, the classes left after the file layer: degenerate maps in the preview, camera matrices
that cannot be inverted, `rig calibrate --overwrite`, the demo report's paths, a read-only output
filesystem and the OpenCV FileStorage reader's errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from cli_steps import assert_one_line, calibrate_on_plane, run

from rig.api import process
from rig.cli import main
from rig.errors import OutputError
from rig.store import files
from rig.store import result_files as outputs
from rig.store.result_files import write_preview
from rig.store.results import write_result

REPO = Path(__file__).resolve().parents[1]


# 5. the preview of a degenerate map (the crash after phase.npy was written) ---------------------

DEGENERATE_MAPS = {
    "all-nan": lambda shape: np.full(shape, np.nan),
    "constant": lambda shape: np.full(shape, 7.0),
    "constant-huge": lambda shape: np.full(shape, 1e20),  # the ends coincide after +-0.5: was 0/0 in a tick
    "span-overflows": lambda shape: np.where(np.indices(shape)[1] % 2 == 0, -1e308, 1e308),  # was an endless tick loop
    "infinities": lambda shape: np.where(np.indices(shape)[1] % 2 == 0, np.inf, -np.inf),
    "one-finite": lambda shape: np.where(np.indices(shape).sum(axis=0) == 0, 3.0, np.nan),
    "float32-extremes": lambda shape: np.where(np.indices(shape)[0] % 2 == 0, 3.4e38, -3.4e38),
    "subnormal": lambda shape: np.arange(np.prod(shape)).reshape(shape) * 5e-324,
}


@pytest.mark.parametrize("name", sorted(DEGENERATE_MAPS))
def test_preview_of_a_degenerate_map_is_drawn(tmp_path, name) -> None:
    values = DEGENERATE_MAPS[name]((24, 40))
    with np.errstate(over="raise", divide="raise", invalid="raise"):  # no hidden overflow or 0/0 either
        low, high = write_preview(tmp_path / "p.png", values, "mm", name)
    assert np.isfinite([low, high, high - low]).all() and low < high
    import cv2

    assert cv2.imread(str(tmp_path / "p.png")).shape[:2] == (24, 40 + outputs.PREVIEW_BAR_PX)


def test_preview_of_an_empty_map_is_drawn(tmp_path) -> None:
    assert write_preview(tmp_path / "p.png", np.zeros((0, 0)), "rad") == (0.0, 1.0)  # was SIGFPE in OpenCV


@pytest.mark.parametrize("name", ["constant-huge", "span-overflows", "all-nan"])
def test_outputs_of_a_degenerate_height_map_are_complete(tmp_path, small_capture, name) -> None:
    result = process(small_capture.capture, small_capture.calibration)
    with np.errstate(over="ignore"):  # 1e308 becomes an infinity in float32, as a height would
        height = DEGENERATE_MAPS[name](result.mask.shape).astype(np.float32)
    out = tmp_path / "out"
    report = write_result(replace(result, height=height), out)
    on_disk = json.loads((out / "report.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    assert on_disk["preview"] == report["preview"] and np.isfinite(report["preview"]["range"]).all()
    assert {p.name for p in out.iterdir()} == set(report["files"].values())


def test_a_failing_preview_keeps_the_old_output(tmp_path, small_capture, monkeypatch) -> None:
    result = process(small_capture.capture, small_capture.calibration)
    out = tmp_path / "out"
    write_result(result, out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def broken(*_args, **_kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(outputs, "write_preview", broken)
    with pytest.raises(OSError):
        write_result(result, out, overwrite=True)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert not list(tmp_path.glob("out.*"))  # no staging directory left behind


# 9. a NaN or singular camera matrix (was reported as "the whole map is shadow") -------------------

GOOD_CAMERA = [[200.0, 0.0, 80.0], [0.0, 200.0, 60.0], [0.0, 0.0, 1.0]]


@pytest.mark.parametrize(
    ("field", "value", "expected"),
    [
        ("camera_matrix", [[float("nan"), 0, 80], [0, 200, 60], [0, 0, 1]], "finite"),
        ("camera_matrix", [[0, 0, 80], [0, 0, 60], [0, 0, 1]], "fx, fy > 0"),
        ("camera_matrix", [[200, 0, 80], [0, -200, 60], [0, 0, 1]], "fx, fy > 0"),
        ("camera_matrix", [[1e-300, 0, 80], [0, 1e-300, 60], [0, 0, 1]], "invertible"),
        ("camera_matrix", [[200, 0, 80], [0, 200, 60], [0, 0, 0]], "[0, 0, 1]"),
        ("camera_matrix", [[200, 0, 80], [0, 200, 60]], "3x3"),
        ("camera_matrix", "identity", "3x3"),
        ("distortion", [0.1, float("inf"), 0, 0, 0], "finite"),
        ("distortion", [0.1, 0.2, 0.3], "0, 4, 5, 8, 12 or 14"),
    ],
)
def test_unusable_camera_matrix_is_named_when_the_calibration_is_read(
    capsys, tmp_path, small_capture, field, value, expected
) -> None:
    path = small_capture.calibration / "calibration.json"
    data = json.loads(path.read_text())
    data.update({"camera_matrix": GOOD_CAMERA, "distortion": [0.0] * 5, field: value})
    path.write_text(json.dumps(data, allow_nan=True).replace("NaN", "1e999").replace("Infinity", "1e999"))
    if "nan" in json.dumps(value, allow_nan=True).lower():  # JSON has no NaN: 1e999 - 1e999 is what a tool would write
        path.write_text(path.read_text().replace("1e999", "NaN"))
    code, err = run(
        capsys,
        "process",
        small_capture.capture,
        "--calibration",
        small_capture.calibration,
        "-o",
        tmp_path / "out",
        "-q",
    )
    assert_one_line(code, err, str(path), field, expected)
    assert not (tmp_path / "out").exists()


def test_a_usable_camera_matrix_is_accepted(tmp_path, small_capture) -> None:
    from calibration.store import read_calibration

    path = small_capture.calibration / "calibration.json"
    data = json.loads(path.read_text())
    data.update({"camera_matrix": GOOD_CAMERA, "distortion": [0.0] * 5})
    path.write_text(json.dumps(data))
    assert read_calibration(small_capture.calibration).extra["camera_matrix"] == GOOD_CAMERA


# 1, 7. `rig calibrate --overwrite`: the old calibration survives a failed or stopped session -------

SMALL_RIG = "[camera]\nsize = [64, 48]\n[projector]\nsize = [96, 120]\n[scan]\nfrequencies = [1, 8]\nsteps = 4\n"


class FailingOperator:
    """Sets up nothing and fails when asked for the plane at ``fail_at`` mm (a stage fault)."""

    def __init__(self, fail_at: float, error: BaseException) -> None:
        self.fail_at, self.error = fail_at, error

    def plane(self, height_mm: float) -> None:
        if height_mm == self.fail_at:
            raise self.error

    def board(self, index: int, on_plane: bool) -> None: ...
    def pose(self, index: int) -> None: ...
    def clear(self) -> None: ...


@pytest.mark.parametrize("error", [OutputError("stage: motor fault"), KeyboardInterrupt()], ids=["error", "interrupt"])
def test_failed_calibrate_overwrite_keeps_the_old_calibration(tmp_path, error) -> None:
    from calibration.store import read_calibration
    from rig.calibrate.session import CalibrationPlan, calibrate
    from rig.config import load_config

    (tmp_path / "rig.toml").write_text(SMALL_RIG)
    config = load_config(tmp_path / "rig.toml")
    cal = tmp_path / "cal"
    old = calibrate(config, CalibrationPlan(board=None, pixel_mm=1.6), cal)
    assert old.calibration.path == cal  # the final name, not the staging directory's
    before = {p.relative_to(cal): p.read_bytes() for p in cal.rglob("*") if p.is_file()}
    plan = CalibrationPlan(heights_mm=(20.0, 40.0, 80.0), board=None, pixel_mm=1.6)
    with pytest.raises(type(error)):
        calibrate(config, plan, cal, FailingOperator(40.0, error), overwrite=True)
    assert {p.relative_to(cal): p.read_bytes() for p in cal.rglob("*") if p.is_file()} == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith("cal")] == ["cal"]
    new = calibrate(config, plan, cal, overwrite=True)
    assert read_calibration(cal).extra["heights_mm"] == [20.0, 40.0, 80.0] == new.calibration.extra["heights_mm"]


# 4. `rig demo`'s report names the committed capture, not its staging directory ---------------------


def test_demo_report_names_the_final_paths(capsys, tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    for out in (Path("demo"), tmp_path / "demo-abs"):
        assert main(["demo", "-o", str(out), "--size", "48x32", "-q"]) == 0
        capsys.readouterr()
        text = (out / "processed" / "report.json").read_text()
        assert files.INCOMPLETE_MARK not in text, text
        report = json.loads(text)
        assert files.same_path(report["capture"], out / "scan" / "object")
        assert files.same_path(report["calibration"], out / "scan" / "calibration")
        assert files.same_path(report["reference"], out / "scan" / "calibration" / "reference")


def test_committed_path_maps_relative_and_absolute_spellings(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    staging, target = Path("d.incomplete-x"), Path("d")
    assert files.committed_path(staging / "scan" / "object", staging, target) == Path("d/scan/object")
    assert files.committed_path(tmp_path / staging / "a", staging, target) == tmp_path / "d" / "a"
    assert files.committed_path(Path("elsewhere/a"), staging, target) == Path("elsewhere/a")


# 5. an output on a read-only filesystem: one line, exit 1, before any work -------------------------


def _mount(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(["mount", *args], capture_output=True, text=True)


@pytest.fixture(scope="module")
def read_only(tmp_path_factory):
    """A tmpfs holding a capture, a processing output and a calibration session, remounted read-only.

    Needs permission to mount (root, or a container that allows it); skipped with the reason otherwise.
    """
    from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan

    root = tmp_path_factory.mktemp("ro")
    mount = root / "fs"
    mount.mkdir()
    try:
        done = _mount(["-t", "tmpfs", "-o", "size=64m", "tmpfs", str(mount)])
    except FileNotFoundError:
        pytest.skip("no mount command to make a read-only filesystem")
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs privileges): {done.stderr.strip()}")
    try:
        scan = write_simulated_scan(simulate_scan("hemisphere", geometry=demo_geometry(48, 32), seed=1), mount / "scan")
        assert main(["process", str(scan.capture), "-o", str(mount / "out"), "-q"]) == 0
        (root / "rig.toml").write_text(SMALL_RIG)
        assert calibrate_on_plane(root / "rig.toml", mount / "cal", 1.6) == 0
        (mount / "foreign.yml").write_text("%YAML:1.0\n---\nM1: 1\n")
        done = _mount(["-o", "remount,ro", str(mount)])
        if done.returncode != 0:
            pytest.skip(f"cannot remount the tmpfs read-only: {done.stderr.strip()}")
        yield {"fs": mount, "capture": scan.capture, "calibration": scan.calibration, "rig": root / "rig.toml"}
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


READ_ONLY_COMMANDS = {
    "process-new": ("process", "{capture}", "-o", "{fs}/new", "-q"),
    "process-replace": ("process", "{capture}", "-o", "{fs}/out", "-q"),
    "process-below": ("process", "{capture}", "-o", "{fs}/sub/dir/out", "-q"),
    "scan": ("scan", "--config", "{rig}", "-o", "{fs}/cap"),
    "scan-overwrite": ("scan", "--config", "{rig}", "-o", "{capture}", "--overwrite"),
    "simulate": ("simulate", "-o", "{fs}/sim", "--size", "32x24"),
    "demo": ("demo", "-o", "{fs}/demo", "--size", "32x24", "-q"),
    "calibrate": ("calibrate", "--config", "{rig}", "-o", "{fs}/cal2", "--board", "none", "--pixel-mm", "1.6", "-q"),
    "calibrate-overwrite": (
        "calibrate",
        "--config",
        "{rig}",
        "-o",
        "{fs}/cal",
        "--overwrite",
        "--board",
        "none",
        "--pixel-mm",
        "1.6",
        "-q",
    ),
    "calibrate-from-in-place": ("calibrate", "--from", "{fs}/cal", "-q"),
    "calibrate-from-elsewhere": ("calibrate", "--from", "{fs}/cal", "-o", "{fs}/cal3", "-q"),
    "import-opencv": (
        "calibrate",
        "--import-opencv",
        "{fs}/foreign.yml",
        "--projector-size",
        "96x120",
        "-o",
        "{fs}/imported",
    ),
}


@pytest.mark.parametrize("name", sorted(READ_ONLY_COMMANDS))
def test_read_only_output_is_one_line(capsys, read_only, name) -> None:
    argv = [a.format(**read_only) for a in READ_ONLY_COMMANDS[name]]
    before = sorted(str(p) for p in read_only["fs"].rglob("*"))
    code, err = run(capsys, *argv)
    assert_one_line(code, err, "Read-only file system")
    line = next(line for line in err.splitlines() if ": error:" in line)
    assert ".tmp" not in line and files.INCOMPLETE_MARK not in line, line  # names the output, not a scratch file
    assert sorted(str(p) for p in read_only["fs"].rglob("*")) == before


# 5. `rig calibrate --import-opencv` on files OpenCV cannot parse, under OpenCV 4 and 5 --------------

MATRIX = "!!opencv-matrix\n   rows: {rows}\n   cols: 3\n   dt: {dt}\n   data: [ {data} ]\n"
BROKEN_FILESTORAGE = {  # name -> (file name, content); each must be one line naming the file
    "yaml-syntax": ("c.yml", "%YAML:1.0\n---\nM1: [[[[\n"),  # constructor: SystemError (4.10+, 5.0) or cv2.error
    "xml-syntax": ("c.xml", '<?xml version="1.0"?>\n<opencv_storage><M1 type_id="opencv-matrix"><rows>3</rows></M1>'),
    "data-count": ("c.yml", "%YAML:1.0\n---\nM1: " + MATRIX.format(rows=3, dt="d", data="1., 2.")),  # mat(): cv2.error
    "unknown-dt": ("c.yml", "%YAML:1.0\n---\nM1: " + MATRIX.format(rows=3, dt="q", data=", ".join(["1."] * 9))),
    "huge-rows": ("c.yml", "%YAML:1.0\n---\nM1: " + MATRIX.format(rows=10**8, dt="d", data="1.")),
    "text-data": ("c.yml", "%YAML:1.0\n---\nM1: " + MATRIX.format(rows=1, dt="d", data="abc")),
    "map-not-matrix": ("c.yml", "%YAML:1.0\n---\nM1: {a: 1}\n"),
    "list-of-words": ("c.yml", "%YAML:1.0\n---\nM1: [a, b]\n"),  # was read as zeros
    "json-no-dt": ("c.json", '{"M1": {"type_id": "opencv-matrix", "rows": 3}}'),
}


def _check_broken_filestorage(directory: Path, opencv_site: str = "") -> dict[str, str]:
    """Each broken file through `rig calibrate --import-opencv` (with ``opencv_site`` first on the path):
    name -> what went wrong ("" when it was one clean line)."""
    problems = {}
    for name, (file_name, text) in BROKEN_FILESTORAGE.items():
        path = directory / name / file_name
        path.parent.mkdir(parents=True)
        path.write_text(text)
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "rig.cli",
                "calibrate",
                "--import-opencv",
                str(path),
                "--projector-size",
                "96x120",
                "-o",
                str(directory / name / "cal"),
            ],
            capture_output=True,
            text=True,
            env=_env(opencv_site),
        )
        lines = done.stderr.strip().splitlines()
        ok = done.returncode == 1 and len(lines) == 1 and str(path) in lines[0] and "Traceback" not in done.stderr
        problems[name] = "" if ok and not (directory / name / "cal").exists() else done.stderr[-300:]
    return problems


def _env(extra_path: str = "") -> dict[str, str]:
    paths = [p for p in (extra_path, str(REPO), os.environ.get("PYTHONPATH", "")) if p]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}


def test_import_opencv_errors_are_one_line(tmp_path) -> None:
    """Covered here: the installed OpenCV (5.0 from pip). The next test repeats this under each OpenCV
    install named in RIG_TEST_OPENCV_PATHS (checked with opencv-python-headless 4.10.0 and 4.14.0)."""
    problems = _check_broken_filestorage(tmp_path)
    assert not any(problems.values()), problems


OTHER_OPENCVS = [p for p in os.environ.get("RIG_TEST_OPENCV_PATHS", "").split(os.pathsep) if p]


@pytest.mark.skipif(
    not OTHER_OPENCVS,
    reason="set RIG_TEST_OPENCV_PATHS to directories holding other OpenCV "
    "installs (pip install --target DIR 'opencv-python-headless<5') to run under them too",
)
@pytest.mark.parametrize("site", OTHER_OPENCVS or ["none"])
def test_import_opencv_errors_are_one_line_under_other_opencv(tmp_path, site) -> None:
    version = subprocess.run(
        [sys.executable, "-c", "import cv2; print(cv2.__version__)"], capture_output=True, text=True, env=_env(site)
    ).stdout.strip()
    assert version, f"no OpenCV importable from {site}"
    problems = _check_broken_filestorage(tmp_path, site)
    assert not any(problems.values()), (version, problems)


# issue 21: --no-undistort with a camera-projector calibration, which undistorts rays itself ---------


def test_no_undistort_is_refused_with_a_stereo_calibration(capsys, tmp_path, small_capture) -> None:
    from calibration.store import Calibration, write_calibration
    from mock_devices.stereo_synth import calibration_fields, demo_rig

    fields = calibration_fields(demo_rig(160, 120))
    write_calibration(tmp_path / "stereo", Calibration(model="stereo", extra=fields))
    out = tmp_path / "out"
    code, err = run(
        capsys, "process", small_capture.capture, "--calibration", tmp_path / "stereo", "--no-undistort", "-o", out
    )
    assert_one_line(code, err, "--no-undistort", "camera-projector")
    assert not out.exists()
