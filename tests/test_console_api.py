"""The console's JSON API through the ASGI test client, on the simulated rig (issue 13).

Status and devices, a scan to a result, the busy refusal of a second acquisition, Stop, live
frames and exposure, containment of every name in the data directory, the access token and the
same-origin rule, readable errors, and recovery after an injected device fault; the Verify view's
routes (issue 23) and result downloads from the result store (issue 19).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from console_client import BASE, HEIGHT, WIDTH, WS, wait_job, wait_saved
from fastapi.testclient import TestClient

from rig.config import load_config
from rig.console.app import create_app


def live_frames(socket: Any, count: int) -> list[dict[str, Any]]:
    """The headers of the next ``count`` live frames (text messages in between are skipped)."""
    headers = []
    while len(headers) < count:
        message = socket.receive()
        if message.get("bytes"):
            data = message["bytes"]
            size = int.from_bytes(data[:4], "little")
            headers.append(json.loads(data[4 : 4 + size]))
    return headers


def scan_into_fault(client: TestClient, socket: Any, fault: str, name: str) -> tuple[dict[str, Any], str]:
    """Inject ``fault`` into the simulated rig, start an unprocessed scan ``name``: its job and the
    message of the first error event on ``socket``."""
    assert client.post("/api/simulation/fault", json={"fault": fault}).status_code == 200
    job = client.post("/api/scan", json={"name": name, "process": False}).json()["job"]
    while True:
        message = socket.receive()
        if message.get("text"):
            data = json.loads(message["text"])
            if data["type"] == "error":
                return job, data["message"]


def calibration_messages(socket: Any) -> tuple[list[str], dict[str, Any]]:
    """The step notes of a calibration job on ``socket`` up to its result message, and that result;
    an error message fails the test."""
    steps: list[str] = []
    while True:
        message = socket.receive()
        if message.get("text"):
            data = json.loads(message["text"])
            if data["type"] == "progress" and data["event"]["kind"] == "message":
                steps.append(data["event"]["note"])
            elif data["type"] == "calibration":
                return steps, data
            elif data["type"] == "error":
                raise AssertionError(data["message"])


def test_status_devices_and_openapi(console: TestClient) -> None:
    status = console.get("/api/status").json()
    assert status["state"] == "idle" and not status["busy"] and status["simulated"]
    devices = {d["role"]: d for d in console.get("/api/devices").json()["devices"]}
    assert devices["camera"]["backend"] == "simulated" and devices["camera"]["state"] == "open"
    assert devices["projector"]["backend"] == "gl-offscreen" and devices["trigger"]["backend"] == "simulated-serial"
    paths = console.get("/api/openapi.json").json()["paths"]
    for path in (
        "/api/status",
        "/api/devices",
        "/api/exposure",
        "/api/projector",
        "/api/scan",
        "/api/process",
        "/api/captures",
        "/api/results",
        "/api/calibrations",
    ):
        assert path in paths


def test_scan_gives_a_result_and_a_second_scan_is_refused_as_busy(console: TestClient) -> None:
    first = console.post("/api/scan", json={"name": "part-001", "options": {"correction": "none"}})
    assert first.status_code == 202
    second = console.post("/api/scan", json={"name": "part-002"})
    assert second.status_code == 409
    assert "busy" in second.json()["error"] and "one acquisition at a time" in second.json()["error"]
    job = wait_job(console, first.json()["job"]["id"])
    assert job["state"] == "done", job
    assert [c["name"] for c in console.get("/api/captures").json()["captures"]] == ["part-001"]
    assert not (console.app.state.session.data.root / "captures" / "part-002").exists()
    summary = wait_saved(console, "part-001")
    assert summary["shows"] == "phase" and summary["unit"] == "rad"  # no calibration in the data directory
    assert summary["valid_fraction"] > 0.9
    values = console.get("/api/results/part-001/values.f32")
    assert values.headers["X-Width"] == str(WIDTH) and len(values.content) == WIDTH * HEIGHT * 4
    assert console.get("/api/results/part-001/map.png").content[:8] == b"\x89PNG\r\n\x1a\n"
    surface = console.get("/api/results/part-001/surface").json()
    assert len(surface["z"]) == HEIGHT // surface["step"] or len(surface["z"]) == -(-HEIGHT // surface["step"])
    assert console.get("/api/results/part-001/files/phase.npy").status_code == 200
    assert console.get("/api/results/part-001/files/points.ply").status_code == 404  # phase only: no cloud
    # the 3-D view's points: every valid pixel, coloured as the map, the phase as a relief (not edge-on)
    cloud = console.get("/api/results/part-001/cloud.bin")
    count = int(cloud.headers["X-Points"])
    assert cloud.headers["X-Axis-Unit"] == "px" and cloud.headers["X-Step"] == "1"
    xyz = np.frombuffer(cloud.content[: count * 12], dtype="<f4").reshape(-1, 3)
    rgba = np.frombuffer(cloud.content[count * 12 :], dtype=np.uint8).reshape(-1, 4)
    phase = np.frombuffer(values.content, dtype="<f4").reshape(HEIGHT, WIDTH)
    assert count == np.isfinite(phase).sum()
    assert np.ptp(xyz[:, 2]) == pytest.approx(0.25 * WIDTH, rel=1e-3)
    bgr = cv2.imdecode(np.frombuffer(console.get("/api/results/part-001/map.png").content, np.uint8), cv2.IMREAD_COLOR)
    cols, rows = xyz[:, 0].astype(int), xyz[:, 1].astype(int)
    np.testing.assert_array_equal(rgba[:, :3], bgr[rows, cols, ::-1])
    assert [float(v) for v in cloud.headers["X-Range"].split(",")] == pytest.approx(
        [np.nanmin(phase), np.nanmax(phase)]
    )


def test_scan_with_a_calibration_gives_heights(
    tmp_path: Path, console_rig_toml: Path, exact_calibration: Callable[[Path, Path], Path]
) -> None:
    data = tmp_path / "data"
    exact_calibration(console_rig_toml, data / "calibrations" / "cal")
    with TestClient(create_app(load_config(console_rig_toml), data), base_url=BASE) as client:
        assert client.get("/api/calibrations").json() == {"calibrations": ["cal"], "active": "cal"}
        job = client.post("/api/scan", json={"name": "part", "options": {"correction": "none"}}).json()["job"]
        assert wait_job(client, job["id"])["state"] == "done"
        summary = wait_saved(client, "part")
        heights = np.frombuffer(client.get("/api/results/part/values.f32").content, dtype="<f4").reshape(HEIGHT, WIDTH)
    from rig.hardware.simulated import geometry_from_config, scene_height

    config = load_config(console_rig_toml)
    truth = scene_height(config, "object", geometry_from_config(config))
    valid = np.isfinite(heights)
    assert summary["shows"] == "height" and valid.mean() > 0.9
    assert np.median(np.abs(heights[valid] - truth[valid])) < 0.5  # mm; the hemisphere is ~80 mm high
    assert (data / "results" / "part" / "points.ply").is_file()
    # processed from the frames held in memory: the same heights and report as the stored capture gives
    from rig import api
    from rig.pipeline.plan import ProcessOptions

    stored = api.process(data / "captures" / "part", data / "calibrations" / "cal", ProcessOptions(correction="none"))
    np.testing.assert_array_equal(heights, stored.height)
    report = json.loads((data / "results" / "part" / "report.json").read_text())
    assert report["capture"] == stored.report["capture"] == str(data / "captures" / "part")


def test_live_3d_sends_point_clouds_at_the_objects_height(
    tmp_path: Path, console_rig_toml: Path, exact_calibration: Callable[[Path, Path], Path]
) -> None:
    """Live 3-D (issue 24): short sets processed as they come, each a cloud whose heights are the
    simulated object's, with its rate and latency; switched off, live camera frames come back."""
    from rig.hardware.simulated import geometry_from_config, scene_height

    data = tmp_path / "data"
    exact_calibration(console_rig_toml, data / "calibrations" / "cal")
    config = load_config(console_rig_toml)
    truth = scene_height(config, "object", geometry_from_config(config))
    with TestClient(create_app(config, data), base_url=BASE) as client:
        with client.websocket_connect(WS + "/api/events") as socket:
            socket.receive_text()  # hello
            socket.send_text(json.dumps({"live": True}))
            assert client.put("/api/live3d", json={"on": True}).json()["on"] is True
            clouds = []
            while len(clouds) < 3:
                message = socket.receive()
                if message.get("bytes"):
                    raw = message["bytes"]
                    size = int.from_bytes(raw[:4], "little")
                    header = json.loads(raw[4 : 4 + size])
                    if header["type"] == "live3d":
                        clouds.append((header, raw[4 + size :]))
            assert client.get("/api/status").json()["live_3d"]["sets"] >= 3
            assert client.put("/api/live3d", json={"on": False}).json()["on"] is False
            while True:  # the camera view again
                message = socket.receive()
                raw = message.get("bytes") or b"\0\0\0\0{}"
                size = int.from_bytes(raw[:4], "little")
                if json.loads(raw[4 : 4 + size] or b"{}").get("type") == "frame":
                    break
    header, body = clouds[-1]
    assert header["patterns"] == 8 and header["unit"] == "mm" and header["axis_unit"] == "mm"
    assert header["rate_hz"] > 0 and header["latency_ms"] > 0
    xyz = np.frombuffer(body[: header["points"] * 12], dtype="<f4").reshape(-1, 3)
    assert len(body) == header["points"] * 16
    heights = np.sort(xyz[:, 2])
    top = truth[np.isfinite(truth)].max()
    assert abs(heights[-len(heights) // 200] - top) < 3.0, (heights[-len(heights) // 200], top)  # mm, near the top
    assert abs(np.median(heights) - np.median(truth[np.isfinite(truth)])) < 3.0


def test_stop_cancels_the_scan_and_leaves_no_complete_capture(console: TestClient) -> None:
    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()  # hello
        job = console.post("/api/scan", json={"name": "stopped"}).json()["job"]
        while True:
            message = socket.receive()
            if message.get("text") and json.loads(message["text"]).get("type") == "progress":
                break
        assert console.post("/api/stop", json={}).json()["stopped"] == [job["id"]]
        busy_before_the_end = None
        while True:  # a page that hears the job ended may scan again at once: the rig is free before
            data = json.loads(socket.receive_text())
            if data["type"] == "status":
                busy_before_the_end = data["status"]["busy"]
            elif data["type"] == "job" and data["job"]["id"] == job["id"] and data["job"]["state"] != "running":
                break
        assert busy_before_the_end is False
    finished = wait_job(console, job["id"])
    assert finished["state"] == "cancelled" and "stopped" in finished["error"]
    root = console.app.state.session.data.root / "captures"
    assert not (root / "stopped").exists()
    leftovers = list(root.glob("stopped.incomplete*"))
    assert leftovers and json.loads((leftovers[0] / "capture.json").read_text())["complete"] is False
    listed = console.get("/api/captures").json()["captures"]
    assert [c["complete"] for c in listed] == [False] and listed[0]["name"].startswith("stopped.incomplete")
    # the rig is free again
    again = console.post("/api/scan", json={"name": "after-stop", "process": False}).json()["job"]
    assert wait_job(console, again["id"])["state"] == "done"


def test_live_frames_follow_the_exposure(console: TestClient) -> None:
    assert console.put("/api/projector", json={"pattern": "white"}).status_code == 200
    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()
        socket.send_text(json.dumps({"live": True}))
        bright = live_frames(socket, 3)[-1]
        assert console.put("/api/exposure", json={"exposure_us": 2500}).json()["exposure_us"] == 2500
        dark = live_frames(socket, 3)[-1]
        assert dark["exposure_us"] == 2500
        assert dark["mean"] < 0.5 * bright["mean"]
        assert len(bright["histogram"]) == 256 and bright["focus"] > 0
        console.put("/api/projector", json={"pattern": "fringe", "frequency": 16})
        fringe = live_frames(socket, 3)[-1]
        assert fringe["valid_fraction"] is not None and fringe["valid_fraction"] > 0.5
    assert console.app.state.session.status()["live"]["watchers"] == 0  # the page went away: rig idle


@pytest.mark.parametrize("name", ["../outside", "a/b", ".hidden", "..", "x" * 200])
def test_names_stay_inside_the_data_directory(console: TestClient, name: str) -> None:
    reply = console.post("/api/process", json={"capture": name})
    assert reply.status_code == 400 and "plain name" in reply.json()["error"]
    assert console.post("/api/scan", json={"name": name}).status_code == 400
    assert not console.app.state.session.status()["busy"]


def test_a_link_out_of_the_data_directory_is_refused(console: TestClient, tmp_path: Path) -> None:
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "report.json").write_text("{}")
    (console.app.state.session.data.root / "results" / "link").symlink_to(outside)
    reply = console.get("/api/results/link")
    assert reply.status_code == 400 and "outside the data directory" in reply.json()["error"]
    assert console.get("/api/results/..%2F..%2Fetc/map.png").status_code in (400, 404)
    assert console.get("/api/results/nothing").status_code == 404


def test_errors_are_one_readable_line(console: TestClient) -> None:
    reply = console.put("/api/exposure", json={"exposure_us": -5})
    assert reply.status_code == 400 and reply.json()["error"].startswith("exposure_us: expected")
    reply = console.put("/api/projector", json={"pattern": "checkerboard"})
    assert reply.status_code == 400 and "pattern: expected one of black, white, fringe" in reply.json()["error"]
    reply = console.post("/api/process", json={"capture": "missing"})
    assert reply.status_code == 404 and "captures/missing: not found" in reply.json()["error"]


def test_token_is_required_when_set(tmp_path: Path, console_rig_toml: Path) -> None:
    app = create_app(load_config(console_rig_toml), tmp_path / "data", token="s3cret-0123456789abcdef")
    with TestClient(app, base_url=BASE) as client:
        assert client.get("/api/status").status_code == 401
        assert client.get("/api/status", headers={"Authorization": "Bearer wrong"}).status_code == 401
        assert client.get("/api/status", headers={"Authorization": "Bearer s3cret-0123456789abcdef"}).status_code == 200
        page = client.get("/?token=s3cret-0123456789abcdef")
        assert page.status_code == 200 and "rig_console_token=s3cret-0123456789abcdef" in page.headers["set-cookie"]
        assert client.get("/api/status").status_code == 200  # the cookie now carries it
        client.cookies.clear()
        from starlette.websockets import WebSocketDisconnect

        with pytest.raises(WebSocketDisconnect):
            with client.websocket_connect(WS + "/api/events") as socket:
                socket.receive_text()


def test_requests_from_another_origin_are_refused(console: TestClient) -> None:
    reply = console.post("/api/scan", json={}, headers={"Origin": "http://example.com"})
    assert reply.status_code == 403 and not console.app.state.session.status()["busy"]


def test_a_device_fault_is_reported_and_the_next_scan_works(console: TestClient) -> None:
    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()
        job, error = scan_into_fault(console, socket, "camera-gone", "faulty")
    assert "disappeared" in error
    assert wait_job(console, job["id"])["state"] == "failed"
    status = console.get("/api/status").json()
    assert "disappeared" in status["device_error"]
    retry = console.post("/api/scan", json={"name": "after-fault", "process": False}).json()["job"]
    assert wait_job(console, retry["id"])["state"] == "done"
    assert console.get("/api/devices").json()["devices"][1]["state"] == "open"


def test_fault_injection_is_off_unless_asked_for(tmp_path: Path, console_rig_toml: Path) -> None:
    with TestClient(create_app(load_config(console_rig_toml), tmp_path / "data"), base_url=BASE) as client:
        assert client.post("/api/simulation/fault", json={"fault": "camera-gone"}).status_code in (404, 405)


def test_reprocess_and_compare(console: TestClient) -> None:
    job = console.post("/api/scan", json={"name": "base", "options": {"correction": "none"}}).json()["job"]
    wait_job(console, job["id"])
    wait_saved(console, "base")
    again = console.post(
        "/api/process", json={"capture": "base", "name": "base-vote", "options": {"correction": "vote"}}
    )
    assert again.status_code == 202
    assert wait_job(console, again.json()["job"]["id"])["state"] == "done"
    assert console.get("/api/results/base-vote").json()["methods"]["correction"] == "vote"
    assert set(console.get("/api/captures/base").json()["results"]) == {"base", "base-vote"}
    figures = console.get("/api/compare", params={"a": "base", "b": "base-vote"}).json()
    assert figures["unit"] == "rad" and figures["rms"] >= 0 and figures["valid_fraction"] > 0.5
    assert console.get("/api/compare.png", params={"a": "base", "b": "base-vote"}).content[:4] == b"\x89PNG"


def test_calibration_wizard_runs_unattended_on_the_simulated_rig(console: TestClient) -> None:
    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()
        reply = console.post("/api/calibrate", json={"name": "cal", "heights_mm": [25, 50, 100], "board_views": 0})
        assert reply.status_code == 202
        assert console.post("/api/scan", json={}).status_code == 409  # one acquisition at a time
        steps, result = calibration_messages(socket)
    assert any("reference plane" in s for s in steps) and any("25 mm" in s for s in steps)
    assert result["l0_mm"] == pytest.approx(1000.0, rel=0.01) and result["d0_mm"] == pytest.approx(250.0, rel=0.01)
    assert wait_job(console, reply.json()["job"]["id"])["state"] == "done"
    assert console.get("/api/calibrations").json() == {"calibrations": ["cal"], "active": "cal"}
    job = console.post("/api/scan", json={"name": "after-cal", "options": {"correction": "none"}}).json()["job"]
    wait_job(console, job["id"])
    assert wait_saved(console, "after-cal")["shows"] == "height"


def test_the_alignment_grid_shows_in_the_live_frame(console: TestClient) -> None:
    """The projector's grid + crosshair, seen by the simulated camera: the live frame follows the grid's image."""
    import cv2

    from mock_devices.synth import projector_coordinates, sample_projector_image
    from processing.projection.patterns import pattern_image
    from rig.hardware.simulated import geometry_from_config, scene_height

    reply = console.put("/api/projector", json={"pattern": "grid", "pitch_px": 32})
    assert reply.status_code == 200 and reply.json()["capture_pattern"] == {"kind": "grid", "pitch_px": 32}
    console.put("/api/live", json={"overlay": False})
    config = console.app.state.session.config
    geometry = geometry_from_config(config)
    mapping = projector_coordinates(scene_height(config, "object", geometry), geometry)

    def seen(pitch: int, roll: int = 0) -> np.ndarray:
        image = np.roll(pattern_image({"kind": "grid", "pitch_px": pitch}, config.projector.size), roll, axis=(0, 1))
        return sample_projector_image(image, mapping)[mapping.lit]

    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()
        socket.send_text(json.dumps({"live": True}))
        live_frames(socket, 2)  # frames taken before the pattern reached the camera are past
        data = b""
        while not data:
            data = socket.receive().get("bytes") or b""
    size = int.from_bytes(data[:4], "little")
    frame = cv2.imdecode(np.frombuffer(data[4 + size :], dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
    assert frame.shape == (HEIGHT, WIDTH)
    shown = frame[mapping.lit].astype(np.float64)
    match = np.corrcoef(shown, seen(32))[0, 1]
    half_pitch_off = np.corrcoef(shown, seen(32, roll=16))[0, 1]
    print(
        f"grid in the live frame: correlation {match:.2f} with the grid's image, {half_pitch_off:.2f} half a pitch off"
    )
    assert match > 0.8 and half_pitch_off < 0.3, (match, half_pitch_off)
    assert console.put("/api/projector", json={"pattern": "grid", "pitch_px": 2}).status_code == 400


def test_a_trigger_timeout_is_reported_and_the_next_scan_works(console: TestClient) -> None:
    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()
        job, error = scan_into_fault(console, socket, "trigger-timeout", "stalled")
    print(f"trigger-timeout error: {error}")
    assert "trigger" in error.lower() and "Traceback" not in error and "\n" not in error, error
    assert wait_job(console, job["id"])["state"] == "failed"
    assert not (console.app.state.session.data.root / "captures" / "stalled").exists()
    assert console.get("/api/status").json()["device_error"]
    retry = console.post("/api/scan", json={"name": "after-timeout", "process": False}).json()["job"]
    assert wait_job(console, retry["id"])["state"] == "done"
    assert [c["name"] for c in console.get("/api/captures").json()["captures"] if c.get("complete", True)] == [
        "after-timeout"
    ]


def test_calibration_wizard_options_model_and_gamma(console: TestClient) -> None:
    stereo = console.post("/api/calibrate", json={"name": "st", "model": "stereo", "board_views": 3})
    assert (
        stereo.status_code == 400 and "simulated rig" in stereo.json()["error"] and "real rig" in stereo.json()["error"]
    )
    bad = console.post("/api/calibrate", json={"name": "g", "gamma_levels": 3})
    assert bad.status_code == 400 and bad.json()["error"].startswith("gamma_levels: expected")
    assert console.post("/api/calibrate", json={"model": "affine"}).status_code == 400
    assert not (console.app.state.session.data.root / "calibrations" / "st").exists()
    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()
        reply = console.post(
            "/api/calibrate",
            json={
                "name": "poly",
                "heights_mm": [25, 50, 100],
                "board_views": 0,
                "model": "polynomial",
                "gamma_levels": 5,
            },
        )
        assert reply.status_code == 202
        steps, result = calibration_messages(socket)
    assert steps[0].startswith("gamma ramp") and result["model"] == "polynomial"
    assert any(line.startswith("projector gamma") for line in result["lines"])
    assert any(line.startswith("polynomial degree") for line in result["lines"])
    assert wait_job(console, reply.json()["job"]["id"])["state"] == "done"
    stored = json.loads(
        (console.app.state.session.data.root / "calibrations" / "poly" / "calibration.json").read_text()
    )
    assert stored["model"] == "polynomial" and "gamma" in stored


def test_a_real_rig_prompt_waits_for_the_answer_from_the_page(console: TestClient) -> None:
    """The operator flow of a real rig (the simulated rig sets its scenes up itself): each prompt
    reaches the page, the session waits until the page answers Done, and Stop ends the wait."""
    import threading

    from rig.events import Cancelled

    session = console.app.state.session
    job = session.jobs.start("calibrate", "manual")
    operator = session.operator(job)
    done: list[str] = []

    def plane() -> None:
        try:
            operator.plane(50.0)
            done.append("answered")
        except Cancelled as exc:
            done.append(f"cancelled: {exc}")

    assert console.post("/api/calibrate/answer", json={}).status_code == 400  # nothing asked yet
    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()
        worker = threading.Thread(target=plane)
        worker.start()
        while True:
            message = socket.receive()
            if message.get("text") and json.loads(message["text"])["type"] == "prompt":
                prompt = json.loads(message["text"])
                break
        assert prompt == {"type": "prompt", "job": job.id, "text": "move the plane to 50 mm"}
        assert console.get("/api/status").json()["prompt"]["text"] == "move the plane to 50 mm"
        time.sleep(0.3)
        assert worker.is_alive() and not done  # still waiting for the operator
        assert console.post("/api/calibrate/answer", json={}).json() == {"answered": True}
        worker.join(timeout=10)
    assert done == ["answered"] and console.get("/api/status").json()["prompt"] is None
    assert console.post("/api/calibrate/answer", json={}).status_code == 400  # answered once

    worker = threading.Thread(target=plane)
    worker.start()
    while session.prompt is None:
        time.sleep(0.01)
    assert console.post("/api/stop", params={"job": job.id}, json={}).json()["stopped"] == [job.id]
    worker.join(timeout=10)
    assert done[-1].startswith("cancelled") and session.prompt is None


def _interrupted_copy(console: TestClient, name: str) -> Path:
    """A complete scan ``name`` copied to ``name.incomplete-k1ll`` marked incomplete: what a kill
    after the last frame but before the commit leaves behind."""
    import shutil

    job = console.post("/api/scan", json={"name": name, "process": False}).json()["job"]
    assert wait_job(console, job["id"])["state"] == "done"
    captures = Path(console.get("/api/status").json()["data"]["root"]) / "captures"
    staged = captures / f"{name}.incomplete-k1ll"
    shutil.copytree(captures / name, staged)
    manifest = json.loads((staged / "capture.json").read_text())
    (staged / "capture.json").write_text(json.dumps({**manifest, "complete": False}))
    return staged


def test_an_interrupted_scan_is_listed_and_can_be_salvaged(console: TestClient) -> None:
    staged = _interrupted_copy(console, "cut")
    rows = {row["name"]: row for row in console.get("/api/captures").json()["captures"]}
    assert rows[staged.name]["complete"] is False and "salvage or discard" in rows[staged.name]["error"]
    assert console.post("/api/process", json={"capture": staged.name}).status_code == 400  # not a capture name
    reply = console.post(f"/api/captures/{staged.name}/salvage", json={"options": {"correction": "none"}})
    assert reply.status_code == 202
    job = wait_job(console, reply.json()["job"]["id"])
    assert job["state"] == "done" and job["name"].startswith("cut-salvaged-none")
    assert wait_saved(console, job["name"])["shows"] == "phase"
    assert staged.is_dir()  # salvaging reads, never moves or deletes


def test_discarding_an_interrupted_scan_moves_it_to_the_trash(console: TestClient) -> None:
    staged = _interrupted_copy(console, "cut")
    files = sorted(p.relative_to(staged) for p in staged.rglob("*"))
    reply = console.post(f"/api/captures/{staged.name}/discard", json={})
    assert reply.status_code == 200 and reply.json()["moved_to"] == f"trash/captures/{staged.name}"
    trash = staged.parent.parent / "trash" / "captures" / staged.name
    assert not staged.exists() and sorted(p.relative_to(trash) for p in trash.rglob("*")) == files
    assert staged.name not in [row["name"] for row in console.get("/api/captures").json()["captures"]]
    assert console.post("/api/captures/cut/discard", json={}).status_code == 404  # only interrupted writes
    assert (staged.parent / "cut" / "capture.json").is_file()


# --------------------------------------------------------------------------- Verify view (issue 23)

VERIFY_ARTEFACTS = (
    Path(__file__).parent.parent / "examples" / "artefacts.toml"
).read_text() + "[volume]\ndepth_mm = 150.0\n"
VERIFY_MPE = {"PF": 1.5, "PS": 0.4, "SD": 0.4, "F": 1.5}  # what the 320x240 camera meets (pixels of ~1.4 mm)
REDUCED = {"spheres": 1, "ball_bars": 1, "planes": 1}


def verification_messages(socket: Any) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The verify progress events on ``socket`` up to the verification message, and that message."""
    events: list[dict[str, Any]] = []
    while True:
        message = socket.receive()
        if message.get("text"):
            data = json.loads(message["text"])
            if data["type"] == "progress" and data["kind"] == "verify":
                events.append(data["event"])
            elif data["type"] == "verification":
                return events, data
            elif data["type"] == "error":
                raise AssertionError(data["message"])


@pytest.fixture
def verifiable(console: TestClient, console_rig_toml: Path, exact_calibration: Callable[..., Path]) -> TestClient:
    """The console with an exact calibration ``vcal`` of its rig and DATA/artefacts.toml."""
    root = console.app.state.session.data.root
    exact_calibration(console_rig_toml, root / "calibrations" / "vcal")
    (root / "artefacts.toml").write_text(VERIFY_ARTEFACTS)
    return console


def test_verify_runs_unattended_and_reports_the_four_quantities(verifiable: TestClient) -> None:
    console = verifiable
    body = {"name": "v1", "calibration": "vcal", **REDUCED, "mpe_mm": VERIFY_MPE}
    with console.websocket_connect(WS + "/api/events") as socket:
        socket.receive_text()
        reply = console.post("/api/verify", json=body)
        assert reply.status_code == 202 and reply.json()["job"]["kind"] == "verify"
        assert console.post("/api/scan", json={}).status_code == 409  # one acquisition at a time
        assert console.post("/api/verify", json={**body, "name": "v2"}).status_code == 409
        events, done = verification_messages(socket)
    assert wait_job(console, reply.json()["job"]["id"])["state"] == "done"
    notes = [e["note"] for e in events if e["kind"] == "message"]
    assert any(n.startswith("sphere, position 1 of 1") for n in notes), notes
    assert done["pass"] is True and done["calibration"] == "vcal" and done["summary"].startswith("PASS")
    stored = console.get("/api/verifications/v1").json()
    report = stored["report"]
    for q in ("PF", "PS", "SD", "F"):
        assert report[q]["pass"] and report[q]["mpe_mm"] == VERIFY_MPE[q] and len(report[q]["positions"]) == 1
    assert {"residuals-sphere.png", "residuals-ball-bar.png", "residuals-plane.png"} <= set(stored["figures"])
    assert console.get("/api/verifications/v1/figures/residuals-sphere.png").content[:4] == b"\x89PNG"
    assert console.get("/api/verifications/v1/figures/..%2Freport.json").status_code == 404
    assert console.get("/api/verifications").json() == {"verifications": ["v1"]}
    history = console.get("/api/calibrations/vcal/verifications").json()
    assert len(history["entries"]) == 1
    assert history["series"]["SD"][0]["worst_mm"] == report["SD"]["worst_mm"]


def test_verify_requests_are_checked(verifiable: TestClient) -> None:
    console = verifiable
    assert console.post("/api/verify", json={"calibration": "vcal", "spheres": 0}).status_code == 400
    assert console.post("/api/verify", json={"calibration": "vcal", "planes": 7}).status_code == 400
    bad_mpe = console.post("/api/verify", json={"calibration": "vcal", "mpe_mm": {"PF": 1.0}})
    assert bad_mpe.status_code == 400 and "mpe_mm" in bad_mpe.json()["error"]
    assert console.post("/api/verify", json={"calibration": "nothing"}).status_code == 404
    assert console.post("/api/verify", json={"calibration": "vcal", "colour": 1}).status_code == 422
    # the access rule: a request that changes something needs a JSON body or the client header
    assert console.post("/api/verify", content=b"calibration=vcal").status_code in (403, 415)
    assert console.post("/api/verify/answer", json={}).status_code == 400  # nothing asked
    assert console.get("/api/verifications").json() == {"verifications": []}


def test_result_downloads_come_from_the_result_store(verifiable: TestClient) -> None:
    """Every file a result holds is listed with its media type and can be downloaded, the new
    formats (mesh.ply, mesh.stl, mesh.obj) included; a name outside the store's is refused."""
    from rig import api
    from rig.store.results import MEDIA_TYPES

    console = verifiable
    data = console.app.state.session.data
    job = console.post("/api/scan", json={"name": "meshy", "process": False}).json()["job"]
    wait_job(console, job["id"])
    result = api.process(data.path("captures", "meshy"), calibration=data.path("calibrations", "vcal"))
    api.write_outputs(result, data.path("results", "meshy"), formats=["ply", "mesh-ply", "stl", "obj"])
    listed = console.get("/api/results/meshy/files").json()["files"]
    names = [f["name"] for f in listed]
    assert {"points.ply", "mesh.ply", "mesh.stl", "mesh.obj", "height.npy", "report.json"} <= set(names)
    assert "points.e57" not in names  # not written: not offered
    for f in listed:
        assert f["media_type"] == MEDIA_TYPES[f["name"]]
        reply = console.get(f"/api/results/meshy/files/{f['name']}")
        assert reply.status_code == 200 and reply.headers["content-type"].startswith(f["media_type"])
        assert reply.content == (data.path("results", "meshy") / f["name"]).read_bytes()
    assert console.get("/api/results/meshy/files/mesh.stl").content[80:84] != b""
    assert console.get("/api/results/meshy/files/points.e57").status_code == 404
    assert console.get("/api/results/meshy/files/calibration.json").status_code == 404


def test_a_verify_prompt_on_a_real_rig_is_answered_from_the_page(console: TestClient) -> None:
    """On a real rig each placement is a prompt in the page; /api/verify/answer lets the session go on."""
    import threading

    from rig.verify.guideline import Placement
    from rig.verify.operator import PromptOperator

    session = console.app.state.session
    job = session.jobs.start("verify", "manual")
    operator = PromptOperator(lambda text: session.ask_operator(job, text))
    spot = Placement("ball-bar", 3, 7, "space diagonal", ())
    worker = threading.Thread(target=operator.place, args=(spot,))
    worker.start()
    while session.prompt is None:
        time.sleep(0.01)
    prompt = console.get("/api/status").json()["prompt"]
    assert prompt["job"] == job.id and prompt["text"].startswith("ball bar, position 3 of 7: space diagonal")
    assert not prompt["text"].endswith("press Enter")
    assert console.post("/api/verify/answer", json={}).json() == {"answered": True}
    worker.join(timeout=10)
    assert not worker.is_alive() and console.get("/api/status").json()["prompt"] is None
