"""The console's tools in a real headless Chromium, on a scan of the simulated gauge block (25.000
mm high, a centred rectangle a third of the view wide and high) with the rig's exact calibration
(issue 24):

- measuring: an operator clicks on the map, the page shows the server's numbers, and they are the
  block's known height, width and flat floor;
- managing: a result deleted from the Captures view comes back with Undo, a capture is renamed,
  calibrations are chosen, imported from an OpenCV file (a bad file is refused next to its field)
  and deleted with Undo; a capture's wrapped phase, modulation and frames are shown;
- the API page draws every route with no request beyond the console;
- input errors: an empty or refused exposure is a sentence under the field, which returns to the
  camera's value; fringe settings reach a second tab; the wizard's bad plane heights and counts
  are named under their fields;
- a calibration made by the wizard shows its planes, gamma curve and board detections.

With ``RIG_SCREENSHOTS=1`` the frames are 640x480 and the screenshots go to docs/console/ (as in
test_console_browser.py), else to a temporary folder.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from browser_harness import CHROMIUM, HEIGHT, WIDTH, playwright_api, shot
from console_client import served

from rig.config import load_config

BLOCK_MM = 25.0  # mock_devices.scenes.gauge_block's default height


@pytest.fixture(scope="module")
def rig(
    tmp_path_factory: pytest.TempPathFactory,
    simulated_rig_toml: Callable[..., str],
    exact_calibration: Callable[[Path, Path], Path],
) -> Iterator[dict[str, Any]]:
    """The console on the simulated rig looking at the gauge block, its calibration ``cal``; the block's pixel box."""
    from rig.console.app import create_app
    from rig.hardware.simulated import geometry_from_config, scene_height

    root = tmp_path_factory.mktemp("measure-browser")
    toml = root / "rig.toml"
    text = simulated_rig_toml((456, 570), (WIDTH, HEIGHT), 35.0).replace('"hemisphere"', '"gauge-block"')
    toml.write_text(text.replace("[scan]\n", "[scan]\nfetch_timeout_s = 0.5\nretries = 1\n"))
    exact_calibration(toml, root / "data" / "calibrations" / "cal")
    config = load_config(toml)
    geometry = geometry_from_config(config)
    rows, cols = np.nonzero(scene_height(config, "object", geometry) > BLOCK_MM / 2)
    with served(create_app(config, root / "data")) as port:
        yield {
            "url": f"http://127.0.0.1:{port}/",
            "box": (int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max())),
            "scale_on_top": geometry.pixel_mm * (geometry.l0_mm - BLOCK_MM) / geometry.l0_mm,
        }


@pytest.fixture(scope="module")
def chromium() -> Iterator[Any]:
    with playwright_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=["--use-gl=swiftshader"])
        yield browser
        browser.close()


@pytest.fixture
def browser_page(chromium: Any) -> Iterator[Any]:
    """A fresh page of its own."""
    context = chromium.new_context(viewport={"width": 1400, "height": 1100})
    yield context.new_page()
    context.close()


@pytest.fixture(scope="module")
def page(chromium: Any, rig: dict[str, Any]) -> Iterator[Any]:
    """A page that has scanned the block (no fringe-order correction) and shows its result."""
    context = chromium.new_context(viewport={"width": 1400, "height": 1100})
    page = context.new_page()
    page.goto(rig["url"])
    page.wait_for_function("document.querySelector('#scan-correction').options.length > 0")
    page.locator("#scan-correction").select_option("none")
    page.wait_for_function("document.querySelector('#calibration').value === 'cal'")
    page.get_by_test_id("scan-button").click()
    page.wait_for_function("document.querySelector('#view-result').dataset.final === 'true'", timeout=90_000)
    yield page
    context.close()


def click_map(page: Any, x: float, y: float) -> None:
    """Click the centre of map pixel (x, y)."""
    box = page.get_by_test_id("height-map").bounding_box()
    page.mouse.click(box["x"] + (x + 0.5) * box["width"] / WIDTH, box["y"] + (y + 0.5) * box["height"] / HEIGHT)


