"""Calibration routes: list and choose calibrations, run the calibration session, answer its prompts."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, Request
from pydantic import Field

from rig.console.routes._common import Body, client_of, job_reply, session_of
from rig.console.session import ConsoleSession

router = APIRouter(prefix="/api", tags=["calibration"])


class CalibrationBody(Body):
    name: str | None = Field(None, description="calibration name in DATA/calibrations; null: none (phase only)")


class CalibrateBody(Body):
    name: str | None = Field(None, description="calibration name in DATA/calibrations (default cal-<time>)")
    heights_mm: list[float] = Field([25.0, 50.0, 100.0, 150.0], description="plane heights above the reference plane")
    board_views: int = Field(6, description="tilted board views for the camera intrinsics (0: pixel size only)")
    model: str = Field("reference-plane", description="height model: reference-plane, polynomial (stereo: real rig)")
    gamma_levels: int = Field(
        0, description="projector gamma ramp of this many flat levels first (0: none, else 5 .. 256)"
    )


@router.get("/calibrations")
def calibrations(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return {"calibrations": session.data.names("calibrations"), "active": session.calibration}


@router.put("/calibration", summary="the calibration scans are processed with")
async def set_calibration(body: CalibrationBody, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return {"active": session.set_calibration(body.name)}


@router.post(
    "/calibrate",
    status_code=202,
    summary="run the calibration session (prompts and steps on the websocket); 409 while acquiring",
)
async def calibrate(
    body: CalibrateBody, request: Request, session: ConsoleSession = Depends(session_of)
) -> dict[str, Any]:
    job = session.calibrate(
        body.name,
        tuple(body.heights_mm),
        body.board_views,
        client_of(request),
        model=body.model,
        gamma_levels=body.gamma_levels,
    )
    return job_reply(job, session)


@router.post("/calibrate/answer", summary="the operator did what the prompt asked")
async def calibrate_answer(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    session.answer()
    return {"answered": True}
