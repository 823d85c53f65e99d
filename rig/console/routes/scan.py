"""Scan and processing routes: start a scan, reprocess a capture, follow and stop jobs."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Request
from pydantic import Field

from rig.console.routes._common import Body, client_of, job_reply, session_of
from rig.console.session import ConsoleSession
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions
from rig.pipeline.registry import available_options

router = APIRouter(prefix="/api")


class OptionsBody(Body):
    unwrap: str = "auto"
    denoise: str = "none"
    correction: str = DEFAULT_CORRECTION

    def options(self) -> ProcessOptions:
        return ProcessOptions(unwrap=self.unwrap, denoise=self.denoise, correction=self.correction)


class ScanBody(Body):
    name: str | None = Field(None, description="capture name in DATA/captures (default scan-<time>)")
    process: bool = Field(True, description="process the capture with the chosen calibration when acquired")
    options: OptionsBody = Field(default_factory=OptionsBody)


class ProcessBody(Body):
    capture: str = Field(..., description="capture name in DATA/captures")
    name: str | None = Field(
        None, description="result name in DATA/results (default <capture>-<correction>-<time>); 409 if taken"
    )
    options: OptionsBody = Field(default_factory=OptionsBody)


@router.get(
    "/options", tags=["results"], summary="unwrap, correction and denoise choices: default, names, one line each"
)
async def options() -> dict[str, Any]:
    return available_options()


@router.post(
    "/scan",
    tags=["scan"],
    status_code=202,
    summary="start a scan (409 while another acquisition runs); progress on the websocket",
)
async def scan(body: ScanBody, request: Request, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    job = session.scan(body.name, body.process, body.options.options(), client_of(request))
    return job_reply(job, session)


@router.post("/stop", tags=["scan"], summary="cancel a running job (default: all)")
async def stop(job: str | None = None, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return {"stopped": session.stop(job)}


@router.get("/jobs", tags=["scan"], summary="every job the console remembers, oldest first")
async def jobs(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return {"jobs": session.jobs.all()}


@router.get("/jobs/{job_id}", tags=["scan"])
async def get_job(job_id: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    job = session.jobs.get(job_id)
    if job is None:
        raise HTTPException(404, f"job {job_id!r}: unknown")
    return job


class SalvageBody(Body):
    name: str | None = Field(
        None, description="result name in DATA/results (default <capture>-salvaged-...); 409 if taken"
    )
    options: OptionsBody = Field(default_factory=OptionsBody)


@router.post(
    "/captures/{capture}/salvage",
    tags=["results"],
    status_code=202,
    summary="process what an interrupted scan's folder holds (fails with one line if frames are missing)",
)
async def salvage(
    capture: str, body: SalvageBody, request: Request, session: ConsoleSession = Depends(session_of)
) -> dict[str, Any]:
    job = session.process(capture, body.options.options(), body.name, client_of(request), salvage=True)
    return job_reply(job, session)


@router.post("/captures/{capture}/discard", tags=["results"], summary="move an interrupted scan's folder to DATA/trash")
async def discard(capture: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return {"discarded": capture, "moved_to": session.discard(capture)}


@router.post("/process", tags=["results"], status_code=202, summary="process a capture with other options")
async def process(body: ProcessBody, request: Request, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    job = session.process(body.capture, body.options.options(), body.name, client_of(request))
    return job_reply(job, session)
