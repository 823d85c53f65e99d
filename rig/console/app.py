"""The console's ASGI application: the page, the JSON API under /api/, and the event websocket.

:func:`create_app` builds it around one :class:`rig.console.session.ConsoleSession` and the
routers of :mod:`rig.console.routes`; the routes only translate HTTP to session calls (which call
the services). FastAPI serves the OpenAPI document at ``/api/openapi.json``; ``/api/docs`` is a page of the
console drawing it (no CDN). Who may call it is decided by :mod:`rig.console.access` before any route runs.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Iterable
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.concurrency import run_in_threadpool

from rig.config import RigConfig
from rig.console.access import AccessMiddleware, AccessRules
from rig.console.datadir import DataDir
from rig.console.hub import Hub
from rig.console.live_view import LIVE_FPS
from rig.console.routes import ROUTERS
from rig.console.routes.live import STATIC
from rig.console.session import Busy, Conflict, ConsoleSession
from rig.errors import ResultExistsError, RigError


def create_app(
    config: RigConfig,
    data_dir: str | Path,
    token: str | None = None,
    fault_injection: bool = False,
    live_fps: float = LIVE_FPS,
    host: str = "127.0.0.1",
    allowed_hosts: Iterable[str] = (),
) -> FastAPI:
    """The console for the rig of ``config``, keeping its files in ``data_dir``.

    ``token``: required on every request when set (the command sets one when binding beyond
    127.0.0.1); ``host`` and ``allowed_hosts``: the names the ``Host`` header may carry besides the
    loopback names (:mod:`rig.console.access`). ``fault_injection``: enable
    ``POST /api/simulation/fault`` (tests, fault drills). The rig is opened when the app starts and
    closed when it stops.
    """
    rules = AccessRules(host, allowed_hosts, token)
    hub = Hub()
    session = ConsoleSession(config, DataDir(data_dir), hub.publish, fault_injection=fault_injection, live_fps=live_fps)

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
        docs_url=None,  # /api/docs is the console's own offline page (routes/docs.py)
        redoc_url=None,
    )
    app.state.session = session
    app.state.hub = hub
    _add_error_handlers(app)
    for router in ROUTERS:
        app.include_router(router)
    if fault_injection:
        from rig.console.routes.simulation import router as simulation

        app.include_router(simulation)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    app.add_middleware(AccessMiddleware, rules=rules)
    return app


def _add_error_handlers(app: FastAPI) -> None:
    """Every refusal is one readable line under ``error``: 409 busy or taken, 404 unknown, 400 else."""

    @app.exception_handler(RigError)
    async def rig_error(_: Request, exc: RigError) -> JSONResponse:
        status = 409 if isinstance(exc, (Busy, Conflict, ResultExistsError)) else 400
        return JSONResponse({"error": str(exc)}, status_code=status)

    @app.exception_handler(FileNotFoundError)
    async def not_found(_: Request, exc: FileNotFoundError) -> JSONResponse:
        return JSONResponse({"error": str(exc)}, status_code=404)

    @app.exception_handler(RequestValidationError)
    async def invalid(_: Request, exc: RequestValidationError) -> JSONResponse:
        return JSONResponse({"error": _validation_line(exc.errors()), "detail": exc.errors()}, status_code=422)


def _validation_line(errors: Any) -> str:
    """Pydantic's first complaint as one sentence: ``heights_mm.1: Input should be a valid number``."""
    if not errors:
        return "request: not understood"
    first = errors[0]
    where = ".".join(str(part) for part in first.get("loc", ()) if part != "body") or "request"
    return f"{where}: {first.get('msg', 'invalid')}" + (f" (found {first['input']!r})" if "input" in first else "")
