"""Hardening III, the console's doors (issue 22): each class reproduced against the real app.

Requests go through the ASGI app (FastAPI's test client) or, for connection-level limits, a real
uvicorn server on a free port; the rig is the simulated one. Classes: 1 DNS rebinding (Host
header), 2 ``Origin: null`` and body-less state changes, 3 token length, 5 staging names taken
for calibrations and results, 6 a scan's scene label, 7 a job that raised something unexpected
(and bounds before allocation), 10 the data directory removed while running, 12 request bodies
and slow headers, 14 a processing request naming an existing result. The jobs service's lock is
hammered from threads.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from console_client import BASE, WS, served, wait_job
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from rig.config import load_config
from rig.console.app import create_app
from rig.errors import ConfigError
from rig.jobs import Jobs

ROOT = Path(__file__).resolve().parent.parent
EVIL = {"Host": "rebind.attacker.example"}


# ------------------------------------------------------------------ 1: the Host header


def test_a_foreign_host_name_is_refused_on_http_and_the_websocket(console: TestClient) -> None:
    reply = console.post("/api/scan", json={}, headers=EVIL)
    assert reply.status_code == 421 and "rebind.attacker.example" in reply.json()["error"]
    assert console.get("/api/status", headers=EVIL).status_code == 421
    assert console.get("/api/jobs").json()["jobs"] == []  # nothing started
    with pytest.raises(WebSocketDisconnect) as closed:
        with console.websocket_connect("ws://rebind.attacker.example/api/events") as events:
            events.receive_text()
    assert closed.value.code == 1008
    for host in ("localhost:8765", "127.0.0.1", "[::1]:8765"):
        assert console.get("/api/status", headers={"Host": host}).status_code == 200, host


def test_allowed_host_names_a_reverse_proxy_and_a_wildcard_address_takes_ip_literals(
    tmp_path: Path, console_rig_toml: Path
) -> None:
    app = create_app(load_config(console_rig_toml), tmp_path / "data", host="0.0.0.0", allowed_hosts=["scanner.lab"])
    with TestClient(app, base_url=BASE) as client:
        assert client.get("/api/status", headers={"Host": "scanner.lab"}).status_code == 200
        assert client.get("/api/status", headers={"Host": "192.168.7.20:8765"}).status_code == 200
        assert client.get("/api/status", headers={"Host": "scanner.lab.attacker.example"}).status_code == 421


# ------------------------------------------------------------------ 2: Origin null, body-less changes


def test_origin_null_is_refused_on_http_and_the_websocket(console: TestClient) -> None:
    null = {"Origin": "null"}
    assert console.post("/api/stop", json={}, headers=null).status_code == 403
    assert console.post("/api/calibrate/answer", json={}, headers=null).status_code == 403
    with pytest.raises(WebSocketDisconnect) as closed:
        with console.websocket_connect(WS + "/api/events", headers=null) as events:
            events.receive_text()
    assert closed.value.code == 1008 and "null" in closed.value.reason


def test_a_state_change_needs_a_json_body_or_the_console_header(console: TestClient) -> None:
    for path in ("/api/stop", "/api/calibrate/answer"):
        reply = console.post(path)  # what a cross-site form or a simple fetch can send
        assert reply.status_code == 403 and "x-console-client" in reply.json()["error"], path
        reply = console.post(path, content=b"{}", headers={"Content-Type": "text/plain"})
        assert reply.status_code == 403, path
    assert console.post("/api/stop", headers={"X-Console-Client": "page-1"}).status_code == 200
    assert console.post("/api/stop", json={}).status_code == 200


# ------------------------------------------------------------------ 3: the token


@pytest.mark.parametrize("token", ["", "short", "x" * 15])
def test_an_empty_or_short_token_is_refused(tmp_path: Path, console_rig_toml: Path, token: str) -> None:
    with pytest.raises(ConfigError, match="--token: expected at least 16 characters"):
        create_app(load_config(console_rig_toml), tmp_path / "data", token=token)


def test_the_command_refuses_an_empty_token_with_one_line(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "rig.cli", "console", "--host", "0.0.0.0", "--token", "", "--data", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.strip().count("\n") == 0 and "--token: expected at least 16 characters" in done.stderr


# ------------------------------------------------------------------ 5: staging names after a kill


def _calibrated_data(tmp_path: Path, console_rig_toml: Path) -> Path:
    """A data directory with calibration ``cal``, and what a kill mid-commit leaves beside it."""
    from calibration.store import write_calibration
    from rig.acquisition.scan import scan
    from rig.hardware.simulated import geometry_from_config
    from rig.hardware.synthesis import exact_calibration

    config = load_config(console_rig_toml)
    data = tmp_path / "data"
    cal = data / "calibrations" / "cal"
    scan(config, cal / "reference", scene="reference")
    write_calibration(cal, exact_calibration(geometry_from_config(config)))
    shutil.copytree(cal, data / "calibrations" / "zz.incomplete-k1ll")  # newer: would be chosen first
    shutil.copytree(cal, data / "calibrations" / "cal.replaced-k1ll")
    (data / "results" / "r1.incomplete-k1ll").mkdir(parents=True)
    (data / "results" / "r1.incomplete-k1ll" / "report.json").write_text("{}")
    return data


def test_staging_folders_are_never_listed_or_activated(tmp_path: Path, console_rig_toml: Path) -> None:
    data = _calibrated_data(tmp_path, console_rig_toml)
    with TestClient(create_app(load_config(console_rig_toml), data), base_url=BASE) as client:
        assert client.get("/api/calibrations").json() == {"calibrations": ["cal"], "active": "cal"}
        reply = client.put("/api/calibration", json={"name": "zz.incomplete-k1ll"})
        assert reply.status_code == 400 and "unfinished writes" in reply.json()["error"]
        assert client.get("/api/status").json()["calibration"] == "cal"
        assert client.get("/api/results").json()["results"] == []
        assert client.get("/api/results/r1.incomplete-k1ll").status_code == 400


# ------------------------------------------------------------------ 6: a scan's scene


def test_a_scan_cannot_claim_a_scene_it_does_not_image(console: TestClient) -> None:
    reply = console.post("/api/scan", json={"name": "labelled", "scene": "reference"})
    assert reply.status_code == 422 and reply.json()["error"].startswith("scene: ")
    assert console.get("/api/jobs").json()["jobs"] == []


# ------------------------------------------------------------------ 7: jobs always end


def test_an_unbounded_gamma_ramp_is_refused_before_anything_is_built(console: TestClient) -> None:
    reply = console.post("/api/calibrate", json={"gamma_levels": 10**12, "board_views": 0})
    assert reply.status_code == 400 and "gamma_levels: expected 0 (no gamma ramp) or 5 .. 256" in reply.json()["error"]
    assert console.get("/api/status").json()["busy"] is False


@pytest.mark.parametrize(
    ("error", "state"),
    [(MemoryError(), "failed"), (RecursionError("deep"), "failed"), (KeyError("k"), "failed"), (None, "done")],
)
def test_a_job_ends_whatever_its_work_raises(error: BaseException | None, state: str) -> None:
    published: list[dict[str, Any]] = []
    jobs = Jobs(published.append)
    job = jobs.start("calibrate", "cal-x")

    def work() -> None:
        if error is not None:
            raise error

    returned = jobs.run(job, work)
    assert returned is error
    assert jobs.get(job.id)["state"] == state and jobs.running() == []
    if error is not None:
        assert jobs.get(job.id)["error"] and published[-2]["type"] == "error"
    with pytest.raises(Exception, match="not running"):
        jobs.stop(job.id)


def test_a_stopped_job_ends_cancelled() -> None:
    jobs = Jobs(lambda message: None)
    job = jobs.start("scan", "part")
    assert jobs.stop() == [job.id]
    jobs.run(job, lambda: job.token.check("scan"))
    assert jobs.get(job.id)["state"] == "cancelled"


def test_the_jobs_registry_holds_under_threads() -> None:
    """Jobs started, updated, finished and forgotten on many threads while others list them (the
    console's event loop lists while its worker threads change them): no error, no job lost."""
    jobs = Jobs(lambda message: None, keep=20)
    errors: list[BaseException] = []
    started: list[str] = []
    stop = threading.Event()

    def writer(n: int) -> None:
        for i in range(300):
            job = jobs.start("process", f"w{n}-{i}")
            started.append(job.id)
            sink = jobs.sink(job, "process")
            from rig.events import Event

            sink(Event("process", "step", 1, 2))
            jobs.run(job, lambda: None)

    def reader() -> None:
        while not stop.is_set():
            try:
                jobs.running()
                jobs.all()
                for record in jobs.all():
                    assert record["state"] in ("running", "done")
            except BaseException as exc:  # noqa: BLE001 - collected for the assertion
                errors.append(exc)

    readers = [threading.Thread(target=reader) for _ in range(3)]
    writers = [threading.Thread(target=writer, args=(n,)) for n in range(4)]
    for t in readers + writers:
        t.start()
    for t in writers:
        t.join()
    stop.set()
    for t in readers:
        t.join()
    assert errors == []
    assert len(set(started)) == 1200 and jobs.running() == []
    assert len(jobs.all()) == 20  # finished jobs beyond the bound are forgotten, oldest first
    assert jobs.all()[-1]["id"] == max(started, key=lambda i: int(i.split("-")[1]))


# ------------------------------------------------------------------ 10: the data directory removed


def test_a_removed_data_directory_is_made_again(console: TestClient) -> None:
    root = Path(console.get("/api/status").json()["data"]["root"])
    shutil.rmtree(root)
    assert console.get("/api/status").status_code == 200
    assert sorted(p.name for p in root.iterdir()) == ["calibrations", "captures", "results", "verifications"]
    shutil.rmtree(root)
    reply = console.post("/api/scan", json={"name": "after", "process": False})
    assert reply.status_code == 202
    assert wait_job(console, reply.json()["job"]["id"])["state"] == "done"
    assert (root / "captures" / "after" / "capture.json").is_file()


def test_a_data_directory_that_cannot_be_made_again_is_one_line(console: TestClient) -> None:
    root = Path(console.get("/api/status").json()["data"]["root"])
    shutil.rmtree(root)
    root.write_text("not a directory")
    reply = console.get("/api/status")
    assert reply.status_code == 400 and reply.json()["error"].startswith(f"data directory {root}")
    reply = console.post("/api/scan", json={"name": "lost", "process": False})
    assert reply.status_code == 400 and console.get("/api/jobs").json()["jobs"] == []


# ------------------------------------------------------------------ 12: bodies and slow clients


def test_a_large_body_is_refused_before_it_is_read(console: TestClient) -> None:
    big = b'{"name": "' + b"x" * (2 << 20) + b'"}'
    reply = console.post("/api/scan", content=big, headers={"Content-Type": "application/json"})
    assert reply.status_code == 413

    def chunks() -> Iterator[bytes]:
        yield b'{"name": "'
        for _ in range(40):
            yield b"x" * 65536
        yield b'"}'

    reply = console.post("/api/scan", content=chunks(), headers={"Content-Type": "application/json"})
    assert reply.status_code == 413 and console.get("/api/jobs").json()["jobs"] == []


@pytest.fixture
def port(tmp_path: Path, console_rig_toml: Path) -> Iterator[int]:
    """The console under uvicorn as ``rig console`` serves it, with a 0.5 s header deadline; its port."""
    with served(create_app(load_config(console_rig_toml), tmp_path / "data"), header_timeout_s=0.5) as port:
        yield port


def test_a_client_that_trickles_its_headers_is_cut_off(port: int) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=30) as slow:
        slow.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        for _ in range(3):  # a header line now and then, never the blank line that ends them
            time.sleep(0.3)
            try:
                slow.sendall(b"X-Slow: 1\r\n")
            except OSError:
                break
        assert slow.recv(1024) == b""  # closed by the server (the 30 s socket timeout would raise)
    with socket.create_connection(("127.0.0.1", port), timeout=30) as quick:
        quick.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        assert quick.recv(64).startswith(b"HTTP/1.1 200")


