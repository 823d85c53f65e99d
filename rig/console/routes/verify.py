"""Verification routes: run `rig verify`'s session as a job, answer its prompts, read its reports and history."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, Request
from fastapi.responses import FileResponse
from pydantic import Field
from starlette.concurrency import run_in_threadpool

from rig.console.routes._common import Body, client_of, job_reply, session_of
from rig.console.session import ConsoleSession
from rig.console.verification import VERIFICATIONS, figure_path, read_verification, verification_history
from rig.verify import guideline

router = APIRouter(prefix="/api", tags=["verification"])


class VerifyBody(Body):
    name: str | None = Field(None, description="verification name in DATA/verifications (default verify-<cal>-<time>)")
    calibration: str | None = Field(None, description="calibration to verify (default: the chosen one)")
    spheres: int = Field(guideline.SPHERE_POSITIONS, description="sphere positions (fewer: a reduced procedure)")
    ball_bars: int = Field(guideline.BALL_BAR_POSITIONS, description="ball-bar positions (1 .. 7)")
    planes: int = Field(guideline.PLANE_POSITIONS, description="plane positions (1 .. 6)")
    mpe_mm: dict[str, float] | None = Field(
        None, description="maximum permissible errors PF, PS, SD, F in mm (default on the simulated rig: its own)"
    )


@router.post(
    "/verify",
    status_code=202,
    summary="verify a calibration (VDI/VDE 2634-2: PF, PS, SD, F); progress and prompts on the websocket; 409 while acquiring",
)
async def verify(body: VerifyBody, request: Request, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    counts = (body.spheres, body.ball_bars, body.planes)
    job = session.verify(body.name, body.calibration, counts, body.mpe_mm, client_of(request))
    return job_reply(job, session)


@router.post("/verify/answer", summary="the operator has placed the artefact the prompt asked for")
async def verify_answer(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    session.answer()
    return {"answered": True}


@router.get("/verifications", summary="the stored verifications, newest first")
def verifications(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return {"verifications": session.data.names(VERIFICATIONS)}


@router.get("/verifications/{name}", summary="a verification's report.json and the names of its figures")
async def verification(name: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return await run_in_threadpool(read_verification, session.data, name)


@router.get(
    "/verifications/{name}/figures/{figure}", summary="a figure of the report (residual maps, positions, history)"
)
async def verification_figure(name: str, figure: str, session: ConsoleSession = Depends(session_of)) -> FileResponse:
    return FileResponse(figure_path(session.data, name, figure), media_type="image/png")


@router.get(
    "/calibrations/{name}/verifications", summary="a calibration's verification history (worst values over time)"
)
async def history(name: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return await run_in_threadpool(verification_history, session.data, name)
