"""`rig import`: the pattern spec, conversions and provenance, and the three real-data folders.

The real folders (``../shared/real-data``, see its README) are imported downsampled 2 x 2 to keep
the tests quick, processed without calibration, and their phase is checked against what the
README states (fringe counts, direction, smoothness). Skipped cleanly without ``../shared``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from realdata import REAL_DATA, needs_real_data

from rig.cli import main
from rig.errors import CaptureError, ConfigError
from rig.pipeline.run import process
from rig.store.importer import ImportOptions, import_folder, natural_key, parse_angle, parse_spec

# ------------------------------------------------------------------ the spec mini-language


def test_spec_expands_to_capture_patterns() -> None:
    patterns = parse_spec("sin:f=32,steps=12,phase=pi; gray:bits=6")
    assert len(patterns) == 18
    assert patterns[0] == {
        "kind": "sinusoid",
        "axis": "x",
        "frequency": 32,
        "steps": 12,
        "step": 0,
        "phase_rad": math.pi,
    }
    assert patterns[11]["step"] == 11
    assert patterns[12] == {"kind": "gray", "axis": "x", "bit": 0, "bits": 6, "inverted": False}
    multi = parse_spec("sin:f=64/58/53,steps=4")
    assert [p["frequency"] for p in multi] == [64] * 4 + [58] * 4 + [53] * 4
    shifted = parse_spec("sin:f=36,shifts=0/90/180/270deg")
    assert [p["shift_rad"] for p in shifted] == pytest.approx([0, math.pi / 2, math.pi, 3 * math.pi / 2])
    mixed = parse_spec("skip:2; white; black; gray:bits=2,inverted=interleaved,axis=y")
    assert mixed[:2] == [None, None] and mixed[2]["level"] == 1.0 and mixed[3]["level"] == 0.0
    assert [(p["bit"], p["inverted"], p["axis"]) for p in mixed[4:]] == [
        (0, False, "y"),
        (0, True, "y"),
        (1, False, "y"),
        (1, True, "y"),
    ]


@pytest.mark.parametrize(
    "text,value",
    [
        ("pi", math.pi),
        ("-pi", -math.pi),
        ("pi/2", math.pi / 2),
        ("2pi/3", 2 * math.pi / 3),
        ("90deg", math.pi / 2),
        ("-1.5", -1.5),
        (".5", 0.5),
    ],
)
def test_angles(text, value) -> None:
    assert parse_angle(text, "x") == pytest.approx(value)


@pytest.mark.parametrize(
    "spec,message",
    [
        ("", "empty spec"),
        ("sine:f=3,steps=4", "unknown kind 'sine'"),
        ("sin:steps=4", "expected f=FRINGES and steps=N"),
        ("sin:f=0,steps=4", "f: expected a positive number, found '0'"),
        ("sin:f=8,steps=4,phase=half", "phase: expected an angle"),
        ("sin:f=8,steps=3,shifts=0/1", "shifts: expected 3 values"),
        ("sin:f=8,steps=4,colour=red", "unknown key 'colour'"),
        ("gray:bits=4,inverted=sometimes", "inverted: expected none, after or interleaved"),
        ("flat:level=2", "level: expected a number in 0..1"),
    ],
)
def test_bad_specs_are_named(spec, message) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_spec(spec)


def test_natural_order() -> None:
    names = ["10.png", "2.png", "1.png", "lens_090.jpg", "lens_000.jpg", "0.png"]
    assert sorted(names, key=natural_key) == ["0.png", "1.png", "2.png", "10.png", "lens_000.jpg", "lens_090.jpg"]


# ------------------------------------------------------------------ conversions, provenance, errors


def _fringe_folder(tmp_path: Path, colour: bool = False, count: int = 4) -> Path:
    folder = tmp_path / "theirs"
    folder.mkdir()
    x = np.arange(64)
    for k in range(count):  # written as 0, 1, ... 10 so that name order differs from natural order
        row = 120 + 100 * np.cos(2 * np.pi * 4 * x / 64 + 2 * np.pi * k / count)
        image = np.rint(np.tile(row, (48, 1))).astype(np.uint8)
        if colour:
            image = np.dstack([image, image, image])
        cv2.imwrite(str(folder / f"{k * 10}.png"), image)
    return folder


def test_import_converts_colour_and_records_provenance(tmp_path) -> None:
    folder = _fringe_folder(tmp_path, colour=True)
    capture = import_folder(folder, "sin:f=4,steps=4", tmp_path / "cap", ImportOptions(projector_width=64))
    assert capture.manifest["import"]["files"] == ["0.png", "10.png", "20.png", "30.png"]
    assert "3-channel colour -> grey" in capture.manifest["import"]["conversions"][0]
    assert capture.frames[1]["source_file"] == "10.png" and len(capture.frames[1]["source_sha256"]) == 64
    assert capture.load_frames().shape == (4, 48, 64) and capture.projector_size == (64, 48)
    result = process(capture.path)
    truth = 2 * np.pi * 4 * (np.arange(64)) / 64
    phase = result.phase[24]
    ok = np.isfinite(phase)
    offset = np.round((phase[ok] - truth[ok]).mean() / (2 * np.pi)) * 2 * np.pi  # spatial: up to 2 pi k
    assert np.max(np.abs(phase[ok] - offset - truth[ok])) < 0.05


def test_shift_sign_negates_the_phase(tmp_path) -> None:
    folder = _fringe_folder(tmp_path)
    plus = process(import_folder(folder, "sin:f=4,steps=4", tmp_path / "a").path).object.wrapped.phase[0]
    minus = process(
        import_folder(folder, "sin:f=4,steps=4", tmp_path / "b", ImportOptions(shift_sign=-1)).path
    ).object.wrapped.phase[0]
    np.testing.assert_allclose(np.angle(np.exp(1j * (plus + minus))), 0.0, atol=1e-6)


def test_gray_planes_stored_least_significant_first(tmp_path) -> None:
    """Issue 21: ``gray:bits=N,order=lsb`` for a folder whose Gray planes run from the least
    significant; the capture's absolute phase is the projector's, read in the wrong order it is not."""
    from processing.patterns import pattern_image

    width, height = 128, 16
    patterns = parse_spec("sin:f=8,steps=4; gray:bits=3")
    sinusoids, planes = patterns[:4], patterns[4:]
    folder = tmp_path / "lsb-first"
    folder.mkdir()
    for i, pattern in enumerate(sinusoids + planes[::-1]):  # the planes stored least significant first
        image = 30 + 200 * pattern_image(pattern, (width, height))
        cv2.imwrite(str(folder / f"{i:02d}.png"), np.rint(image).astype(np.uint8))
    lsb = import_folder(folder, "sin:f=8,steps=4; gray:bits=3,order=lsb", tmp_path / "lsb")
    assert [p["bit"] for p in lsb.patterns[4:]] == [2, 1, 0]
    msb = import_folder(folder, "sin:f=8,steps=4; gray:bits=3", tmp_path / "msb")
    truth = 2 * np.pi * 8 * (np.arange(width) + 0.5) / width  # the phase at each pixel's centre
    errors = {}
    for name, capture in (("lsb", lsb), ("msb", msb)):
        phase = process(capture.path).phase[height // 2]
        ok = np.isfinite(phase)
        errors[name] = float(np.max(np.abs(phase[ok] - truth[ok]))) if ok.sum() > width // 2 else np.inf
    assert errors["lsb"] < 0.05 and errors["msb"] > 1.0, errors
    with pytest.raises(ConfigError, match="order: expected msb"):
        parse_spec("gray:bits=3,order=backwards")


def test_pattern_file_with_explicit_files(tmp_path) -> None:
    folder = _fringe_folder(tmp_path)
    spec = tmp_path / "spec.json"
    patterns = [{"kind": "sinusoid", "axis": "x", "frequency": 4, "steps": 3, "step": j} for j in range(3)]
    spec.write_text(json.dumps({"patterns": patterns, "files": ["30.png", "0.png", "10.png"]}))
    capture = import_folder(folder, f"@{spec}", tmp_path / "cap")
    assert capture.manifest["import"]["files"] == ["30.png", "0.png", "10.png"]


def test_file_count_mismatch_is_one_line_via_cli(tmp_path, capsys) -> None:
    folder = _fringe_folder(tmp_path)
    code = main(["import", str(folder), "--patterns", "sin:f=4,steps=6", "-o", str(tmp_path / "cap")])
    err = capsys.readouterr().err
    assert code == 1 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "the pattern spec describes 6 files (6 patterns), found 4 images (0.png .. 30.png)" in err
    assert not (tmp_path / "cap").exists()


def test_a_path_that_does_not_exist_is_named_so(tmp_path, capsys) -> None:
    missing = tmp_path / "no-such-folder"
    code = main(["import", str(missing), "--patterns", "sin:f=4,steps=4", "-o", str(tmp_path / "cap")])
    err = capsys.readouterr().err
    assert code == 1 and len(err.strip().splitlines()) == 1
    assert f"{missing}: does not exist" in err and "not a folder of images" not in err
    assert not (tmp_path / "cap").exists()


def test_a_parent_folder_points_at_the_subfolders_with_images(tmp_path, capsys) -> None:
    _fringe_folder(tmp_path)  # tmp_path/theirs/ holds the images, tmp_path itself none
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "readme.txt").write_text("no images here")
    code = main(["import", str(tmp_path), "--patterns", "sin:f=4,steps=4", "-o", str(tmp_path / "cap")])
    err = capsys.readouterr().err
    assert code == 1 and len(err.strip().splitlines()) == 1
    assert "found no images" in err and "subfolders hold images: theirs/ (4 images)" in err and "notes" not in err
    assert not (tmp_path / "cap").exists()


@needs_real_data
def test_the_eyes_parent_folder_points_at_l(tmp_path, capsys) -> None:
    code = main(
        [
            "import",
            str(REAL_DATA / "slmaster-eye"),
            "--patterns",
            "sin:f=32,steps=12,phase=pi; gray:bits=6",
            "-o",
            str(tmp_path / "eye"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 1 and "subfolders hold images: L/ (18 images)" in err


def test_images_of_different_sizes_are_refused(tmp_path) -> None:
    folder = _fringe_folder(tmp_path)
    cv2.imwrite(str(folder / "20.png"), np.zeros((40, 64), np.uint8))
    with pytest.raises(CaptureError, match=r"20.png: expected 64x48 uint8 like 0.png, found 64x40 uint8"):
        import_folder(folder, "sin:f=4,steps=4", tmp_path / "cap")


def test_import_refuses_to_overwrite(tmp_path) -> None:
    folder = _fringe_folder(tmp_path)
    import_folder(folder, "sin:f=4,steps=4", tmp_path / "cap")
    with pytest.raises(CaptureError, match="already exists"):
        import_folder(folder, "sin:f=4,steps=4", tmp_path / "cap")


# ------------------------------------------------------------------ real data


def _import(tmp_path, capsys, folder: Path, spec: str, *options: str) -> Path:
    out = tmp_path / folder.name
    code = main(["import", str(folder), "--patterns", spec, "-o", str(out), "--downsample", "2", *options])
    assert code == 0, capsys.readouterr().err
    return out


def _row_steps(phase: np.ndarray) -> np.ndarray:
    d = np.diff(phase, axis=1)
    return d[np.isfinite(d)]


@needs_real_data
def test_slmaster_eye_gray_code_gives_monotonic_absolute_phase(tmp_path, capsys) -> None:
    capture = _import(
        tmp_path,
        capsys,
        REAL_DATA / "slmaster-eye" / "L",
        "sin:f=32,steps=12,phase=pi; gray:bits=6",
        "--projector-width",
        "1920",
        "--projector-height",
        "1024",
    )
    result = process(capture)
    assert result.object.unwrapped.method == "gray"  # 6 planes for 32 periods: complementary Gray code
    assert result.mask.sum() > 10000  # the plaque
    steps = _row_steps(result.phase)
    assert np.mean(steps > 0) > 0.99  # phase grows with the projector column along image x
    assert np.mean(np.abs(steps) > np.pi) < 1e-3  # no fringe-order slips
    valid = result.phase[np.isfinite(result.phase)]
    assert 0 <= valid.min() and valid.max() < 2 * np.pi * 32  # absolute: within the projector's 32 periods
    vertical = np.diff(result.phase, axis=0)
    assert np.mean(np.abs(vertical[np.isfinite(vertical)]) > np.pi) < 1e-3
    periods = np.nanpercentile(result.phase, [1, 99]) / (2 * np.pi)
    assert periods[1] - periods[0] > 8  # the plaque spans ~11 of the 32 periods (40 px each at full size)


@needs_real_data
def test_slmaster_david_heterodyne_is_smooth_and_monotonic(tmp_path, capsys) -> None:
    capture = _import(
        tmp_path,
        capsys,
        REAL_DATA / "slmaster-david-heterodyne",
        "sin:f=64/58/53,steps=4,phase=pi",
        "--projector-width",
        "1920",
    )
    result = process(capture)
    assert result.object.unwrapped.method == "heterodyne"
    lit = result.object.wrapped.valid
    assert result.mask.sum() > 0.85 * lit.sum()  # beat residuals reject few of the well-modulated pixels
    steps = _row_steps(result.phase)
    assert np.mean(steps > 0) > 0.99
    assert np.mean(np.abs(steps) > np.pi) < 5e-3
    vertical = np.diff(result.phase, axis=0)
    assert np.mean(np.abs(vertical[np.isfinite(vertical)]) > np.pi) < 5e-3


@needs_real_data
def test_fpp_tools_lens_fringe_count_and_smooth_spatial_unwrap(tmp_path, capsys) -> None:
    folder = REAL_DATA / "fpp-tools-lens"
    spec = "sin:f=36,shifts=0/90/180/270deg"
    capture = _import(tmp_path, capsys, folder, spec, "--glob", "lens_crop_*.jpg")
    result = process(capture)
    assert result.object.unwrapped.method == "spatial"
    wrapped = result.object.wrapped.phase[0]
    board = wrapped[:35]  # the rows above the lens: only the flat board, fringes widening to the right
    wraps = [np.nonzero(np.abs(np.diff(row)) > np.pi)[0] for row in board]
    assert 28 <= np.median([len(w) for w in wraps]) <= 32
    left_period_px = 2 * np.median([np.median(np.diff(w[:6])) for w in wraps])  # full-size pixels
    assert 16 <= left_period_px <= 20  # README: "period about 18-19 camera px in the crop"
    steps = _row_steps(result.phase)
    assert np.mean(np.abs(steps) > np.pi) < 1e-3  # quality-guided unwrap is smooth
    assert np.mean(steps < 0) > 0.99  # with the shifts as named, phase decreases along x ...
    flipped = process(
        _import(tmp_path / "flip", capsys, folder, spec, "--glob", "lens_crop_*.jpg", "--shift-sign", "-1")
    )
    assert np.mean(_row_steps(flipped.phase) > 0) > 0.99  # ... and --shift-sign -1 turns it round