# ------------------------------------------------------------------ 14: result names collide loudly


def test_processing_into_an_existing_result_name_is_a_conflict(console: TestClient) -> None:
    job = console.post("/api/scan", json={"name": "part", "options": {"correction": "none"}}).json()["job"]
    assert wait_job(console, job["id"])["state"] == "done"
    root = Path(console.get("/api/status").json()["data"]["root"])
    before = {p.name: p.stat().st_mtime_ns for p in (root / "results" / "part").iterdir()}
    assert console.post("/api/scan", json={"name": "other", "process": False}).status_code == 202
    wait_job(console, console.get("/api/jobs").json()["jobs"][-1]["id"])
    reply = console.post("/api/process", json={"capture": "other", "name": "part"})
    assert reply.status_code == 409 and "results/part: already exists" in reply.json()["error"]
    assert {p.name: p.stat().st_mtime_ns for p in (root / "results" / "part").iterdir()} == before


def test_a_linked_file_in_a_result_is_not_served(console: TestClient, tmp_path: Path) -> None:
    """Issue 22 class 9 (downloads): a symbolic link planted in a result folder is not followed."""
    job = console.post("/api/scan", json={"name": "linked", "options": {"correction": "none"}}).json()["job"]
    assert wait_job(console, job["id"])["state"] == "done"
    root = Path(console.get("/api/status").json()["data"]["root"])
    secret = tmp_path / "outside.json"
    secret.write_text('{"secret": 1}')
    report = root / "results" / "linked" / "report.json"
    assert console.get("/api/results/linked/files/report.json").status_code == 200
    report.unlink()
    report.symlink_to(secret)
    reply = console.get("/api/results/linked/files/report.json")
    assert reply.status_code == 404 and "secret" not in reply.text