def measure(page: Any, tool: str, first: tuple[int, int], second: tuple[int, int]) -> dict[str, float]:
    """Choose ``tool``, click its two points on the map; the figures the page shows, by test id."""
    page.get_by_test_id("measure-tool").select_option(tool)
    before = finished(page)
    click_map(page, *first)
    click_map(page, *second)
    wait_finished(page, before)
    shown = page.eval_on_selector_all(
        "#measure-figures td[data-testid]", "cells => cells.map(c => [c.dataset.testid, c.dataset.value])"
    )
    return {key: float(value) for key, value in shown if value not in ("", "null")}


def picked(page: Any) -> list[int]:
    """The map pixels the clicks picked (the page writes them into its coordinate fields)."""
    return [int(page.get_by_test_id(f"measure-{f}").input_value()) for f in ("x0", "y0", "x1", "y1")]


def csv_download(page: Any) -> Any:
    """What the page's CSV link downloads."""
    return page.request.get(page.eval_on_selector("[data-testid=measure-csv]", "a => a.href"))


def finished(page: Any) -> int:
    """Measurements the page has finished (``data-count`` of the figures table)."""
    return int(page.eval_on_selector("#measure-figures", "t => Number(t.dataset.count || 0)"))


def wait_finished(page: Any, before: int) -> None:
    page.wait_for_function(f"Number(document.querySelector('#measure-figures').dataset.count || 0) > {before}")


def test_region_statistics_give_the_step_height(page: Any, rig: dict[str, Any]) -> None:
    x0, y0, x1, y1 = rig["box"]
    top = measure(page, "roi", (x0 + 5, y0 + 5), (x1 - 5, y1 - 5))
    floor = measure(page, "roi", (2, 2), (x0 - 5, y1))
    assert top["measure-mean"] - floor["measure-mean"] == pytest.approx(BLOCK_MM, abs=0.3)  # mm
    assert page.get_by_test_id("measure-mean").inner_text().endswith(" mm")
    corners = picked(page)
    assert np.abs(np.array(corners) - [2, 2, x0 - 5, y1]).max() <= 1  # the clicked pixels, to the pixel
    assert (
        page.get_by_test_id("measure-hint").inner_text()
        == f"roi on {page_result(page)} at {', '.join(map(str, corners))}"
    )


def test_plane_fit_shows_the_flatness_of_the_floor_and_the_height_above_it(page: Any, rig: dict[str, Any]) -> None:
    x0, y0, x1, y1 = rig["box"]
    spread = measure(page, "roi", (2, 2), (x0 - 5, y1))
    plane = measure(page, "plane", (2, 2), (x0 - 5, y1))
    # the floor is the exact, level reference plane: the fit leaves its noise, whose spread the region shows
    assert plane["measure-tilt"] < 0.5
    assert plane["measure-flatness"] == pytest.approx(spread["measure-peak-to-valley"], rel=0.05)
    assert plane["measure-rms"] == pytest.approx(spread["measure-std"], rel=0.02)
    page.wait_for_function("document.querySelector('#measure-plane-caption').textContent.includes('above the plane')")
    high = float(page.locator("#measure-plane-caption").inner_text().split("..")[1].split()[0])
    assert high == pytest.approx(BLOCK_MM, abs=1.0)  # the block is the highest thing above the floor's plane
    shot(page, "result-measure-plane", full_page=True)


