"""The console's ASGI application: the page, the JSON API under /api/, and the event websocket.

:func:`create_app` builds it around one :class:`rig.console.session.ConsoleSession`; the routes
only translate HTTP to session calls (which call the services). FastAPI serves the OpenAPI
document at ``/api/openapi.json`` and its explorer at ``/api/docs``.

Access rules: with a ``token`` every request needs it (``?token=`` once — the page then keeps it
in a cookie —, the cookie, or ``Authorization: Bearer``); a request from a page of another origin
is refused (a web page elsewhere cannot drive the rig through the operator's browser); every name
a request carries is resolved inside the data directory (:class:`rig.console.datadir.DataDir`).
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
import uuid
from collections.abc import AsyncIterator, MutableMapping
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

from fastapi import FastAPI, HTTPException, Query, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool
from starlette.types import ASGIApp, Receive, Scope, Send

from rig.config import RigConfig
from rig.console.datadir import DataDir
from rig.console.results import colour_bar_png, difference, difference_png
from rig.console.session import Busy, ConsoleSession, ProjectorSetting
from rig.errors import RigError
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions

log = logging.getLogger(__name__)

STATIC = Path(__file__).resolve().parent / "static"
TOKEN_COOKIE = "rig_console_token"
CLIENT_HEADER = "x-console-client"
DOWNLOADS = {
    "points.ply": "application/octet-stream",
    "height.npy": "application/octet-stream",
    "phase.npy": "application/octet-stream",
    "report.json": "application/json",
    "preview.png": "image/png",
}


# ------------------------------------------------------------------ request bodies


class ExposureBody(BaseModel):
    exposure_us: float | None = Field(None, description="exposure time in microseconds")
    gain: float | None = Field(None, description="camera gain (the backend's unit)")


class ProjectorBody(BaseModel):
    pattern: str = Field("black", description="black, white, fringe or grid (alignment: lines and a centre crosshair)")
    frequency: float = Field(8.0, description="fringes across the projector (fringe)")
    phase_deg: float = Field(0.0, description="fringe phase in degrees")
    axis: str = Field("x", description="x: fringes vary along the projector's width")
    pitch_px: int = Field(64, description="grid line spacing in projector pixels (grid)")


class LiveBody(BaseModel):
    overlay: bool | None = Field(None, description="saturated pixels in red")
    view: str | None = Field(None, description="camera or modulation (while a fringe is shown)")


class OptionsBody(BaseModel):
    unwrap: str = "auto"
    denoise: str = "none"
    correction: str = DEFAULT_CORRECTION

    def options(self) -> ProcessOptions:
        return ProcessOptions(unwrap=self.unwrap, denoise=self.denoise, correction=self.correction)


class ScanBody(BaseModel):
    name: str | None = Field(None, description="capture name in DATA/captures (default scan-<time>)")
    scene: str = Field("object", description="simulated rig only: object, reference, plane-at-<h>mm or a scene name")
    process: bool = Field(True, description="process the capture with the chosen calibration when acquired")
    options: OptionsBody = Field(default_factory=OptionsBody)


class ProcessBody(BaseModel):
    capture: str = Field(..., description="capture name in DATA/captures")
    name: str | None = Field(None, description="result name in DATA/results (default <capture>-<correction>-<time>)")
    options: OptionsBody = Field(default_factory=OptionsBody)


class CalibrationBody(BaseModel):
    name: str | None = Field(None, description="calibration name in DATA/calibrations; null: none (phase only)")


class CalibrateBody(BaseModel):
    name: str | None = Field(None, description="calibration name in DATA/calibrations (default cal-<time>)")
    heights_mm: list[float] = Field([25.0, 50.0, 100.0, 150.0], description="plane heights above the reference plane")
    board_views: int = Field(6, description="tilted board views for the camera intrinsics (0: pixel size only)")
    model: str = Field("reference-plane", description="height model: reference-plane, polynomial (stereo: real rig)")
    gamma_levels: int = Field(0, description="projector gamma ramp of this many flat levels first (0: none, else >= 5)")


class FaultBody(BaseModel):
    fault: str = Field(..., description="camera-gone or trigger-timeout")


# ------------------------------------------------------------------ websocket fan-out


class Hub:
    """Delivers session messages to every connected page; live frames are dropped for slow pages."""

    def __init__(self) -> None:
        self.loop: asyncio.AbstractEventLoop | None = None
        self.clients: dict[str, asyncio.Queue[tuple[dict[str, Any], bytes | None]]] = {}
        self.frame_pending: dict[str, bool] = {}

    def publish(self, message: dict[str, Any], image: bytes | None = None) -> None:
        """Thread-safe: queue ``message`` (and its image) for every client."""
        loop = self.loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # the loop is shutting down
            loop.call_soon_threadsafe(self._deliver, message, image)

    def _deliver(self, message: dict[str, Any], image: bytes | None) -> None:
        for client, q in self.clients.items():
            if image is not None:
                if self.frame_pending.get(client):
                    continue
                self.frame_pending[client] = True
            with contextlib.suppress(asyncio.QueueFull):
                q.put_nowait((message, image))


# ------------------------------------------------------------------ access control


class AccessMiddleware:
    """Token check (when a token is set) and same-origin check, for HTTP and websocket requests."""

    def __init__(self, app: ASGIApp, token: str | None) -> None:
        self.app = app
        self.token = token

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        origin = headers.get("origin")
        foreign = bool(origin) and origin != "null" and urlsplit(origin).netloc != headers.get("host", "")
        if foreign and (scope["type"] == "websocket" or scope.get("method") not in ("GET", "HEAD")):
            await self._refuse(scope, receive, send, 403, f"origin {origin} is not this console")
            return
        if self.token is not None:
            query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
            given = [*query.get("token", [])]
            cookie = headers.get("cookie", "")
            for part in cookie.split(";"):
                key, _, value = part.strip().partition("=")
                if key == TOKEN_COOKIE:
                    given.append(value)
            auth = headers.get("authorization", "")
            if auth.lower().startswith("bearer "):
                given.append(auth[7:].strip())
            if not any(hmac.compare_digest(g.encode(), self.token.encode()) for g in given):
                await self._refuse(scope, receive, send, 401, "access token required: open the URL the console printed")
                return
            if query.get("token") and scope["type"] == "http":
                send = self._with_cookie(send)
        await self.app(scope, receive, send)

    def _with_cookie(self, send: Send) -> Send:
        cookie = f"{TOKEN_COOKIE}={self.token}; Path=/; HttpOnly; SameSite=Strict".encode("latin-1")

        async def wrapped(message: MutableMapping[str, Any]) -> None:
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", []), (b"set-cookie", cookie)]}
            await send(message)

        return wrapped

    async def _refuse(self, scope: Scope, receive: Receive, send: Send, status: int, text: str) -> None:
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1008, "reason": text})
            return
        response = JSONResponse({"error": text}, status_code=status)
        await response(scope, receive, send)


# ------------------------------------------------------------------ the app


def create_app(
    config: RigConfig,
    data_dir: str | Path,
    token: str | None = None,
    fault_injection: bool = False,
    live_fps: float = 20.0,
) -> FastAPI:
    """The console for the rig of ``config``, keeping its files in ``data_dir``.

    ``token``: required on every request when set (the command sets one when binding beyond
    127.0.0.1). ``fault_injection``: enable ``POST /api/simulation/fault`` (tests, fault drills).
    The rig is opened when the app starts and closed when it stops.
    """
    data = DataDir(data_dir)
    hub = Hub()
    session = ConsoleSession(config, data, hub.publish, fault_injection=fault_injection, live_fps=live_fps)

    @contextlib.asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        hub.loop = asyncio.get_running_loop()
        await run_in_threadpool(session.start)
        try:
            yield
        finally:
            await run_in_threadpool(session.close)

    app = FastAPI(
        title="fpp-rig console",
        description="Run the scanner: live view, exposure, projector, scan, results, captures, calibration.",
        version="1",
        lifespan=lifespan,
        openapi_url="/api/openapi.json",
        docs_url="/api/docs",
        redoc_url=None,
    )
    app.state.session = session
    app.state.hub = hub

    @app.exception_handler(RigError)
    async def rig_error(_: Request, exc: RigError) -> JSONResponse:
        status = 409 if isinstance(exc, Busy) else 400
        return JSONResponse({"error": str(exc)}, status_code=status)

    @app.exception_handler(FileNotFoundError)
    async def not_found(_: Request, exc: FileNotFoundError) -> JSONResponse:
        return JSONResponse({"error": str(exc)}, status_code=404)

    def client_of(request: Request) -> str | None:
        return request.headers.get(CLIENT_HEADER)

    # -- state
    @app.get("/api/status", tags=["rig"], summary="what the rig is doing, its settings and devices")
    async def status() -> dict[str, Any]:
        return session.status()

    @app.get("/api/devices", tags=["rig"], summary="each device's backend, state and the last device error")
    async def devices() -> dict[str, Any]:
        return {"devices": session.devices(), "error": session.device_error}

    @app.put("/api/exposure", tags=["rig"], summary="camera exposure (us) and gain")
    async def exposure(body: ExposureBody) -> dict[str, Any]:
        return await run_in_threadpool(session.set_exposure, body.exposure_us, body.gain)

    @app.get("/api/exposure", tags=["rig"])
    async def get_exposure() -> dict[str, Any]:
        return {"exposure_us": session.exposure_us, "gain": session.gain}

    @app.put("/api/projector", tags=["rig"], summary="what the projector shows between scans")
    async def projector(body: ProjectorBody) -> dict[str, Any]:
        setting = ProjectorSetting(body.pattern, body.frequency, body.phase_deg, body.axis, body.pitch_px)
        return await run_in_threadpool(session.set_projector, setting)

    @app.get("/api/projector", tags=["rig"])
    async def get_projector() -> dict[str, Any]:
        return session.projector.__dict__

    @app.put("/api/live", tags=["rig"], summary="live view drawing: saturation overlay, camera or modulation map")
    async def live(body: LiveBody) -> dict[str, Any]:
        return session.set_live(body.overlay, body.view)

    # -- acquisition and processing
    @app.post(
        "/api/scan",
        tags=["scan"],
        status_code=202,
        summary="start a scan (409 while another acquisition runs); progress on the websocket",
    )
    async def scan(body: ScanBody, request: Request) -> dict[str, Any]:
        job = session.scan(body.name, body.scene, body.process, body.options.options(), client_of(request))
        return {"job": job.as_dict()}

    @app.post("/api/stop", tags=["scan"], summary="cancel a running job (default: all)")
    async def stop(job: str | None = None) -> dict[str, Any]:
        return {"stopped": session.stop(job)}

    @app.get("/api/jobs/{job_id}", tags=["scan"])
    async def get_job(job_id: str) -> dict[str, Any]:
        if job_id not in session.jobs:
            raise HTTPException(404, f"job {job_id!r}: unknown")
        return session.jobs[job_id].as_dict()

    @app.post("/api/process", tags=["results"], status_code=202, summary="process a capture with other options")
    async def process(body: ProcessBody, request: Request) -> dict[str, Any]:
        job = session.process(body.capture, body.options.options(), body.name, client_of(request))
        return {"job": job.as_dict()}

    # -- data
    @app.get("/api/captures", tags=["data"])
    def captures() -> dict[str, Any]:
        from rig.api import load_capture

        rows = []
        for name in data.names("captures"):
            try:
                capture = load_capture(data.path("captures", name))
                rows.append(
                    {
                        "name": name,
                        "scene": capture.scene,
                        "width": capture.width,
                        "height": capture.height,
                        "frames": len(capture.frames),
                        "created": capture.manifest.get("created_utc"),
                    }
                )
            except RigError as exc:
                rows.append({"name": name, "complete": False, "error": str(exc)})
        return {"captures": rows}

    @app.get("/api/captures/{name}", tags=["data"])
    def capture(name: str) -> dict[str, Any]:
        from rig.api import load_capture

        loaded = load_capture(data.existing("captures", name))
        results = [r for r in data.names("results") if _result_capture(data, r) == name]
        return {"name": name, "manifest": loaded.manifest, "results": results}

    @app.get("/api/results", tags=["data"])
    def results() -> dict[str, Any]:
        return {"results": [{"name": name, "capture": _result_capture(data, name)} for name in data.names("results")]}

    @app.get("/api/results/{name}", tags=["data"], summary="a result's key figures")
    async def result(name: str) -> dict[str, Any]:
        return (await run_in_threadpool(session.result, name)).summary()

    @app.get("/api/results/{name}/map.png", tags=["data"], summary="colour-mapped height (or phase)")
    async def result_png(name: str) -> Response:
        view = await run_in_threadpool(session.result, name)
        return Response(await run_in_threadpool(view.png), media_type="image/png")

    @app.get(
        "/api/results/{name}/values.f32",
        tags=["data"],
        summary="raw values as little-endian float32, row-major (X-Width, X-Height, X-Unit headers)",
    )
    async def result_values(name: str) -> Response:
        view = await run_in_threadpool(session.result, name)
        h, w = view.shape
        return Response(
            view.values.astype("<f4").tobytes(),
            media_type="application/octet-stream",
            headers={"X-Width": str(w), "X-Height": str(h), "X-Unit": view.unit},
        )

    @app.get("/api/results/{name}/surface", tags=["data"], summary="down-sampled surface for a 3-D view")
    async def result_surface(name: str) -> dict[str, Any]:
        view = await run_in_threadpool(session.result, name)
        return await run_in_threadpool(view.surface)

    @app.get(
        "/api/results/{name}/files/{file}",
        tags=["data"],
        summary="download a result file (points.ply, height.npy, ...)",
    )
    async def result_file(name: str, file: str) -> FileResponse:
        if file not in DOWNLOADS:
            raise HTTPException(404, f"file: expected one of {', '.join(DOWNLOADS)}, found {file!r}")
        path = data.existing("results", name) / file
        if not path.is_file():
            raise HTTPException(404, f"results/{name}/{file}: not written (yet)")
        return FileResponse(path, media_type=DOWNLOADS[file], filename=f"{name}-{file}")

    @app.get("/api/compare", tags=["data"], summary="difference of two results (a - b)")
    async def compare(a: str = Query(...), b: str = Query(...)) -> dict[str, Any]:
        view_a, view_b = await run_in_threadpool(session.result, a), await run_in_threadpool(session.result, b)
        _, figures = difference(view_a, view_b)
        return figures

    @app.get("/api/compare.png", tags=["data"], summary="difference map of two results, symmetric colour scale")
    async def compare_png(a: str = Query(...), b: str = Query(...)) -> Response:
        view_a, view_b = await run_in_threadpool(session.result, a), await run_in_threadpool(session.result, b)
        diff, _ = difference(view_a, view_b)
        png, bound = difference_png(diff)
        return Response(png, media_type="image/png", headers={"X-Range": f"{-bound},{bound}"})

    @app.get("/api/colour-bar.png", tags=["data"], include_in_schema=False)
    async def colour_bar() -> Response:
        return Response(colour_bar_png(), media_type="image/png")

    @app.get("/api/calibrations", tags=["calibration"])
    def calibrations() -> dict[str, Any]:
        return {"calibrations": data.names("calibrations"), "active": session.calibration}

    @app.put("/api/calibration", tags=["calibration"], summary="the calibration scans are processed with")
    async def set_calibration(body: CalibrationBody) -> dict[str, Any]:
        return {"active": session.set_calibration(body.name)}

    @app.post(
        "/api/calibrate",
        tags=["calibration"],
        status_code=202,
        summary="run the calibration session (prompts and steps on the websocket); 409 while acquiring",
    )
    async def calibrate(body: CalibrateBody, request: Request) -> dict[str, Any]:
        job = session.calibrate(
            body.name,
            tuple(body.heights_mm),
            body.board_views,
            client_of(request),
            model=body.model,
            gamma_levels=body.gamma_levels,
        )
        return {"job": job.as_dict()}

    @app.post("/api/calibrate/answer", tags=["calibration"], summary="the operator did what the prompt asked")
    async def calibrate_answer() -> dict[str, Any]:
        session.answer()
        return {"answered": True}

    if fault_injection:

        @app.post("/api/simulation/fault", tags=["simulation"], summary="reopen the simulated rig with a device fault")
        async def fault(body: FaultBody) -> dict[str, Any]:
            await run_in_threadpool(session.inject_fault, body.fault)
            return {"fault": body.fault}

    # -- events
    @app.websocket("/api/events")
    async def events(socket: WebSocket) -> None:
        await socket.accept()
        client = socket.query_params.get("client") or uuid.uuid4().hex
        q: asyncio.Queue[tuple[dict[str, Any], bytes | None]] = asyncio.Queue(maxsize=512)
        hub.clients[client] = q
        watching = False
        await socket.send_text(json.dumps({"type": "hello", "client": client, "status": session.status()}))

        async def sender() -> None:
            while True:
                message, image = await q.get()
                if image is None:
                    await socket.send_text(json.dumps(message, default=str))
                    continue
                header = json.dumps(message).encode()
                await socket.send_bytes(len(header).to_bytes(4, "little") + header + image)
                hub.frame_pending[client] = False

        task = asyncio.create_task(sender())
        try:
            while True:
                request = json.loads(await socket.receive_text())
                if "live" in request and bool(request["live"]) != watching:
                    watching = bool(request["live"])
                    session.watch(1 if watching else -1)
        except (WebSocketDisconnect, json.JSONDecodeError, RuntimeError):
            pass
        finally:
            task.cancel()
            hub.clients.pop(client, None)
            hub.frame_pending.pop(client, None)
            if watching:
                session.watch(-1)
            session.client_left(client)

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/vendor/plotly.min.js", include_in_schema=False)
    async def plotly_js() -> FileResponse:
        return FileResponse(_plotly_js(), media_type="text/javascript", headers={"Cache-Control": "max-age=86400"})

    app.add_middleware(AccessMiddleware, token=token)
    return app


def _plotly_js() -> Path:
    """plotly.js as shipped inside the installed ``plotly`` Python package (no JavaScript build step)."""
    import plotly

    return Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"


def _result_capture(data: DataDir, name: str) -> str | None:
    """Name of the capture a result was made from (from its report), if it lies in DATA/captures."""
    try:
        report = json.loads((data.path("results", name) / "report.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    capture = Path(str(report.get("capture") or ""))
    return capture.name if capture.parent.name == "captures" else None
