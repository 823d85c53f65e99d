"""Managing the data directory from the page: delete captures, results and calibrations to the
trash (with undo), list and restore what the trash holds, rename them.

Every change is announced to every page (a ``data`` message) so that lists in other tabs follow.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, Request
from pydantic import Field

from rig.console.routes._common import Body, session_of
from rig.console.routes.data import result_capture
from rig.console.session import ConsoleSession
from rig.console.trash import Trash

router = APIRouter(prefix="/api", tags=["data"])


class RestoreBody(Body):
    kind: str = Field(..., description="captures, results or calibrations")
    entry: str = Field(..., description="the entry's name in DATA/trash/KIND, as GET /api/trash lists it")


class RenameBody(Body):
    to: str = Field(..., description="the new name (letters, digits, '.', '_', '-')")


def _busy(session: ConsoleSession, name: str) -> bool:
    return any(job["name"] == name for job in session.jobs.running())


def _forget(session: ConsoleSession, kind: str, name: str, new: str | None = None) -> None:
    """What the session holds of an entry that left its place (renamed to ``new``, or deleted): a
    result shown, the active calibration (which follows a rename)."""
    if kind == "results":
        held = session.processing
        held.results.pop(name, None)  # one dict operation: atomic under the interpreter lock
        if held.latest and held.latest.get("name") == name:
            held.latest = None
    if kind == "calibrations" and session.calibration == name:
        session.set_calibration(new)


def announce(request: Request, change: str, **fields: Any) -> dict[str, Any]:
    """Tell every page what changed (a ``data`` message, then the status with the calibrations); the message."""
    message = {"type": "data", "change": change, **fields}
    hub = request.app.state.hub
    hub.publish(message)
    hub.publish({"type": "status", "status": request.app.state.session.status()})
    return message


@router.delete("/{kind}/{name}", summary="move a capture, result or calibration to DATA/trash (undo: restore)")
def delete(kind: str, name: str, request: Request, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    entry = Trash(session.data).delete(kind, name, busy=_busy(session, name))
    _forget(session, kind, name)
    return announce(request, "deleted", **entry.as_dict())


@router.get("/trash", summary="what DATA/trash holds (captures, results, calibrations), newest first")
def trash(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return {"entries": [e.as_dict() for e in Trash(session.data).entries()]}


@router.post("/trash/restore", summary="move an entry of DATA/trash back under its name; 409 if the name is taken")
def restore(body: RestoreBody, request: Request, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    name = Trash(session.data).restore(body.kind, body.entry)
    return announce(request, "restored", kind=body.kind, name=name)


@router.post("/{kind}/{name}/rename", summary="rename a capture, result or calibration; 409 if the new name is taken")
def rename(
    kind: str, name: str, body: RenameBody, request: Request, session: ConsoleSession = Depends(session_of)
) -> dict[str, Any]:
    data = session.data
    made_from = [r for r in data.names("results") if result_capture(data, r) == name] if kind == "captures" else []
    new = Trash(data).rename(kind, name, body.to, busy=_busy(session, name))
    _forget(session, kind, name, new)
    # a result's report.json names its capture and is never rewritten: say which ones keep the old name
    return announce(request, "renamed", kind=kind, name=new, old=name, results_naming_old=made_from)
