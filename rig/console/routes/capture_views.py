"""Looking into a capture from the page: its frames as PNG, and each phase-shifted group's wrapped
phase and modulation as colour maps (:mod:`rig.capture_views`)."""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi import APIRouter, Depends
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from rig import capture_views
from rig.console.results import encode_png
from rig.console.routes._common import session_of
from rig.console.session import ConsoleSession
from rig.errors import RigError
from rig.store.capture import Capture
from rig.store.result_files import colour_map

router = APIRouter(prefix="/api/captures/{name}", tags=["data"])


def _capture(session: ConsoleSession, name: str) -> Capture:
    from rig.api import load_capture

    return load_capture(session.data.existing("captures", name))


def _png(image: np.ndarray, headers: dict[str, str] | None = None) -> Response:
    return Response(encode_png(image), media_type="image/png", headers=headers or {})


@router.get("/frames", summary="a capture's frames and its phase-shifted groups")
async def frames(name: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    capture = await run_in_threadpool(_capture, session, name)
    return {"capture": name, **capture_views.describe_frames(capture)}


@router.get("/frames/{index}.png", summary="one raw frame, scaled to 8 bits")
async def frame(name: str, index: int, session: ConsoleSession = Depends(session_of)) -> Response:
    capture = await run_in_threadpool(_capture, session, name)
    return _png(await run_in_threadpool(capture_views.frame_8bit, capture, index))


@router.get("/groups/{group}/{what}.png", summary="wrapped phase (-pi .. pi) or modulation of a phase-shifted group")
async def group_map(name: str, group: int, what: str, session: ConsoleSession = Depends(session_of)) -> Response:
    if what not in ("phase", "modulation"):
        raise RigError(f"map: expected phase or modulation, found {what!r}")
    capture = await run_in_threadpool(_capture, session, name)
    phase, modulation = await run_in_threadpool(capture_views.wrapped_phase, capture, group)
    if what == "phase":
        return _png(colour_map(phase, -np.pi, np.pi), {"X-Range": f"{-np.pi},{np.pi}", "X-Unit": "rad"})
    finite = modulation[np.isfinite(modulation)]
    high = float(np.percentile(finite, 99.5)) if finite.size else 1.0
    high = high if high > 0 else 1.0
    return _png(colour_map(modulation, 0.0, high), {"X-Range": f"0,{high}", "X-Unit": "grey levels"})
