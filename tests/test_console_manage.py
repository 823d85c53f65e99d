"""Managing the data directory from the console (issue 24): delete to DATA/trash and restore
(undo), rename, and import an OpenCV FileStorage calibration; every change is a ``data`` message
to every page, and every refusal one line."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from console_client import WS, wait_job, wait_saved
from fastapi.testclient import TestClient

from rig.console.datadir import DataDir
from rig.console.trash import Trash, TrashError

HEADERS = {"X-Console-Client": "test"}


def _scan(console: TestClient, name: str) -> None:
    job = console.post("/api/scan", json={"name": name, "options": {"correction": "none"}}).json()["job"]
    assert wait_job(console, job["id"])["state"] == "done"
    wait_saved(console, name)


def test_a_deleted_result_goes_to_the_trash_and_comes_back_unchanged(console: TestClient) -> None:
    _scan(console, "part")
    root = console.app.state.session.data.root
    before = console.get("/api/results/part/values.f32").content
    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()  # hello
        reply = console.delete("/api/results/part", headers=HEADERS)
        assert reply.status_code == 200
        while (message := json.loads(socket.receive_text()))["type"] != "data":
            pass
    entry = reply.json()
    assert message == entry and entry["change"] == "deleted" and entry["name"] == "part"
    assert (root / "trash" / "results" / entry["entry"] / "report.json").is_file()
    assert console.get("/api/results/part").status_code == 404  # not served from memory either
    assert [e["entry"] for e in console.get("/api/trash").json()["entries"]] == [entry["entry"]]
    restored = console.post("/api/trash/restore", json={"kind": "results", "entry": entry["entry"]})
    assert restored.status_code == 200 and restored.json()["name"] == "part"
    assert console.get("/api/results/part/values.f32").content == before
    assert console.get("/api/trash").json()["entries"] == []


def test_rename_and_restore_refuse_a_taken_name(console: TestClient) -> None:
    _scan(console, "a")
    _scan(console, "b")
    assert console.post("/api/captures/a/rename", json={"to": "b"}).status_code == 409
    bad = console.post("/api/captures/a/rename", json={"to": "../x"})
    assert bad.status_code == 400 and "plain name" in bad.json()["error"]
    renamed = console.post("/api/captures/a/rename", json={"to": "a2"}).json()
    assert renamed["name"] == "a2" and renamed["results_naming_old"] == ["a"]
    assert [c["name"] for c in console.get("/api/captures").json()["captures"]] == ["b", "a2"]
    entry = console.delete("/api/results/a", headers=HEADERS).json()["entry"]
    assert console.post("/api/results/b/rename", json={"to": "a"}).status_code == 200
    taken = console.post("/api/trash/restore", json={"kind": "results", "entry": entry})
    assert taken.status_code == 409 and "taken again" in taken.json()["error"]
    assert console.delete("/api/verifications/x", headers=HEADERS).status_code == 400
    assert console.delete("/api/captures/nothing", headers=HEADERS).status_code == 404
    assert console.delete("/api/captures/b").status_code == 403  # no page header: not from the console's page
    assert "b" in [c["name"] for c in console.get("/api/captures").json()["captures"]]


def test_deleting_the_active_calibration_leaves_phase_only(
    console: TestClient, console_rig_toml: Path, exact_calibration: Callable[[Path, Path], Path]
) -> None:
    data = console.app.state.session.data
    exact_calibration(console_rig_toml, data.root / "calibrations" / "cal")
    assert console.put("/api/calibration", json={"name": "cal"}).json() == {"active": "cal"}
    assert console.post("/api/calibrations/cal/rename", json={"to": "cal2"}).status_code == 200
    assert console.get("/api/calibrations").json() == {"calibrations": ["cal2"], "active": "cal2"}
    console.delete("/api/calibrations/cal2", headers=HEADERS)
    assert console.get("/api/calibrations").json() == {"calibrations": [], "active": None}


def test_an_entry_being_written_is_not_moved(tmp_path: Path) -> None:
    data = DataDir(tmp_path)
    (tmp_path / "captures" / "c1").mkdir()
    (tmp_path / "captures" / "c1" / "capture.json").write_text("{}")
    (tmp_path / "captures" / "c1.incomplete-abcd").mkdir()  # a write of the same name under way
    with pytest.raises(TrashError, match="in use by a running job"):
        Trash(data).delete("captures", "c1")
    assert (tmp_path / "captures" / "c1" / "capture.json").is_file()


def _storage_text(tmp_path: Path, camera: tuple[int, int], projector: tuple[int, int]) -> tuple[str, dict]:
    from mock_devices.stereo_synth import calibration_fields, demo_rig

    truth = calibration_fields(demo_rig(*camera, *projector))
    path = tmp_path / "caliInfo.yml"
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    keys = ("camera_matrix", "distortion", "projector_matrix", "projector_distortion", "rotation", "translation_mm")
    for node, key in zip(("K1", "D1", "K2", "D2", "R", "T"), keys):
        storage.write(node, np.asarray(truth[key], dtype=np.float64))
    storage.release()
    return path.read_text(), truth


def test_an_opencv_calibration_is_imported_from_the_page(console: TestClient, tmp_path: Path) -> None:
    from console_client import HEIGHT, WIDTH

    text, truth = _storage_text(tmp_path, (WIDTH, HEIGHT), (456, 570))
    reply = console.post("/api/calibrations/import", json={"name": "slm", "file_name": "caliInfo.yml", "text": text})
    assert reply.status_code == 200, reply.text
    stored = json.loads((console.app.state.session.data.root / "calibrations" / "slm" / "calibration.json").read_text())
    assert stored["model"] == "stereo" and stored["projector_size"] == [456, 570]
    assert np.allclose(stored["camera_matrix"], truth["camera_matrix"], atol=1e-12)
    assert "slm" in console.get("/api/calibrations").json()["calibrations"]
    again = console.post("/api/calibrations/import", json={"name": "slm", "text": text})
    assert again.status_code == 409
    broken = console.post(
        "/api/calibrations/import", json={"name": "x", "file_name": "mine.yml", "text": "%YAML:1.0\nK1: 1\n"}
    )
    assert broken.status_code == 400 and broken.json()["error"].startswith("mine.yml: ")
    assert not (console.app.state.session.data.root / "calibrations" / "x").exists()  # nothing half-written
    wrong = console.post("/api/calibrations/import", json={"name": "y", "file_name": "a.txt", "text": text})
    assert wrong.status_code == 400 and "FileStorage" in wrong.json()["error"]


def test_a_captures_frames_wrapped_phase_and_modulation_are_shown(console: TestClient) -> None:
    """The wrapped phase of the finest group agrees with the processed result's phase, wrapped (two
    code paths: the capture view's and the pipeline's); the frames are the capture's own."""
    from console_client import HEIGHT, WIDTH

    from rig.api import load_capture
    from rig.store.results import read_result

    _scan(console, "look")
    data = console.app.state.session.data
    listing = console.get("/api/captures/look/frames").json()
    capture = load_capture(data.path("captures", "look"))
    assert len(listing["frames"]) == len(capture.patterns) and all(f["held"] for f in listing["frames"])
    assert [g["frequency"] for g in listing["groups"]] == [1, 8, 32]
    png = console.get("/api/captures/look/frames/3.png").content
    shown = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    assert shown.shape == (HEIGHT, WIDTH) and np.array_equal(shown, capture.load_frame(3))  # 8-bit camera
    from rig.capture_views import wrapped_phase

    wrapped, modulation = wrapped_phase(capture, 2)
    absolute = read_result(data.path("results", "look")).values  # phase (rad) of the finest frequency
    both = np.isfinite(absolute)
    gap = np.angle(np.exp(1j * (absolute[both] - wrapped[both])))
    assert np.mean(np.abs(gap) < 0.05) > 0.95
    assert np.median(modulation[both]) > 10  # grey levels: the fringes are well lit
    for what in ("phase", "modulation"):
        reply = console.get(f"/api/captures/look/groups/2/{what}.png")
        assert reply.status_code == 200 and reply.content[:4] == b"\x89PNG"
    assert console.get("/api/captures/look/groups/3/phase.png").status_code == 400
    assert console.get("/api/captures/look/groups/0/colour.png").status_code == 400
    assert console.get("/api/captures/look/frames/999.png").status_code == 400
