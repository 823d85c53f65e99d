"""What every router needs: the session of the app a request reached, and the client that sent it."""

from __future__ import annotations

from typing import Any

from fastapi import Request
from pydantic import BaseModel, ConfigDict

from rig.console.session import ConsoleSession

CLIENT_HEADER = "x-console-client"


def session_of(request: Request) -> ConsoleSession:
    """The app's console session (a FastAPI dependency)."""
    session: ConsoleSession = request.app.state.session
    return session


def client_of(request: Request) -> str | None:
    """The page that sent ``request`` (its ``X-Console-Client`` id), if it said."""
    return request.headers.get(CLIENT_HEADER)


class Body(BaseModel):
    """A request body: unknown fields are refused (a misspelt option must not be silently ignored)."""

    model_config = ConfigDict(extra="forbid")


def job_reply(job: Any, session: ConsoleSession) -> dict[str, Any]:
    """The reply to a request that started a job: the job as it is now."""
    return {"job": session.jobs.get(job.id)}
