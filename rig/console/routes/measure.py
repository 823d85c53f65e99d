"""Measuring routes: a result's line profile, point-to-point distance, plane fit (and its
height-above-plane map), histogram and region statistics, as JSON or CSV (``format=csv``).

Positions are pixels of the result's map (``x`` column, ``y`` row); a region is the rectangle
spanned by (x0, y0) and (x1, y1), the whole map when left out. The numbers come from
:mod:`rig.measure`; a measurement that cannot be made is a 400 with one line.
"""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Depends, Query
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from rig import measure
from rig.console.results import ResultView, difference_png
from rig.console.routes._common import session_of
from rig.console.session import ConsoleSession
from rig.errors import RigError

router = APIRouter(prefix="/api/results/{name}/measure", tags=["measure"])

Format = Literal["json", "csv"]


# One Query per parameter: FastAPI keeps per-parameter state on them, so they are never shared.
def X() -> Any:
    return Query(..., description="column of the map (pixels)")


def Y() -> Any:
    return Query(..., description="row of the map (pixels)")


def RX() -> Any:
    return Query(None, description="region corner column (pixels); the whole map when the corners are left out")


def RY() -> Any:
    return Query(None, description="region corner row (pixels)")


def FORMAT() -> Any:
    return Query("json", description="json, or csv for a file to download")


def surface_of(view: ResultView) -> measure.Surface:
    """The result's map to measure on: heights with their points, or a phase map over pixels."""
    points = view.points if view.unit == "mm" else None
    return measure.Surface(view.values, view.unit, points)


async def _surface(session: ConsoleSession, name: str) -> measure.Surface:
    return surface_of(await run_in_threadpool(session.result, name))


def _corners(x0: float | None, y0: float | None, x1: float | None, y1: float | None) -> list[float] | None:
    given = [c for c in (x0, y0, x1, y1) if c is not None]
    if not given:
        return None
    if len(given) != 4:
        raise RigError("region: give all four of x0, y0, x1, y1 (two corners), or none for the whole map")
    return given


def _reply(name: str, tool: str, figures: Any, fmt: Format) -> Any:
    if fmt == "csv":
        return Response(
            figures.csv(),
            media_type="text/csv",
            headers={"Content-Disposition": f'attachment; filename="{name}-{tool}.csv"'},
        )
    return {"result": name, **figures.figures()}


@router.get("/profile", summary="the map along a line from (x0, y0) to (x1, y1)")
async def profile(
    name: str,
    x0: float = X(),
    y0: float = Y(),
    x1: float = X(),
    y1: float = Y(),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    return _reply(name, "profile", measure.line_profile(surface, (x0, y0), (x1, y1)), format)


@router.get("/distance", summary="distances between the points (x0, y0) and (x1, y1): lateral, rise, 3-D")
async def distance(
    name: str,
    x0: float = X(),
    y0: float = Y(),
    x1: float = X(),
    y1: float = Y(),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    return _reply(name, "distance", measure.point_distance(surface, (x0, y0), (x1, y1)), format)


@router.get("/plane", summary="plane fitted to a region: flatness, rms, tilt")
async def plane(
    name: str,
    x0: float | None = RX(),
    y0: float | None = RY(),
    x1: float | None = RX(),
    y1: float | None = RY(),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    fit = await run_in_threadpool(measure.fit_plane, surface, _corners(x0, y0, x1, y1))
    return _reply(name, "plane", fit, format)


@router.get("/plane.png", summary="height above the plane fitted to a region, symmetric colour scale (X-Range)")
async def plane_map(
    name: str,
    x0: float | None = RX(),
    y0: float | None = RY(),
    x1: float | None = RX(),
    y1: float | None = RY(),
    session: ConsoleSession = Depends(session_of),
) -> Response:
    surface = await _surface(session, name)

    def draw() -> tuple[bytes, float]:
        fit = measure.fit_plane(surface, _corners(x0, y0, x1, y1))
        return difference_png(measure.height_above_plane(surface, fit))

    png, bound = await run_in_threadpool(draw)
    return Response(png, media_type="image/png", headers={"X-Range": f"{-bound},{bound}", "X-Unit": surface.unit})


@router.get("/histogram", summary="histogram of the valid values of a region")
async def histogram(
    name: str,
    x0: float | None = RX(),
    y0: float | None = RY(),
    x1: float | None = RX(),
    y1: float | None = RY(),
    bins: int = Query(64, description="number of equal-width bins (1 to 4096)"),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    hist = await run_in_threadpool(measure.histogram, surface, _corners(x0, y0, x1, y1), bins)
    return _reply(name, "histogram", hist, format)


@router.get("/roi", summary="statistics of the valid values of a region")
async def roi(
    name: str,
    x0: float | None = RX(),
    y0: float | None = RY(),
    x1: float | None = RX(),
    y1: float | None = RY(),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    stats = await run_in_threadpool(measure.region_stats, surface, _corners(x0, y0, x1, y1))
    return _reply(name, "roi", stats, format)