def test_distance_across_the_block_is_its_width_and_across_its_edge_its_height(page: Any, rig: dict[str, Any]) -> None:
    x0, y0, x1, y1 = rig["box"]
    row = (y0 + y1) // 2
    across = measure(page, "distance", (x0 + 1, row), (x1 - 1, row))
    a, _, b, _ = picked(page)
    expected = (b - a) * rig["scale_on_top"]
    assert across["measure-lateral-distance"] == pytest.approx(expected, abs=rig["scale_on_top"]), (a, b, rig["box"])
    edge = measure(page, "distance", (x0 - WIDTH // 16, row), (x0 + WIDTH // 16, row))  # beyond any shadow
    assert edge.get("measure-rise") == pytest.approx(BLOCK_MM, abs=1.0), page.get_by_test_id(
        "measure-hint"
    ).inner_text()


def test_histogram_and_profile_are_drawn_and_exported_as_csv(page: Any, rig: dict[str, Any]) -> None:
    x0, y0, x1, y1 = rig["box"]
    page.get_by_test_id("measure-tool").select_option("histogram")
    page.get_by_test_id("measure-bins").fill("10")
    before = finished(page)
    page.get_by_test_id("measure-whole").click()
    wait_finished(page, before)
    page.get_by_test_id("measure-chart").locator(".main-svg").first.wait_for()
    counts = [int(r[2]) for r in list(csv.reader(io.StringIO(csv_download(page).text())))[1:]]
    block_share = (x1 - x0 + 1) * (y1 - y0 + 1) / (WIDTH * HEIGHT)
    assert sum(counts[-2:]) / sum(counts) == pytest.approx(block_share, rel=0.1)
    row = (y0 + y1) // 2
    profile = measure(page, "profile", (x0 - 20, row), (x1 + 20, row))
    assert profile["measure-max"] == pytest.approx(BLOCK_MM, abs=2.0) and abs(profile["measure-min"]) < 2.0
    page.get_by_test_id("measure-chart").locator(".main-svg").first.wait_for()
    reply = csv_download(page)
    assert reply.headers["content-type"].startswith("text/csv") and reply.text().startswith("col,row,distance_mm")
    shot(page, "result-measure-profile", full_page=True)


def test_a_point_off_the_map_is_refused_with_a_sentence(page: Any) -> None:
    page.get_by_test_id("measure-tool").select_option("distance")
    for field, value in (("x0", "3"), ("y0", "3"), ("x1", "5000"), ("y1", "3")):
        page.get_by_test_id(f"measure-{field}").fill(value)
    before = finished(page)
    page.get_by_test_id("measure-run").click()
    wait_finished(page, before)
    hint = page.get_by_test_id("measure-hint")
    expected = f"point 2 (5000, 3): outside the {WIDTH}x{HEIGHT} map; pick a pixel on the map"
    assert page.locator("#measure-figures tr").count() == 0 and hint.inner_text() == expected


def page_result(page: Any) -> str:
    return str(page.eval_on_selector("#view-result", "e => e.dataset.result"))


# --------------------------------------------------------------------------- managing data


def names_in(page: Any, list_id: str) -> list[str]:
    return list(page.eval_on_selector_all(f"#{list_id} li", "items => items.map(li => li.dataset.name)"))


def open_capture(page: Any) -> str:
    """The Captures view with the newest capture opened; the capture's name."""
    page.locator("nav button[data-view=captures]").click()
    first = page.locator("#capture-list li.managed").first
    first.wait_for()
    name = str(first.get_attribute("data-name"))
    first.click()
    page.wait_for_function(f"document.querySelector('#capture-title').textContent === '{name}'")
    return name


def open_capture_results(page: Any) -> str:
    """The Captures view with the scanned capture and its results shown; the capture's name."""
    name = open_capture(page)
    page.locator("#capture-results li.managed").first.wait_for()
    return name


def test_a_result_deleted_in_the_page_comes_back_with_undo(page: Any, rig: dict[str, Any]) -> None:
    capture = open_capture_results(page)
    result = names_in(page, "capture-results")[0]
    page.locator(f"#capture-results li[data-name='{result}'] [data-testid=delete]").click()
    page.get_by_test_id("notice").wait_for()
    assert "moved to the trash" in page.get_by_test_id("notice").inner_text()
    page.wait_for_function(f"!document.querySelector(\"#capture-results li[data-name='{result}']\")")
    assert page.request.get(rig["url"] + f"api/results/{result}").status == 404
    assert page.locator("#trash-list li").count() == 1
    shot(page, "captures-trash", full_page=True)
    page.get_by_test_id("undo").click()
    page.locator(f"#capture-results li[data-name='{result}']").wait_for()
    assert page.request.get(rig["url"] + f"api/results/{result}").status == 200
    page.wait_for_function("document.querySelectorAll('#trash-list li').length === 0")
    page.once("dialog", lambda dialog: dialog.accept("renamed-capture"))
    page.locator(f"#capture-list li[data-name='{capture}'] [data-testid=rename]").click()
    page.locator("#capture-list li[data-name='renamed-capture']").wait_for()
    assert (
        page.get_by_test_id("notice")
        .inner_text()
        .startswith(f"captures/{capture} renamed to renamed-capture; {result} still name {capture} in their report")
    )
    assert capture not in names_in(page, "capture-list")
    assert page.get_by_test_id("error").is_hidden(), page.get_by_test_id("error").inner_text()  # no stale name


def _opencv_file(path: Path) -> Path:
    """An OpenCV FileStorage stereo calibration (stereoCalibrate's K1 D1 K2 D2 R T) of a small rig."""
    import cv2

    from mock_devices.stereo_synth import calibration_fields, demo_rig

    truth = calibration_fields(demo_rig(WIDTH, HEIGHT, 456, 570))
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    keys = ("camera_matrix", "distortion", "projector_matrix", "projector_distortion", "rotation", "translation_mm")
    for node, key in zip(("K1", "D1", "K2", "D2", "R", "T"), keys):
        storage.write(node, np.asarray(truth[key], dtype=np.float64))
    storage.release()
    return path


def test_calibrations_are_chosen_imported_and_deleted_in_the_page(page: Any, tmp_path: Path) -> None:
    page.locator("nav button[data-view=calibration]").click()
    page.wait_for_function("document.querySelector('#calibrations-list').dataset.active === 'cal'")
    page.locator("#calibrations-list li[data-name=''] [data-testid=use]").click()
    page.wait_for_function("document.querySelector('#calibrations-list').dataset.active === ''")
    assert page.locator("#calibration").input_value() == ""  # the live view's choice follows
    page.locator("#calibrations-list li[data-name='cal'] [data-testid=use]").click()
    page.wait_for_function("document.querySelector('#calibration').value === 'cal'")
    # import: a missing name, a broken file, then the real one
    page.get_by_test_id("import-file").set_input_files(str(_opencv_file(tmp_path / "caliInfo.yml")))
    page.get_by_test_id("import-button").click()
    assert page.get_by_test_id("import-name-error").inner_text().startswith("give the calibration a name")
    broken = tmp_path / "broken.yml"
    broken.write_text("%YAML:1.0\nK1: 1\n")
    page.get_by_test_id("import-file").set_input_files(str(broken))
    page.get_by_test_id("import-name").fill("slm")
    page.get_by_test_id("import-button").click()
    page.get_by_test_id("import-file-error").wait_for()
    assert page.get_by_test_id("import-file-error").inner_text().startswith("broken.yml: ")
    assert page.get_by_test_id("import-name-error").is_hidden()
    page.get_by_test_id("import-file").set_input_files(str(tmp_path / "caliInfo.yml"))
    page.get_by_test_id("import-button").click()
    page.locator("#calibrations-list li[data-name='slm']").wait_for()
    assert page.get_by_test_id("import-file-error").is_hidden()
    shot(page, "calibration-manage", full_page=True)
    page.locator("#calibrations-list li[data-name='slm'] [data-testid=delete]").click()
    page.wait_for_function("!document.querySelector(\"#calibrations-list li[data-name='slm']\")")
    page.get_by_test_id("undo").click()
    page.locator("#calibrations-list li[data-name='slm']").wait_for()


# --------------------------------------------------------------------------- API page


def test_the_api_page_lists_every_route_offline(browser_page: Any, rig: dict[str, Any]) -> None:
    """Requests to any other host are aborted: the page draws every route of openapi.json regardless."""
    elsewhere: list[str] = []

    def only_the_console(route: Any) -> None:
        if route.request.url.startswith(rig["url"]):
            route.continue_()
        else:
            elsewhere.append(route.request.url)
            route.abort()

    browser_page.route("**/*", only_the_console)
    browser_page.goto(rig["url"] + "api/docs")
    browser_page.wait_for_function("document.querySelector('#api-routes').dataset.routes !== undefined")
    spec = browser_page.request.get(rig["url"] + "api/openapi.json").json()
    operations = sum(len(ops) for ops in spec["paths"].values())
    assert int(browser_page.get_by_test_id("api-routes").get_attribute("data-routes")) == operations
    browser_page.locator("details[data-route='GET /api/results/{name}/measure/plane'] summary").click()
    assert (
        "flatness" in browser_page.locator("details[data-route='GET /api/results/{name}/measure/plane']").inner_text()
    )
    assert elsewhere == []
    shot(browser_page, "api-docs", full_page=True)


# --------------------------------------------------------------------------- input errors


def field_error(page: Any, field: str) -> str:
    """The sentence shown under a field (empty when none)."""
    line = page.get_by_test_id(f"{field}-error")
    return str(line.inner_text()) if line.count() and line.is_visible() else ""


def test_exposure_errors_are_sentences_and_the_field_keeps_the_cameras_value(page: Any, rig: dict[str, Any]) -> None:
    page.locator("nav button[data-view=live]").click()
    exposure = page.get_by_test_id("exposure")
    actual = page.request.get(rig["url"] + "api/exposure").json()["exposure_us"]
    exposure.fill("")
    exposure.dispatch_event("change")
    page.wait_for_function("document.querySelector('[data-testid=exposure-error]')?.hidden === false")
    assert field_error(page, "exposure").startswith("Enter an exposure time in microseconds")
    assert "found" not in field_error(page, "exposure")
    page.wait_for_function(f"document.querySelector('#exposure').value === '{actual:g}'")
    exposure.fill("0")
    exposure.dispatch_event("change")
    page.wait_for_function(
        "document.querySelector('[data-testid=exposure-error]').textContent.startsWith('exposure_us')"
    )
    page.wait_for_function(f"document.querySelector('#exposure').value === '{actual:g}'")  # the camera's value
    assert page.request.get(rig["url"] + "api/exposure").json()["exposure_us"] == actual
    assert page.get_by_test_id("error").is_hidden()
    exposure.fill(f"{actual:g}")
    exposure.dispatch_event("change")
    page.wait_for_function("document.querySelector('[data-testid=exposure-error]').hidden")


def test_fringe_settings_reach_a_second_tab(page: Any, browser_page: Any, rig: dict[str, Any]) -> None:
    browser_page.goto(rig["url"])
    browser_page.wait_for_function("document.querySelector('#fringe-frequency').value !== ''")
    page.locator("nav button[data-view=live]").click()
    page.get_by_test_id("projector-pattern").select_option("fringe")
    page.get_by_test_id("fringe-frequency").fill("12")
    page.get_by_test_id("fringe-frequency").dispatch_event("change")
    browser_page.wait_for_function("document.querySelector('#fringe-frequency').value === '12'")
    assert browser_page.get_by_test_id("projector-pattern").input_value() == "fringe"


def test_the_wizards_fields_say_what_is_wrong_next_to_them(page: Any) -> None:
    page.locator("nav button[data-view=calibration]").click()
    heights = page.locator("#cal-heights")
    heights.fill("25, abc, 100")
    page.get_by_test_id("calibration-start").click()
    assert field_error(page, "cal-heights") == (
        'Entry 2 ("abc") is not a number; enter the plane heights in mm above the reference plane, '
        "separated by commas (e.g. 25, 50, 100)."
    )
    heights.fill("25, 25, 50")
    page.get_by_test_id("calibration-start").click()
    page.wait_for_function("document.querySelector('[data-testid=cal-heights-error]').textContent.includes('distinct')")
    page.locator("#cal-views").fill("")
    heights.fill("25, 50, 100")
    page.get_by_test_id("calibration-start").click()
    assert field_error(page, "cal-views").startswith("Enter how many tilted board views")
    assert field_error(page, "cal-heights") == ""
    page.locator("#cal-views").fill("9999")
    page.get_by_test_id("calibration-start").click()
    page.wait_for_function(
        "document.querySelector('[data-testid=cal-views-error]')?.textContent.startsWith('board_views:')"
    )
    assert "{" not in field_error(page, "cal-views")  # a sentence, not a validation record
    page.locator("#cal-views").fill("6")
    heights.fill("25, 50, 100, 150")


def test_a_captures_wrapped_phase_and_frames_are_shown(page: Any) -> None:
    open_capture(page)
    page.locator("#capture-look summary").click()
    page.wait_for_function("document.querySelector('#look-image').dataset.shows === 'groups/0/phase'")
    labels = page.eval_on_selector_all("#look-what option", "o => o.map(x => x.textContent)")
    assert labels[:2] == ["wrapped phase: x, 1 fringes, 4 steps", "modulation: x, 1 fringes"]
    page.get_by_test_id("look-what").select_option("groups/2/modulation")
    page.wait_for_function("document.querySelector('#look-image').dataset.shows === 'groups/2/modulation'")
    assert page.get_by_test_id("look-note").inner_text().endswith("grey levels (turbo)")
    page.get_by_test_id("look-what").select_option("frames/0")
    page.wait_for_function(
        "(() => { const i = document.querySelector('#look-image'); return i.dataset.shows === 'frames/0' && i.complete && i.naturalWidth > 0; })()"
    )
    assert page.eval_on_selector("#look-image", "i => [i.naturalWidth, i.naturalHeight]") == [WIDTH, HEIGHT]
    shot(page, "captures-look", full_page=True)


# --------------------------------------------------------------------------- calibration you can see


def test_a_calibration_shows_its_planes_gamma_and_board_detections(page: Any) -> None:
    """The wizard calibrates the simulated rig (projector gamma 1) with a gamma ramp and two board
    views; its figures show the planes, a gamma near 1, and each board view's corners and residuals."""
    page.locator("nav button[data-view=calibration]").click()
    page.locator("#cal-name").fill("wiz")
    page.locator("#cal-views").fill("2")
    page.get_by_test_id("calibration-gamma").fill("8")
    page.get_by_test_id("calibration-start").click()
    page.wait_for_function("document.querySelector('#cal-result').dataset.done === 'true'", timeout=180_000)
    page.locator("#calibrations-list li[data-name='wiz'] [data-testid=show]").click()
    page.wait_for_function("document.querySelector('#calfig').dataset.calibration === 'wiz'")
    page.get_by_test_id("calibration-planes").locator(".main-svg").first.wait_for()
    page.get_by_test_id("calibration-gamma-curve").locator(".main-svg").first.wait_for()
    assert float(page.get_by_test_id("calibration-gamma-curve").get_attribute("data-gamma")) == pytest.approx(
        1.0, abs=0.1
    )
    views = page.get_by_test_id("calibration-boards").locator("figure")
    assert views.count() == 3  # the board on the plane and two tilted views
    page.wait_for_function(
        "[...document.querySelectorAll('#calfig-boards figure')].every(f => f.dataset.rms !== undefined)"
    )
    for rms in page.eval_on_selector_all("#calfig-boards figure", "fs => fs.map(f => f.dataset.rms)"):
        assert 0 <= float(rms) < 0.5  # px: the simulated views are sharp and the fit is exact
    shot(page, "calibration-figures", full_page=True)
    page.locator("#calibrations-list li[data-name='cal'] [data-testid=use]").click()
