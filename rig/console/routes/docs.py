"""The API's own page and the console's icon, served from the package (no CDN: the console works
without a connection beyond the rig's network). The page draws ``/api/openapi.json``."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import FileResponse

from rig.console.routes.live import STATIC

router = APIRouter(include_in_schema=False)


@router.get("/api/docs")
async def api_docs() -> FileResponse:
    return FileResponse(STATIC / "apidocs.html", headers={"Cache-Control": "no-store"})


@router.get("/favicon.ico")
async def favicon() -> FileResponse:
    return FileResponse(STATIC / "favicon.svg", media_type="image/svg+xml", headers={"Cache-Control": "max-age=86400"})
