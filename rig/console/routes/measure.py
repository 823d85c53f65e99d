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


Point = tuple[float, float]


def two_points(
    x0: float = Query(..., description="column of the first point (pixels)"),
    y0: float = Query(..., description="row of the first point (pixels)"),
    x1: float = Query(..., description="column of the second point (pixels)"),
    y1: float = Query(..., description="row of the second point (pixels)"),
) -> tuple[Point, Point]:
    """The two points of a profile or a distance, from the query."""
    return (x0, y0), (x1, y1)


def region(
    x0: float | None = Query(None, description="region corner column (pixels); the whole map when left out"),
    y0: float | None = Query(None, description="region corner row (pixels)"),
    x1: float | None = Query(None, description="the other corner's column (pixels)"),
    y1: float | None = Query(None, description="the other corner's row (pixels)"),
) -> list[float] | None:
    """The region's corners from the query: all four, or none for the whole map."""
    given = [c for c in (x0, y0, x1, y1) if c is not None]
    if not given:
        return None
    if len(given) != 4:
        raise RigError("region: give all four of x0, y0, x1, y1 (two corners), or none for the whole map")
    return given


def FORMAT() -> Any:  # a fresh Query per route: FastAPI keeps per-parameter state on it
    return Query("json", description="json, or csv for a file to download")


def surface_of(view: ResultView) -> measure.Surface:
    """The result's map to measure on: heights with their points, or a phase map over pixels."""
    points = view.points if view.unit == "mm" else None
    return measure.Surface(view.values, view.unit, points)


async def _surface(session: ConsoleSession, name: str) -> measure.Surface:
    return surface_of(await run_in_threadpool(session.result, name))


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
    points: tuple[Point, Point] = Depends(two_points),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    return _reply(name, "profile", measure.line_profile(surface, *points), format)


@router.get("/distance", summary="distances between the points (x0, y0) and (x1, y1): lateral, rise, 3-D")
async def distance(
    name: str,
    points: tuple[Point, Point] = Depends(two_points),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    return _reply(name, "distance", measure.point_distance(surface, *points), format)


@router.get("/plane", summary="plane fitted to a region: flatness, rms, tilt")
async def plane(
    name: str,
    corners: list[float] | None = Depends(region),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    fit = await run_in_threadpool(measure.fit_plane, surface, corners)
    return _reply(name, "plane", fit, format)


@router.get("/plane.png", summary="height above the plane fitted to a region, symmetric colour scale (X-Range)")
async def plane_map(
    name: str,
    corners: list[float] | None = Depends(region),
    session: ConsoleSession = Depends(session_of),
) -> Response:
    surface = await _surface(session, name)

    def draw() -> tuple[bytes, float]:
        fit = measure.fit_plane(surface, corners)
        return difference_png(measure.height_above_plane(surface, fit))

    png, bound = await run_in_threadpool(draw)
    return Response(png, media_type="image/png", headers={"X-Range": f"{-bound},{bound}", "X-Unit": surface.unit})


@router.get("/histogram", summary="histogram of the valid values of a region")
async def histogram(
    name: str,
    corners: list[float] | None = Depends(region),
    bins: int = Query(64, description="number of equal-width bins (1 to 4096)"),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    hist = await run_in_threadpool(measure.histogram, surface, corners, bins)
    return _reply(name, "histogram", hist, format)


@router.get("/roi", summary="statistics of the valid values of a region")
async def roi(
    name: str,
    corners: list[float] | None = Depends(region),
    format: Format = FORMAT(),
    session: ConsoleSession = Depends(session_of),
) -> Any:
    surface = await _surface(session, name)
    stats = await run_in_threadpool(measure.region_stats, surface, corners)
    return _reply(name, "roi", stats, format)
