"""The console's scan setup and HDR controls in a real headless Chromium (issues 24 and 25).

On the simulated rig looking at the shiny-and-dark scene with the sensor model: a setup value that
does not fit is refused next to the fields; the part name and notes survive a reload (they are
remembered in the data folder); *HDR auto* shows the assistant's exposures and predicted
coverage, *Use these exposures* puts them in the setup; the scan that follows is named after the
part, records it, and its result shows the per-pixel exposure map with one legend entry per
exposure. A fresh data folder's page asks to calibrate first and leads to the Calibration view.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from browser_harness import CHROMIUM, playwright_api
from console_client import served

from rig.config import load_config

RIG_TOML = """
[camera]
size = [320, 240]
[scan]
fetch_timeout_s = 0.5
retries = 1
[simulation]
scene = "shiny-and-dark"
snr_db = "none"
full_well_e = 10000
"""


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """The console on the simulated rig (320x240, shiny-and-dark, with an exact calibration)."""
    from calibration.store import write_calibration
    from rig.acquisition.scan import scan
    from rig.console.app import create_app
    from rig.hardware.simulated import geometry_from_config
    from rig.hardware.synthesis import exact_calibration

    root = tmp_path_factory.mktemp("console-hdr")
    (root / "rig.toml").write_text(RIG_TOML)
    config = load_config(root / "rig.toml")
    cal = root / "data" / "calibrations" / "cal"
    scan(config, cal / "reference", scene="reference")
    write_calibration(cal, exact_calibration(geometry_from_config(config)))
    app = create_app(config, root / "data")
    with served(app) as port:
        yield {"url": f"http://127.0.0.1:{port}/", "config": config, "data": root / "data"}


@pytest.fixture(scope="module")
def page(server: dict[str, Any]) -> Iterator[Any]:
    assert CHROMIUM is not None
    with playwright_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True)
        page = browser.new_context(viewport={"width": 1400, "height": 1000}).new_page()
        page.goto(server["url"])
        page.wait_for_function("document.querySelector('#setup-pattern-set').options.length > 0")
        yield page
        browser.close()


def test_a_setup_value_that_does_not_fit_is_said_next_to_the_fields(page: Any) -> None:
    page.get_by_test_id("setup-steps").fill("2")
    page.get_by_test_id("setup-steps").press("Enter")  # a change event
    page.wait_for_function(
        "document.querySelector('[data-testid=setup-error]').textContent.startsWith('steps: expected')"
    )
    page.get_by_test_id("setup-steps").fill("")
    page.get_by_test_id("setup-steps").press("Enter")
    page.wait_for_function("document.querySelector('[data-testid=setup-error]').textContent === ''")


def test_part_name_and_notes_survive_a_reload(page: Any, server: dict[str, Any]) -> None:
    page.get_by_test_id("setup-part").fill("bracket-7")
    page.get_by_test_id("setup-part").press("Enter")
    page.get_by_test_id("setup-notes").fill("left side up")
    page.get_by_test_id("setup-notes").blur()
    page.wait_for_function(
        "fetch('/api/scan-setup').then(r => r.json()).then(s => s.notes === 'left side up')", timeout=10_000
    )
    page.reload()
    page.wait_for_function("document.querySelector('[data-testid=setup-part]').value === 'bracket-7'")
    assert page.get_by_test_id("setup-notes").input_value() == "left side up"
    assert json.loads((server["data"] / "scan-setup.json").read_text())["part"] == "bracket-7"
    assert page.get_by_test_id("first-run").is_hidden()  # this folder has a calibration


def test_hdr_auto_then_scan_shows_the_exposure_map(page: Any, server: dict[str, Any]) -> None:
    page.get_by_test_id("hdr-auto").click()
    page.wait_for_function("document.querySelector('[data-testid=hdr-suggestion]').dataset.coverage", timeout=60_000)
    suggestion = page.get_by_test_id("hdr-suggestion").inner_text()
    assert "predicted usable" in suggestion and "alone" in suggestion
    assert float(page.get_by_test_id("hdr-suggestion").get_attribute("data-coverage")) >= 0.98
    page.get_by_test_id("hdr-use").click()
    page.wait_for_function("document.querySelector('[data-testid=setup-exposures]').value.includes(',')")
    exposures = [float(v) for v in page.get_by_test_id("setup-exposures").input_value().split(",")]
    assert 2 <= len(exposures) <= 3
    page.get_by_test_id("scan-button").click()
    page.wait_for_function(
        "(() => { const v = document.querySelector('#view-result'); return v.dataset.final === 'true'"
        " && v.dataset.result.startsWith('bracket-7'); })()",
        timeout=120_000,
    )
    assert page.locator("#view-result").evaluate("v => v.classList.contains('active')")
    page.get_by_test_id("exposure-panel").wait_for(state="visible")
    page.wait_for_function("document.querySelector('[data-testid=exposure-map]').naturalWidth === 320")
    legend = page.get_by_test_id("exposure-legend").locator("li")
    assert 1 <= legend.count() <= len(exposures)
    shown = [float(text.split(" ")[0]) for text in legend.all_inner_texts()]
    assert set(shown) <= set(exposures)
    name = page.locator("#view-result").get_attribute("data-result")
    manifest = json.loads((server["data"] / "captures" / name / "capture.json").read_text())
    assert manifest["part"] == {"name": "bracket-7", "notes": "left side up"}
    assert sorted({p["exposure_us"] for p in manifest["patterns"]}) == sorted(exposures)


def test_a_fresh_data_folder_asks_to_calibrate_first(page: Any, server: dict[str, Any], tmp_path: Path) -> None:
    from rig.console.app import create_app

    with served(create_app(server["config"], tmp_path / "fresh")) as port:
        fresh = page.context.new_page()
        fresh.goto(f"http://127.0.0.1:{port}/")
        fresh.get_by_test_id("first-run").wait_for(state="visible")
        assert "calibrat" in fresh.get_by_test_id("first-run").inner_text().lower()
        fresh.get_by_test_id("first-run-calibrate").click()
        assert fresh.locator("#view-calibration").evaluate("v => v.classList.contains('active')")
        fresh.close()
