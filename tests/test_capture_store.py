"""Capture store: round trip, atomic writes, and one clear error for each kind of bad capture."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from rig.errors import CaptureError
from rig.store.capture import CaptureWriter, check_same_patterns, read_capture, write_capture

PROJECTOR = {"width": 64, "height": 32}


def _patterns(steps: int = 3) -> list[dict]:
    return [{"kind": "sinusoid", "axis": "x", "frequency": 2, "steps": steps, "step": j} for j in range(steps)]


def _frames(n: int, dtype=np.uint8, shape=(24, 32), seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if dtype == np.float32:
        return rng.random((n, *shape), dtype=np.float32)
    top = np.iinfo(dtype).max
    return rng.integers(0, top, size=(n, *shape), endpoint=True).astype(dtype)


def _manifest(path: Path) -> dict:
    return json.loads((path / "capture.json").read_text())


def _rewrite(path: Path, manifest: dict) -> None:
    (path / "capture.json").write_text(json.dumps(manifest))


@pytest.fixture
def capture_dir(tmp_path: Path) -> Path:
    path = tmp_path / "cap"
    write_capture(path, _frames(3), _patterns(), PROJECTOR, extra={"operator": "ana", "notes": {"lens": "16 mm"}})
    return path


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_round_trip_is_lossless_for_every_bit_depth(tmp_path: Path, dtype) -> None:
    frames = _frames(3, dtype)
    capture = write_capture(tmp_path / "c", frames, _patterns(), PROJECTOR)
    loaded = capture.load_frames()
    assert loaded.dtype == frames.dtype and loaded.shape == frames.shape
    np.testing.assert_array_equal(loaded, frames)
    assert capture.complete and capture.bit_depth == {np.uint8: 8, np.uint16: 16, np.float32: 32}[dtype]


def test_manifest_follows_the_format(capture_dir: Path) -> None:
    manifest = _manifest(capture_dir)
    assert manifest["format"] == "fpp-capture" and manifest["version"] == 1 and manifest["complete"] is True
    assert [f["pattern"] for f in manifest["frames"]] == [0, 1, 2]
    assert all(len(f["sha256"]) == 64 and not Path(f["file"]).is_absolute() for f in manifest["frames"])
    assert manifest["created_utc"].endswith("Z")


def test_extra_keys_survive_a_rewrite(capture_dir: Path) -> None:
    capture = read_capture(capture_dir)
    capture.manifest["scene"] = "plane-at-25mm"
    capture.write_manifest()
    manifest = _manifest(capture_dir)
    assert manifest["operator"] == "ana" and manifest["notes"] == {"lens": "16 mm"}
    assert read_capture(capture_dir).scene == "plane-at-25mm"


def test_exception_inside_the_writer_leaves_only_an_incomplete_capture(tmp_path: Path) -> None:
    final = tmp_path / "scan"
    with pytest.raises(RuntimeError, match="camera unplugged"):
        with CaptureWriter(final, {"width": 32, "height": 24, "bit_depth": 8}, PROJECTOR, _patterns()) as writer:
            writer.add_frame(0, _frames(1)[0])
            raise RuntimeError("camera unplugged")
    assert not final.exists()
    (partial,) = tmp_path.glob("scan.incomplete-*")
    manifest = _manifest(partial)
    assert manifest["complete"] is False and "camera unplugged" in manifest["interrupted"]
    with pytest.raises(CaptureError, match="complete: expected true, found false"):
        read_capture(partial)
    salvaged = read_capture(partial, salvage=True)
    assert salvaged.load_frame(0).shape == (24, 32) and len(salvaged.frames) == 1


def test_keyboard_interrupt_also_leaves_it_incomplete(tmp_path: Path) -> None:
    with pytest.raises(KeyboardInterrupt):
        with CaptureWriter(tmp_path / "scan", {"width": 32, "height": 24, "bit_depth": 8}, PROJECTOR, _patterns()):
            raise KeyboardInterrupt
    assert not (tmp_path / "scan").exists()
    (partial,) = tmp_path.glob("scan.incomplete-*")
    assert _manifest(partial)["complete"] is False


def test_writer_refuses_to_finish_with_missing_frames(tmp_path: Path) -> None:
    with pytest.raises(CaptureError, match="2 of 3 patterns have no frame"):
        with CaptureWriter(tmp_path / "scan", {"width": 32, "height": 24, "bit_depth": 8}, PROJECTOR, _patterns()) as w:
            w.add_frame(1, _frames(1)[0])
    assert not (tmp_path / "scan").exists()


def test_existing_capture_is_never_overwritten_silently(capture_dir: Path) -> None:
    before = _manifest(capture_dir)
    with pytest.raises(CaptureError, match="already exists"):
        write_capture(capture_dir, _frames(3, seed=5), _patterns(), PROJECTOR)
    assert _manifest(capture_dir) == before
    write_capture(capture_dir, _frames(3, seed=5), _patterns(), PROJECTOR, overwrite=True)
    np.testing.assert_array_equal(read_capture(capture_dir).load_frames(), _frames(3, seed=5))
    assert not list(capture_dir.parent.glob("*.incomplete-*")) and not list(capture_dir.parent.glob("*.replaced-*"))


# ------------------------------------------------------------------ bad captures, one clear line each


def _edit(field_path: tuple, value):
    def edit(manifest: dict) -> None:
        target = manifest
        for key in field_path[:-1]:
            target = target[key]
        target[field_path[-1]] = value

    return edit


BAD_MANIFESTS = [
    (
        "unknown format",
        _edit(("format",), "fringe-archive"),
        r"capture.json: format: expected 'fpp-capture', found 'fringe-archive'",
    ),
    ("unknown version", _edit(("version",), 2), r"version: expected 1 .*found 2"),
    ("missing frame", lambda m: m["frames"].pop(), r"no frame for pattern\(s\) 2"),
    (
        "extra frame",
        lambda m: m["frames"].append(dict(m["frames"][0], file="frames/x.png")),
        r"extra frame for pattern 0",
    ),
    ("frame of no pattern", _edit(("frames", 1, "pattern"), 7), r"frames\[1\].pattern: expected an index 0 .. 2"),
    ("absolute path", _edit(("frames", 0, "file"), "/etc/passwd"), r"frames\[0\].file: expected a path relative"),
    ("escaping path", _edit(("frames", 0, "file"), "../elsewhere/000.png"), r"frames\[0\].file: .*no '\.\.'"),
    ("bad step", _edit(("patterns", 1, "step"), 3), r"patterns\[1\].step: expected 0 .. 2"),
    ("unknown kind", _edit(("patterns", 0, "kind"), "checkerboard"), r"patterns\[0\].kind: expected one of"),
    ("bad bit depth", _edit(("camera", "bit_depth"), 24), r"camera.bit_depth: expected 1..16 or 32, found 24"),
    ("incomplete", _edit(("complete",), False), r"complete: expected true, found false"),
]


@pytest.mark.parametrize("name,edit,message", BAD_MANIFESTS, ids=[b[0] for b in BAD_MANIFESTS])
def test_bad_manifest_is_refused_with_one_line(capture_dir: Path, name, edit, message) -> None:
    manifest = _manifest(capture_dir)
    edit(manifest)
    _rewrite(capture_dir, manifest)
    with pytest.raises(CaptureError, match=message) as info:
        read_capture(capture_dir)
    assert "\n" not in str(info.value)


def test_missing_manifest_names_the_file(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(CaptureError, match=r"empty/capture.json: missing"):
        read_capture(tmp_path / "empty")


def test_invalid_json_names_line_and_column(capture_dir: Path) -> None:
    (capture_dir / "capture.json").write_text('{"format": "fpp-capture",\n "version": }')
    with pytest.raises(CaptureError, match=r"not valid JSON: .* line 2"):
        read_capture(capture_dir)


def test_checksum_mismatch_names_the_file(capture_dir: Path) -> None:
    frame = capture_dir / _manifest(capture_dir)["frames"][1]["file"]
    cv2.imwrite(str(frame), np.zeros((24, 32), np.uint8))
    with pytest.raises(
        CaptureError, match=rf"{frame.name}: checksum mismatch: expected sha256 [0-9a-f]{{64}}, found [0-9a-f]{{64}}"
    ):
        read_capture(capture_dir)


def test_missing_frame_file_names_it(capture_dir: Path) -> None:
    frame = capture_dir / _manifest(capture_dir)["frames"][2]["file"]
    frame.unlink()
    with pytest.raises(CaptureError, match=rf"{frame.name}: frame file missing \(pattern 2\)"):
        read_capture(capture_dir)


def _replace_frame(capture_dir: Path, index: int, data: bytes) -> Path:
    """Put other bytes in a frame file and update its checksum, so the later checks are reached."""
    import hashlib

    manifest = _manifest(capture_dir)
    frame = capture_dir / manifest["frames"][index]["file"]
    frame.write_bytes(data)
    manifest["frames"][index]["sha256"] = hashlib.sha256(data).hexdigest()
    _rewrite(capture_dir, manifest)
    return frame


@pytest.mark.parametrize(
    "image,message",
    [
        (np.zeros((20, 32), np.uint8), r"image size: expected 32x24 .*found 32x20"),
        (np.zeros((24, 32), np.uint16), r"bit depth: expected uint8 for camera.bit_depth 8, found uint16"),
        (np.zeros((24, 32, 3), np.uint8), r"expected a single-channel image, found 3 channels"),
    ],
    ids=["size", "bit depth", "colour"],
)
def test_wrong_image_is_refused_when_loaded(capture_dir: Path, image: np.ndarray, message: str) -> None:
    frame = _replace_frame(capture_dir, 0, cv2.imencode(".png", image)[1].tobytes())
    capture = read_capture(capture_dir)
    with pytest.raises(CaptureError, match=rf"{frame.name}: {message}"):
        capture.load_frames()


def test_corrupt_image_is_refused(capture_dir: Path) -> None:
    frame = _replace_frame(capture_dir, 0, b"\x89PNG\r\n\x1a\n truncated")
    with pytest.raises(CaptureError, match=rf"{frame.name}: corrupt or unreadable image"):
        read_capture(capture_dir).load_frames()


def test_reference_with_other_patterns_is_refused(tmp_path: Path) -> None:
    obj = write_capture(tmp_path / "obj", _frames(3), _patterns(3), PROJECTOR)
    ref = write_capture(tmp_path / "ref", _frames(4), _patterns(4), PROJECTOR, scene="reference")
    with pytest.raises(CaptureError, match=r"ref/capture.json: patterns: expected the 3 patterns .* found 4"):
        check_same_patterns(ref, obj)
    shifted = [dict(p, frequency=3) for p in _patterns(3)]
    ref2 = write_capture(tmp_path / "ref2", _frames(3), shifted, PROJECTOR, scene="reference")
    with pytest.raises(CaptureError, match=r"patterns\[0\]: expected .*'frequency': 2.* found .*'frequency': 3"):
        check_same_patterns(ref2, obj)


def test_windows_style_absolute_path_is_refused(capture_dir: Path) -> None:
    manifest = _manifest(capture_dir)
    manifest["frames"][0]["file"] = "C:\\frames\\000.png"
    _rewrite(capture_dir, manifest)
    with pytest.raises(CaptureError, match="expected a path relative"):
        read_capture(capture_dir)


def test_frame_linking_outside_the_capture_is_refused(capture_dir: Path, tmp_path: Path) -> None:
    outside = tmp_path / "elsewhere.png"
    frame = capture_dir / _manifest(capture_dir)["frames"][0]["file"]
    outside.write_bytes(frame.read_bytes())
    frame.unlink()
    frame.symlink_to(outside)
    with pytest.raises(CaptureError, match=r"frames/000.png' leads outside .* through a link"):
        read_capture(capture_dir)
