"""Captures and results routes: list and open captures, a result's figures, maps, values, files and comparisons."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Query
from fastapi.responses import FileResponse, Response
from starlette.concurrency import run_in_threadpool

from rig.console.datadir import DataDir
from rig.console.results import ResultView, colour_bar_png, difference, difference_png
from rig.console.routes._common import session_of
from rig.console.session import ConsoleSession
from rig.errors import OutputError, RigError
from rig.store import results as store

router = APIRouter(prefix="/api", tags=["data"])


@router.get("/captures")
def captures(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    from rig.api import load_capture

    rows: list[dict[str, Any]] = []
    for name in session.data.names("captures"):
        try:
            capture = load_capture(session.data.path("captures", name))
        except RigError as exc:
            rows.append({"name": name, "complete": False, "error": str(exc)})
            continue
        rows.append(
            {
                "name": name,
                "scene": capture.scene,
                "width": capture.width,
                "height": capture.height,
                "frames": len(capture.frames),
                "created": capture.manifest.get("created_utc"),
            }
        )
    for name in session.data.interrupted_names("captures"):
        rows.append({"name": name, "complete": False, "error": "interrupted scan: salvage or discard it"})
    return {"captures": rows}


@router.get("/captures/{name}")
def capture(name: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    from rig.api import load_capture

    data = session.data
    loaded = load_capture(data.existing("captures", name))
    results = [r for r in data.names("results") if result_capture(data, r) == name]
    return {"name": name, "manifest": loaded.manifest, "results": results}


@router.get("/results")
def results(session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    data = session.data
    return {"results": [{"name": name, "capture": result_capture(data, name)} for name in data.names("results")]}


async def _view(session: ConsoleSession, name: str) -> ResultView:
    return await run_in_threadpool(session.result, name)


@router.get("/results/{name}", summary="a result's key figures")
async def result(name: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    return (await _view(session, name)).summary()


@router.get("/results/{name}/map.png", summary="colour-mapped height (or phase)")
async def result_png(name: str, session: ConsoleSession = Depends(session_of)) -> Response:
    view = await _view(session, name)
    return Response(await run_in_threadpool(view.png), media_type="image/png")


@router.get(
    "/results/{name}/exposure.png",
    summary="a capture at several exposures: per pixel the exposure it drew on most (colours: the summary's exposures)",
)
async def result_exposure_png(name: str, session: ConsoleSession = Depends(session_of)) -> Response:
    view = await _view(session, name)
    if view.exposure is None:
        raise HTTPException(404, f"results/{name}: not a capture at several exposures (no exposure map)")
    return Response(await run_in_threadpool(view.exposure_png), media_type="image/png")


@router.get(
    "/results/{name}/values.f32",
    summary="raw values as little-endian float32, row-major (X-Width, X-Height, X-Unit headers)",
)
async def result_values(name: str, session: ConsoleSession = Depends(session_of)) -> Response:
    view = await _view(session, name)
    h, w = view.shape
    return Response(
        view.values.astype("<f4").tobytes(),
        media_type="application/octet-stream",
        headers={"X-Width": str(w), "X-Height": str(h), "X-Unit": view.unit},
    )


@router.get("/results/{name}/surface", summary="down-sampled surface for a 3-D view")
async def result_surface(name: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    view = await _view(session, name)
    return await run_in_threadpool(view.surface)


@router.get(
    "/results/{name}/cloud.bin",
    summary="the valid pixels as a coloured point cloud for a WebGL view: N float32 (x, y, z), then N RGBA bytes"
    " (X-Points, X-Step, X-Range, X-Unit, X-Axis-Unit, X-Z-Scale headers)",
)
async def result_cloud(name: str, session: ConsoleSession = Depends(session_of)) -> Response:
    view = await _view(session, name)
    body, headers = await run_in_threadpool(view.cloud)
    return Response(body, media_type="application/octet-stream", headers=headers)


@router.get("/results/{name}/files", summary="the files a result holds (what the page offers for download)")
async def result_files(name: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    path = session.data.existing("results", name)
    return {"files": (await run_in_threadpool(store.describe_result, path))["files"]}


@router.get("/results/{name}/files/{file}", summary="download a result file (points.ply, mesh.stl, height.npy, ...)")
async def result_file(name: str, file: str, session: ConsoleSession = Depends(session_of)) -> FileResponse:
    if file not in store.MEDIA_TYPES:
        raise HTTPException(404, f"file: expected one of {', '.join(store.MEDIA_TYPES)}, found {file!r}")
    directory = session.data.existing("results", name)
    if (directory / file).is_symlink() or not (directory / file).resolve().is_relative_to(session.data.root):
        raise HTTPException(404, f"results/{name}/{file}: not a file of this result (a link)")
    try:
        path = store.result_file(directory, file)  # also refuses a FIFO or a device
    except OutputError:
        raise HTTPException(404, f"results/{name}/{file}: not written (yet)") from None
    return FileResponse(path, media_type=store.MEDIA_TYPES[file], filename=f"{name}-{file}")


@router.get("/compare", summary="difference of two results (a - b)")
async def compare(
    a: str = Query(...), b: str = Query(...), session: ConsoleSession = Depends(session_of)
) -> dict[str, Any]:
    _, figures = difference(await _view(session, a), await _view(session, b))
    return figures


@router.get("/compare.png", summary="difference map of two results, symmetric colour scale")
async def compare_png(
    a: str = Query(...), b: str = Query(...), session: ConsoleSession = Depends(session_of)
) -> Response:
    diff, _ = difference(await _view(session, a), await _view(session, b))
    png, bound = difference_png(diff)
    return Response(png, media_type="image/png", headers={"X-Range": f"{-bound},{bound}"})


@router.get("/colour-bar.png", include_in_schema=False)
async def colour_bar() -> Response:
    return Response(colour_bar_png(), media_type="image/png")


def result_capture(data: DataDir, name: str) -> str | None:
    """Name of the capture a result was made from (from its report), if it lies in DATA/captures."""
    try:
        report = store.read_report(data.path("results", name))
    except (RigError, OSError):
        return None
    return store.capture_name(report)
