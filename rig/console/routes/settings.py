"""Settings routes: camera exposure and gain, the projector between scans, how live frames are drawn."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends
from pydantic import Field
from starlette.concurrency import run_in_threadpool

from rig.console.devices import ProjectorSetting
from rig.console.routes._common import Body, session_of
from rig.console.session import ConsoleSession

router = APIRouter(prefix="/api", tags=["rig"])


class ExposureBody(Body):
    exposure_us: float | None = Field(None, description="exposure time in microseconds")
    gain: float | None = Field(None, description="camera gain (the backend's unit)")


class ProjectorBody(Body):
    pattern: str = Field("black", description="black, white, fringe or grid (alignment: lines and a centre crosshair)")
    frequency: float = Field(8.0, description="fringes across the projector (fringe)")
    phase_deg: float = Field(0.0, description="fringe phase in degrees")
    axis: str = Field("x", description="x: fringes vary along the projector's width")
    pitch_px: int = Field(64, description="grid line spacing in projector pixels (grid)")


class LiveBody(Body):
    overlay: bool | None = Field(None, description="saturated pixels in red")
    view: str | None = Field(None, description="camera or modulation (while a fringe is shown)")


@router.put("/exposure", summary="camera exposure (us) and gain")
async def set_exposure(body: ExposureBody, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return await run_in_threadpool(session.set_exposure, body.exposure_us, body.gain)


@router.get("/exposure")
async def get_exposure(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return {"exposure_us": session.exposure_us, "gain": session.gain}


@router.put("/projector", summary="what the projector shows between scans")
async def set_projector(body: ProjectorBody, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    setting = ProjectorSetting(body.pattern, body.frequency, body.phase_deg, body.axis, body.pitch_px)
    return await run_in_threadpool(session.set_projector, setting)


@router.get("/projector")
async def get_projector(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return dict(session.projector.__dict__)


@router.put("/live", summary="live view drawing: saturation overlay, camera or modulation map")
async def set_live(body: LiveBody, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return session.set_live(body.overlay, body.view)


class Live3DBody(Body):
    on: bool = Field(..., description="true: scan the short pattern set continuously and show each set's points")


@router.put("/live3d", summary="live 3-D view on or off: continuous short scans processed as they come")
async def set_live_3d(body: Live3DBody, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return await run_in_threadpool(session.set_live_3d, body.on)
