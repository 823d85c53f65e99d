"""Status and live routes: the page, the rig's status and devices, and the event websocket.

The websocket sends ``hello`` with the status (the running jobs and the newest result, so a page
opened or reloaded mid-scan shows it), then every message the session publishes. A page sends
``{"live": true|false}`` to watch the live view or stop; leaving stops nothing else — jobs run on.
"""

from __future__ import annotations

import asyncio
import json
import uuid
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Depends, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse

from rig.console.hub import Hub
from rig.console.routes._common import session_of
from rig.console.session import ConsoleSession

router = APIRouter()
STATIC = Path(__file__).resolve().parent.parent / "static"


@router.get("/api/status", tags=["rig"], summary="what the rig is doing, its settings, jobs and devices")
async def status(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return session.status()


@router.get("/api/devices", tags=["rig"], summary="each device's backend, state and the last device error")
async def devices(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return {"devices": session.devices(), "error": session.device_error}


@router.websocket("/api/events")
async def events(socket: WebSocket) -> None:
    session: ConsoleSession = socket.app.state.session
    hub: Hub = socket.app.state.hub
    await socket.accept()
    client = socket.query_params.get("client") or uuid.uuid4().hex
    queue = hub.join(client)
    watching = False
    await socket.send_text(json.dumps({"type": "hello", "client": client, "status": session.status()}))
    task = asyncio.create_task(hub.forward(client, queue, socket))
    try:
        while True:
            request = json.loads(await socket.receive_text())
            if isinstance(request, dict) and "live" in request and bool(request["live"]) != watching:
                watching = bool(request["live"])
                session.watch(1 if watching else -1)
    except (WebSocketDisconnect, json.JSONDecodeError, RuntimeError):
        pass
    finally:
        task.cancel()
        hub.leave(client)
        if watching:
            session.watch(-1)


@router.get("/", include_in_schema=False)
async def index() -> FileResponse:
    return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})


@router.get("/vendor/plotly.min.js", include_in_schema=False)
async def plotly_js() -> FileResponse:
    return FileResponse(_plotly_js(), media_type="text/javascript", headers={"Cache-Control": "max-age=86400"})


def _plotly_js() -> Path:
    """plotly.js as shipped inside the installed ``plotly`` Python package (no JavaScript build step)."""
    import plotly

    return Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"
