"""Benchmark: the console on the simulated rig, in its session and in the real page (headless Chromium).

Session (no browser):

- live view: frames per second the console session publishes (software trigger, figures,
  modulation map under a fringe, JPEG) with one page watching, at ``--live-size``;
- scan to result: seconds from the scan's last frame to the result being published to the page
  (processed from the frames held in memory; without fringe-order correction, then with the
  default ``auto`` and its quick result first), at ``--scan-size``, beside the peer:
  :func:`rig.api.process` of the same capture from disk with the same options, timed in the same
  run (``console / peer``: below 1 where the console's processing overlaps the capture's writing).

Page (``--browser``, the default when Playwright and Debian's ``/usr/bin/chromium`` are there): the
console served by uvicorn as ``rig console`` serves it, driven by Playwright in headless Chromium
(software WebGL) at a 1024x768 window, with the default correction (``auto``) and an exact
calibration, as an operator sees it (issue 24's table):

- Scan click -> last frame, -> quick map on screen, -> corrected map on screen, -> corrected 3-D
  view on screen (camera ``--scan-size``, the page's own clock);
- 3-D draw time of the full-resolution result (upload and first frame of the point cloud);
- live view frames per second the page draws, per view (camera and modulation, fringe shown);
- live 3-D at ``--live-size``: sets per second and latency from a set's last frame to its points
  drawn, as the page shows them.

Each figure: median and min - max over ``--runs`` runs (live figures: over ``--live-seconds``);
the header gives CPU model and load average.

    python benchmarks/bench_console.py [--runs 7] [--live-size 640x480] [--scan-size 1024x768] [--no-browser]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.measure import cpu_description, load_line  # noqa: E402
from rig import api  # noqa: E402
from rig.config import parse_config  # noqa: E402
from rig.console.datadir import DataDir  # noqa: E402
from rig.console.devices import ProjectorSetting  # noqa: E402
from rig.console.live_view import LIVE_FPS  # noqa: E402
from rig.console.session import ConsoleSession  # noqa: E402
from rig.pipeline.plan import ProcessOptions  # noqa: E402


def size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


class Recorder:
    """Collects what the session publishes."""

    def __init__(self) -> None:
        self.frames: list[float] = []
        self.results: list[dict[str, Any]] = []
        self.event = threading.Condition()

    def __call__(self, message: dict[str, Any], image: bytes | None) -> None:
        with self.event:
            if message["type"] == "frame":
                self.frames.append(time.monotonic())
            elif message["type"] == "result":
                self.results.append(message)
            self.event.notify_all()


def calibrate(session: ConsoleSession, config: Any) -> None:
    """The simulated rig's exact geometry as calibration "cal", with a reference scan."""
    from calibration.store import write_calibration
    from rig.acquisition.scan import scan
    from rig.hardware.simulated import geometry_from_config
    from rig.hardware.synthesis import exact_calibration

    cal = session.data.root / "calibrations" / "cal"
    scan(config, cal / "reference", scene="reference")
    write_calibration(cal, exact_calibration(geometry_from_config(config)))
    session.set_calibration("cal")


def live_fps(width: int, height: int, seconds: float) -> float:
    config = parse_config({"camera": {"size": [width, height]}})
    recorder = Recorder()
    with tempfile.TemporaryDirectory() as tmp:
        session = ConsoleSession(config, DataDir(tmp), recorder, live_fps=1000.0)
        session.start()
        try:
            session.set_projector(ProjectorSetting("fringe", 16.0))
            session.watch(1)
            time.sleep(1.0)  # warm up
            start, count0 = time.monotonic(), len(recorder.frames)
            time.sleep(seconds)
            fps = (len(recorder.frames) - count0) / (time.monotonic() - start)
            session.watch(-1)
        finally:
            session.close()
    return fps


def scan_to_result(width: int, height: int, runs: int, correction: str) -> tuple[list[float], list[float], list[float]]:
    """Per run: last frame -> quick result and -> final result published (s), and the peer's seconds."""
    config = parse_config({"camera": {"size": [width, height]}})
    recorder = Recorder()
    quick_s, final_s, peer_s = [], [], []
    options = ProcessOptions(correction=correction)
    with tempfile.TemporaryDirectory() as tmp:
        session = ConsoleSession(config, DataDir(tmp), recorder)
        session.start()
        try:
            calibrate(session, config)
            time.sleep(5.0)  # the console prepares the calibration's reference plane meanwhile
            for run in range(runs):
                job = session.scan(name=f"run-{run}", options=options)
                with recorder.event:
                    recorder.event.wait_for(
                        lambda job=job: any(r["job"] == job.id and r["final"] for r in recorder.results), timeout=120
                    )
                published = {r["final"]: float(r["since_last_frame_s"]) for r in recorder.results if r["job"] == job.id}
                quick_s.append(published.get(False, published[True]))
                final_s.append(published[True])
                while job.state == "running":
                    time.sleep(0.05)
                capture = session.data.path("captures", job.name)
                started = time.perf_counter()
                api.process(capture, session.data.path("calibrations", "cal"), options)
                peer_s.append(time.perf_counter() - started)
        finally:
            session.close()
    return quick_s, final_s, peer_s


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):.3f} s ({min(values):.3f} - {max(values):.3f})"


