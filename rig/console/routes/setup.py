"""Scan setup routes: what the next scan projects and records, and the exposure assistant's suggestion."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends
from pydantic import Field
from starlette.concurrency import run_in_threadpool

from rig.console.routes._common import Body, session_of
from rig.console.session import ConsoleSession

router = APIRouter(prefix="/api", tags=["scan"])


class SetupBody(Body):
    part: str | None = Field(None, description="part name: the capture's name starts with it; recorded in capture.json")
    notes: str | None = Field(None, description="notes recorded in capture.json")
    pattern_set: str | None = Field(None, description="phase-shifting or speckle")
    frequencies: list[float] | None = Field(None, description="fringe counts across the projector ([]: the config's)")
    steps: int | None = Field(None, description="phase shifts per frequency")
    exposures_us: list[float] | None = Field(None, description="exposures in microseconds ([]: the camera's one)")


@router.get("/scan-setup", summary="the scan setup (remembered in the data folder)")
async def get_setup(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return session.describe_setup()


@router.put("/scan-setup", summary="change the scan setup; a value that does not fit is refused with its field named")
async def set_setup(body: SetupBody, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    changes = body.model_dump(exclude_unset=True)
    return await run_in_threadpool(session.set_scan_setup, changes)


@router.post(
    "/scan-setup/hdr-auto",
    summary="the exposure assistant's suggestion for what is in front of the rig (a short pre-capture; 409 while"
    " another acquisition runs)",
)
async def hdr_auto(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return await run_in_threadpool(session.suggest_exposures)
