"""The console's measuring routes on a scan of the simulated gauge block (25.000 mm high, a centred
rectangle a third of the view wide and high) with the rig's exact calibration: the step height from
two regions, the block's width from two points, the flatness of the plane around it, the
histogram's share of block pixels, a line profile, CSV files and one-line refusals."""

from __future__ import annotations

import csv
import io
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from console_client import BASE, wait_job, wait_saved
from fastapi.testclient import TestClient

from rig.config import load_config
from rig.console.app import create_app

BLOCK_MM = 25.0  # mock_devices.scenes.gauge_block's default height


@pytest.fixture(scope="module")
def block(
    tmp_path_factory: pytest.TempPathFactory,
    simulated_rig_toml: Callable[..., str],
    exact_calibration: Callable[[Path, Path], Path],
) -> Iterator[dict[str, Any]]:
    """The console with a scan ``block`` of the gauge block, its truth and the block's pixel box."""
    from rig.hardware.simulated import geometry_from_config, scene_height

    root = tmp_path_factory.mktemp("measure")
    toml = root / "rig.toml"
    text = simulated_rig_toml((456, 570), (320, 240), 35.0).replace('"hemisphere"', '"gauge-block"')
    toml.write_text(text.replace("[scan]\n", "[scan]\nfetch_timeout_s = 0.5\nretries = 1\n"))
    exact_calibration(toml, root / "data" / "calibrations" / "cal")
    config = load_config(toml)
    geometry = geometry_from_config(config)
    truth = scene_height(config, "object", geometry)
    rows, cols = np.nonzero(truth > BLOCK_MM / 2)
    with TestClient(create_app(config, root / "data"), base_url=BASE) as client:
        job = client.post("/api/scan", json={"name": "block", "options": {"correction": "none"}}).json()["job"]
        assert wait_job(client, job["id"])["state"] == "done"
        wait_saved(client, "block")
        yield {
            "client": client,
            "box": (int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max())),
            "pixel_mm": geometry.pixel_mm,
            "l0_mm": geometry.l0_mm,
        }


def _get(client: TestClient, path: str, **query: Any) -> dict[str, Any]:
    reply = client.get(f"/api/results/block/measure/{path}", params=query)
    assert reply.status_code == 200, reply.text
    return dict(reply.json())


def test_step_height_from_two_regions(block: dict[str, Any]) -> None:
    client, (x0, y0, x1, y1) = block["client"], block["box"]
    top = _get(client, "roi", x0=x0 + 5, y0=y0 + 5, x1=x1 - 5, y1=y1 - 5)
    floor = _get(client, "roi", x0=2, y0=2, x1=x0 - 5, y1=y1)
    assert top["valid_fraction"] > 0.95 and floor["valid_fraction"] > 0.9
    assert top["mean"] - floor["mean"] == pytest.approx(BLOCK_MM, abs=0.3)  # mm, step height
    assert top["std"] < 0.5


def test_the_plane_around_the_block_is_flat_and_the_block_stands_above_it(block: dict[str, Any]) -> None:
    client, (x0, _, _, y1) = block["client"], block["box"]
    plane = _get(client, "plane", x0=2, y0=2, x1=x0 - 5, y1=y1)
    assert plane["orthogonal"] and plane["tilt_deg"] < 0.5  # the reference plane is level
    # the plane is exact and level: what the fit leaves is the noise, whose spread the region shows
    spread = _get(client, "roi", x0=2, y0=2, x1=x0 - 5, y1=y1)
    assert plane["rms"] == pytest.approx(spread["std"], rel=0.02) and plane["rms"] < 0.3
    assert plane["flatness"] == pytest.approx(spread["peak_to_valley"], rel=0.05)
    png = client.get("/api/results/block/measure/plane.png", params={"x0": 2, "y0": 2, "x1": x0 - 5, "y1": y1})
    assert png.content[:4] == b"\x89PNG" and float(png.headers["X-Range"].split(",")[1]) == pytest.approx(
        BLOCK_MM, abs=1.0
    )


def test_distance_across_the_block_is_its_width(block: dict[str, Any]) -> None:
    client, (x0, y0, x1, y1) = block["client"], block["box"]
    row = (y0 + y1) // 2
    d = _get(client, "distance", x0=x0 + 1, y0=row, x1=x1 - 1, y1=row)
    # a pixel spans pixel_mm on the reference plane and (l0 - h) / l0 of it at height h (the camera's
    # centre is l0 above the plane): the top's width within one pixel
    scale = block["pixel_mm"] * (block["l0_mm"] - BLOCK_MM) / block["l0_mm"]
    assert d["lateral_distance"] == pytest.approx((x1 - x0 - 2) * scale, abs=scale)
    assert abs(d["rise"]) < 1.0
    step = _get(client, "distance", x0=x0 - 6, y0=row, x1=x0 + 6, y1=row)
    assert step["rise"] == pytest.approx(BLOCK_MM, abs=1.0)


def test_histogram_and_profile_see_the_block(block: dict[str, Any]) -> None:
    client, (x0, y0, x1, y1) = block["client"], block["box"]
    hist = _get(client, "histogram", bins=10, x0=0, y0=0, x1=319, y1=239)
    counts = np.array(hist["counts"])
    share = counts[-2:].sum() / counts.sum()
    block_share = (x1 - x0 + 1) * (y1 - y0 + 1) / (320 * 240)
    assert share == pytest.approx(block_share, rel=0.1)
    row = (y0 + y1) // 2
    profile = _get(client, "profile", x0=x0 - 20, y0=row, x1=x1 + 20, y1=row)
    values = np.array([np.nan if v is None else v for v in profile["value"]])
    high = np.array(profile["col"])[values > BLOCK_MM / 2]
    assert abs(int(high.min()) - x0) <= 1 and abs(int(high.max()) - x1) <= 1


def test_csv_files_and_refusals(block: dict[str, Any]) -> None:
    client = block["client"]
    reply = client.get("/api/results/block/measure/roi", params={"format": "csv"})
    assert reply.headers["content-type"].startswith("text/csv")
    assert 'filename="block-roi.csv"' in reply.headers["content-disposition"]
    table = {row[0]: row[1] for row in csv.reader(io.StringIO(reply.text)) if row}
    assert float(table["mean"]) == pytest.approx(_get(client, "roi")["mean"])
    profile = client.get(
        "/api/results/block/measure/profile", params={"x0": 0, "y0": 5, "x1": 9, "y1": 5, "format": "csv"}
    )
    assert len(list(csv.reader(io.StringIO(profile.text)))) == 11  # a header and ten samples
    off = client.get("/api/results/block/measure/distance", params={"x0": 0, "y0": 0, "x1": 999, "y1": 0})
    assert (
        off.status_code == 400
        and off.json()["error"] == "point 2 (999, 0): outside the 320x240 map; pick a pixel on the map"
    )
    partial = client.get("/api/results/block/measure/roi", params={"x0": 3})
    assert partial.status_code == 400 and "give all four" in partial.json()["error"]
    assert client.get("/api/results/nothing/measure/roi").status_code == 404
