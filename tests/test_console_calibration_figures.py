"""Calibration you can see (issue 24): after the wizard's session on the simulated rig (projector
gamma 2.2), the figures name each plane's residual and flatness, the gamma curve recovers the
simulated gamma, and each board view shows its detected corners with reprojection residuals as
small as the camera fit's."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from typing import Any

import cv2
import numpy as np
import pytest
from console_client import BASE, wait_job
from fastapi.testclient import TestClient

from rig.config import load_config
from rig.console.app import create_app

GAMMA = 2.2


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory, simulated_rig_toml: Callable[..., str]) -> Iterator[Any]:
    root = tmp_path_factory.mktemp("calfig")
    toml = root / "rig.toml"
    toml.write_text(simulated_rig_toml((456, 570), (320, 240), 35.0, gamma=GAMMA))
    with TestClient(create_app(load_config(toml), root / "data"), base_url=BASE) as client:
        job = client.post("/api/calibrate", json={"name": "c", "gamma_levels": 12, "board_views": 4}).json()["job"]
        assert wait_job(client, job["id"], timeout_s=300)["state"] == "done"
        yield client


def test_figures_name_the_planes_gamma_and_camera(calibrated: TestClient) -> None:
    figures = calibrated.get("/api/calibrations/c/figures").json()
    cal = json.loads((calibrated.app.state.session.data.root / "calibrations" / "c" / "calibration.json").read_text())
    assert figures["planes"]["heights_mm"] == [25.0, 50.0, 100.0, 150.0]
    assert figures["planes"]["residuals_mm"] == cal["residuals_mm"] and len(figures["planes"]["flatness_rms_mm"]) == 4
    assert figures["gamma"]["gamma"] == pytest.approx(GAMMA, abs=0.1)
    assert len(figures["gamma"]["levels"]) == len(figures["gamma"]["responses"]) == 12
    assert figures["board_views"] == ["plane", "view-01", "view-02", "view-03", "view-04"]
    assert figures["camera"]["reprojection_rms_px"] == cal["reprojection_rms_px"]


def test_each_board_view_shows_its_corners_and_residuals(calibrated: TestClient) -> None:
    figures = calibrated.get("/api/calibrations/c/figures").json()
    for view in figures["board_views"]:
        reply = calibrated.get(f"/api/calibrations/c/board/{view}.png")
        assert reply.status_code == 200
        found = json.loads(reply.headers["X-Figures"])
        assert found["found"] and found["lit"] >= 4 and found["lit"] <= found["corners"]
        # the pose is solved with the calibration's intrinsics: its residuals are the camera fit's
        assert found["rms_px"] < max(0.5, 5 * figures["camera"]["reprojection_rms_px"]), (view, found)
        picture = cv2.imdecode(np.frombuffer(reply.content, np.uint8), cv2.IMREAD_COLOR)
        assert picture.shape == (240, 320, 3)
        green = (picture[..., 1] > 150) & (picture[..., 0] < 120) & (picture[..., 2] < 120)
        assert green.sum() >= found["lit"]  # a drawn ring per lit corner
    assert calibrated.get("/api/calibrations/c/board/view-99.png").status_code == 404
    assert calibrated.get("/api/calibrations/nothing/figures").status_code == 404
