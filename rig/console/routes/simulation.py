"""Fault drills on the simulated rig (mounted only with ``fault_injection``: tests and drills)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends
from pydantic import Field
from starlette.concurrency import run_in_threadpool

from rig.console.routes._common import Body, session_of
from rig.console.session import ConsoleSession

router = APIRouter(prefix="/api", tags=["simulation"])


class FaultBody(Body):
    fault: str = Field(..., description="camera-gone or trigger-timeout")


@router.post("/simulation/fault", summary="reopen the simulated rig with a device fault")
async def fault(body: FaultBody, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    await run_in_threadpool(session.inject_fault, body.fault)
    return {"fault": body.fault}
