"""The console's scan setup (issue 24's "scan setup in the page", issue 25's HDR controls) through its API:
values checked with their field named, remembered per data folder, used by the next scan (part name
and notes into capture.json, several exposures), the exposure assistant's suggestion, and the
result's exposure map."""

from __future__ import annotations

import json
from pathlib import Path

from console_client import wait_job, wait_saved
from fastapi.testclient import TestClient

from rig.config import load_config
from rig.console.app import create_app
from rig.store.capture import read_capture
from rig.store.exposures import exposure_sets

HEADERS = {"X-Console-Client": "test"}


def test_setup_values_are_checked_with_their_field_named(console: TestClient) -> None:
    reply = console.put("/api/scan-setup", json={"steps": 2}, headers=HEADERS)
    assert reply.status_code == 400 and reply.json()["error"].startswith("steps: expected"), reply.json()
    reply = console.put("/api/scan-setup", json={"exposures_us": [2000, 2000]}, headers=HEADERS)
    assert reply.status_code == 400 and reply.json()["error"].startswith("exposures: expected distinct")
    reply = console.put("/api/scan-setup", json={"pattern_set": "moire"}, headers=HEADERS)
    assert reply.status_code == 400 and "pattern set: expected one of" in reply.json()["error"]
    assert console.get("/api/scan-setup").json()["steps"] is None  # nothing half-applied


def test_setup_is_remembered_per_data_folder_and_used_by_the_next_scan(
    console: TestClient, tmp_path: Path, console_rig_toml: Path
) -> None:
    changes = {"part": "bracket 7/b", "notes": "left side up", "steps": 5, "exposures_us": [5000, 20000]}
    setup = console.put("/api/scan-setup", json=changes, headers=HEADERS).json()
    assert setup["used"]["frames"] == 3 * 5 * 2 and setup["part"] == "bracket 7/b"
    assert json.loads((tmp_path / "data" / "scan-setup.json").read_text())["steps"] == 5
    job = console.post("/api/scan", json={"process": True}, headers=HEADERS).json()["job"]
    assert job["name"].startswith("bracket-7-b"), job["name"]
    assert wait_job(console, job["id"])["state"] == "done"
    capture = read_capture(tmp_path / "data" / "captures" / job["name"])
    assert capture.manifest["part"] == {"name": "bracket 7/b", "notes": "left side up"}
    sets = exposure_sets(capture.pattern_models)
    assert sets.exposures_us == (5000.0, 20000.0) and len(sets.base) == 3 * 5
    summary = wait_saved(console, job["name"])
    assert [e["exposure_us"] for e in summary["exposures"]] == sorted({e["exposure_us"] for e in summary["exposures"]})
    assert abs(sum(e["share"] for e in summary["exposures"]) - 1.0) < 1e-3
    png = console.get(f"/api/results/{job['name']}/exposure.png")
    assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"
    # another console on the same folder starts from what this one remembered
    with TestClient(
        create_app(load_config(console_rig_toml), tmp_path / "data"), base_url=str(console.base_url)
    ) as other:
        assert other.get("/api/scan-setup").json()["part"] == "bracket 7/b"


def test_a_single_exposure_result_has_no_exposure_map(console: TestClient) -> None:
    job = console.post("/api/scan", json={"process": True}, headers=HEADERS).json()["job"]
    assert wait_job(console, job["id"])["state"] == "done"
    summary = wait_saved(console, job["name"])
    assert summary["exposures"] == []
    assert console.get(f"/api/results/{job['name']}/exposure.png").status_code == 404


def test_hdr_auto_suggests_exposures_with_their_predicted_coverage(console: TestClient) -> None:
    plan = console.post("/api/scan-setup/hdr-auto", json={}, headers=HEADERS).json()
    assert 1 <= len(plan["exposures_us"]) <= 3 and 0 <= plan["coverage"] <= 1
    assert "predicted usable" in plan["lines"][0]
    assert console.get("/api/scan-setup").json()["exposures_us"] == []  # shown, not applied
