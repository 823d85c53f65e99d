"""The console's ASGI app under FastAPI's test client, on a small simulated rig (fixtures and helpers
shared by the console's API and hardening tests; the fixtures are registered in conftest.py)."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from rig.config import load_config
from rig.console.app import create_app
from rig.console.server import HEADER_TIMEOUT_S, server_config

WIDTH, HEIGHT = 320, 240
BASE = "http://127.0.0.1:8765"  # a name the console answers to (the Host header is checked)
WS = "ws://127.0.0.1:8765"
STARTUP_S = 60  # a bound on a loaded machine, not a timing assertion


@pytest.fixture
def console_rig_toml(tmp_path: Path, simulated_rig_toml: Callable[..., str]) -> Path:
    path = tmp_path / "rig.toml"
    text = simulated_rig_toml((456, 570), (WIDTH, HEIGHT), 35.0)
    path.write_text(text.replace("[scan]\n", "[scan]\nfetch_timeout_s = 0.5\nretries = 1\n"))
    return path


@pytest.fixture
def console(tmp_path: Path, console_rig_toml: Path) -> Iterator[TestClient]:
    app = create_app(load_config(console_rig_toml), tmp_path / "data", fault_injection=True)
    with TestClient(app, base_url=BASE) as client:
        yield client


def wait_job(client: TestClient, job_id: str, timeout_s: float = 60.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = client.get(f"/api/jobs/{job_id}").json()
        if job["state"] != "running":
            return dict(job)
        time.sleep(0.05)
    raise AssertionError(f"job {job_id} still running after {timeout_s} s")


def wait_saved(client: TestClient, name: str, timeout_s: float = 60.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        reply = client.get(f"/api/results/{name}")
        if reply.status_code == 200 and reply.json()["saved"]:
            return dict(reply.json())
        time.sleep(0.05)
    raise AssertionError(f"result {name} not saved after {timeout_s} s")


@contextlib.contextmanager
def served(app: Any, header_timeout_s: float = HEADER_TIMEOUT_S) -> Iterator[int]:
    """``app`` under uvicorn on a free loopback port, configured as ``rig console`` serves it; the port."""
    import uvicorn

    from benchmarks.dask_cluster import free_port

    port = free_port()
    server = uvicorn.Server(server_config(app, "127.0.0.1", port, header_timeout_s=header_timeout_s))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + STARTUP_S
        while not server.started:
            assert time.monotonic() < deadline, "console did not start"
            time.sleep(0.05)
        yield port
    finally:
        server.should_exit = True
        thread.join(timeout=30)