@contextlib.contextmanager
def served(config: Any, root: Path) -> Iterator[str]:
    """The console of ``config`` (data in ROOT/data, with the exact calibration "cal") under uvicorn; its URL."""
    import uvicorn

    from benchmarks.dask_cluster import free_port
    from calibration.store import write_calibration
    from rig.acquisition.scan import scan
    from rig.console.app import create_app
    from rig.console.server import server_config
    from rig.hardware.simulated import geometry_from_config
    from rig.hardware.synthesis import exact_calibration

    cal = root / "data" / "calibrations" / "cal"
    scan(config, cal / "reference", scene="reference")
    write_calibration(cal, exact_calibration(geometry_from_config(config)))
    port = free_port()
    server = uvicorn.Server(server_config(create_app(config, root / "data"), "127.0.0.1", port))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started:
        if time.monotonic() > deadline:
            raise SystemExit("bench_console: the console did not start within 60 s")
        time.sleep(0.05)
    try:
        yield f"http://127.0.0.1:{port}/"
    finally:
        server.should_exit = True
        thread.join(timeout=30)


@contextlib.contextmanager
def browser_page(url: str) -> Iterator[Any]:
    """A 1024x768 page of headless Chromium (software WebGL) on ``url``, live frames arriving."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        chromium = p.chromium.launch(
            executable_path=CHROMIUM,
            headless=True,
            args=["--use-gl=swiftshader", "--enable-webgl", "--ignore-gpu-blocklist"],
        )
        try:
            page = chromium.new_context(viewport={"width": 1024, "height": 768}).new_page()
            page.goto(url)
            page.wait_for_function(
                "Number(document.querySelector('#live-view').dataset.shown || 0) > 2", timeout=60_000
            )
            yield page
        finally:
            chromium.close()


PAGE_TIMINGS = """() => { const v = document.querySelector('#view-result').dataset;
    const live = document.querySelector('#view-live').dataset;
    return [Number(live.clickToLastFrameMs), Number(v.quickMapSinceLastFrameMs), Number(v.mapSinceLastFrameMs),
            Number(v.sinceLastFrameMs), Number(v.drawMs), Number(v.points), Number(v.serverQuickMs), Number(v.serverFinalMs)]; }"""
RESET_TIMINGS = """() => { for (const k of ['quickMapSinceLastFrameMs', 'mapSinceLastFrameMs', 'sinceLastFrameMs', 'drawMs'])
    delete document.querySelector('#view-result').dataset[k];
    delete document.querySelector('#view-live').dataset.clickToLastFrameMs; }"""


def page_scans(page: Any, runs: int) -> list[list[float]]:
    """Per run (ms): click -> last frame; last frame -> quick map, corrected map, corrected 3-D; 3-D draw;
    points; last frame -> quick and corrected result sent by the server."""
    rows = []
    for _ in range(runs):
        page.locator("nav button[data-view=live]").click()
        page.wait_for_function("!document.querySelector('[data-testid=scan-button]').disabled", timeout=120_000)
        previous = page.eval_on_selector("#view-result", "v => v.dataset.result || ''")
        page.evaluate(RESET_TIMINGS)
        page.get_by_test_id("scan-button").click()
        page.wait_for_function(
            f"""(() => {{ const v = document.querySelector('#view-result').dataset;
            return v.final === 'true' && v.result !== '{previous}' && v.sinceLastFrameMs; }})()""",
            timeout=120_000,
        )
        rows.append(page.evaluate(PAGE_TIMINGS))
        page.get_by_test_id("downloads").locator("a").first.wait_for(timeout=60_000)  # files written: rig idle
    return rows


def page_live_fps(page: Any, seconds: float) -> dict[str, float]:
    """Frames per second the page draws in each live view, a fringe shown."""
    page.locator("nav button[data-view=live]").click()
    page.get_by_test_id("projector-pattern").select_option("fringe")
    rates = {}
    for view in ("camera", "modulation"):
        page.get_by_test_id("live-mode").select_option(view)
        time.sleep(1.0)
        start = page.eval_on_selector("#live-view", "c => Number(c.dataset.shown || 0)")
        time.sleep(seconds)
        rates[view] = (page.eval_on_selector("#live-view", "c => Number(c.dataset.shown || 0)") - start) / seconds
    page.get_by_test_id("live-mode").select_option("camera")
    return rates


def page_live_3d(page: Any, seconds: float) -> tuple[float, list[float]]:
    """Live 3-D sets drawn per second by the page, and the latencies it showed (ms)."""
    page.get_by_test_id("live3d-toggle").check()
    page.wait_for_function("Number(document.querySelector('#live3d-view').dataset.shown || 0) >= 3", timeout=60_000)
    start = page.eval_on_selector("#live3d-view", "c => Number(c.dataset.shown)")
    latencies: list[float] = []
    began = time.monotonic()
    while time.monotonic() - began < seconds:
        latencies.append(float(page.eval_on_selector("#live3d-view", "c => Number(c.dataset.latencyMs)")))
        time.sleep(0.25)
    rate = (page.eval_on_selector("#live3d-view", "c => Number(c.dataset.shown)") - start) / (time.monotonic() - began)
    page.get_by_test_id("live3d-toggle").uncheck()
    return rate, latencies


def browser_bench(args: argparse.Namespace) -> None:
    runs_ms: list[list[float]] = [[], [], [], [], [], [], [], []]
    with tempfile.TemporaryDirectory() as tmp:
        config = parse_config({"camera": {"size": list(args.scan_size)}})
        with served(config, Path(tmp) / "scan") as url, browser_page(url) as page:
            for row in page_scans(page, args.runs):
                for column, value in zip(runs_ms, row):
                    column.append(value)
            live = page_live_fps(page, args.live_seconds)
        config = parse_config({"camera": {"size": list(args.live_size)}})
        with served(config, Path(tmp) / "live") as url, browser_page(url) as page:
            rate, latencies = page_live_3d(page, args.live_seconds)
    click, quick, final_map, final_3d, draw, points, server_quick, server_final = runs_ms
    w, h = args.scan_size
    print(f"page (headless Chromium, 1024x768 window), camera {w}x{h}, correction auto, {args.runs} runs:")
    print(f"  scan click -> last frame:           {spread_ms(click)}")
    print(f"  last frame -> quick map on screen:  {spread_ms(quick)}")
    print(f"  last frame -> corrected map:        {spread_ms(final_map)}")
    print(
        f"    (of which the server, last frame -> result sent: quick {spread_ms(server_quick)}, corrected {spread_ms(server_final)})"
    )
    print(f"  last frame -> corrected 3-D view:   {spread_ms(final_3d)}")
    print(f"  scan click -> corrected 3-D view:   {spread_ms([c + f for c, f in zip(click, final_3d)])}")
    print(f"  3-D view draw ({int(statistics.median(points))} points):  {spread_ms(draw)}")
    for view, fps in live.items():
        print(f"  live view {w}x{h}, {view} view (fringe shown): {fps:.1f} fps drawn by the page")
    lw, lh = args.live_size
    print(f"  live 3-D {lw}x{lh}: {rate:.1f} sets/s drawn, latency (last frame -> drawn) {spread_ms(latencies)}")


def spread_ms(values: list[float]) -> str:
    return f"{statistics.median(values):.0f} ms ({min(values):.0f} - {max(values):.0f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--live-size", type=size, default=(640, 480))
    parser.add_argument("--scan-size", type=size, default=(1024, 768))
    parser.add_argument("--live-seconds", type=float, default=5.0)
    parser.add_argument("--no-browser", dest="browser", action="store_false", help="session figures only")
    parser.add_argument("--no-session", dest="session", action="store_false", help="page figures only")
    args = parser.parse_args()
    for line in cpu_description():
        print(line)
    load_before = os.getloadavg()
    if args.session:
        session_bench(args)
    if args.browser:
        if CHROMIUM is None or not has_playwright():
            print("page figures skipped: no chromium or no playwright (pip install -e '.[test]')")
        else:
            browser_bench(args)
    print(load_line(load_before, os.getloadavg()))


def session_bench(args: argparse.Namespace) -> None:
    fps = live_fps(*args.live_size, args.live_seconds)
    print(
        f"live view {args.live_size[0]}x{args.live_size[1]}, fringe shown (modulation map computed): {fps:.1f} fps "
        f"(uncapped; the console caps it at {LIVE_FPS:g})"
    )
    w, h = args.scan_size
    for correction in ("none", "auto"):
        quick_s, final_s, peer_s = scan_to_result(w, h, args.runs, correction)
        ratios = [c / p for c, p in zip(final_s, peer_s)]
        print(f"scan to result published, {w}x{h}, correction {correction}, {args.runs} runs:")
        if correction != "none":
            print(f"  console (last frame -> quick result): {spread(quick_s)}")
        print(f"  console (last frame -> result):        {spread(final_s)}")
        print(f"  peer rig.api.process from disk:        {spread(peer_s)}")
        print(f"  console / peer: {statistics.median(ratios):.2f} ({min(ratios):.2f} - {max(ratios):.2f})")


def has_playwright() -> bool:
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return False
    return True


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


if __name__ == "__main__":
    main()
