"""What a calibration found, for the Calibration view: plane residuals and flatness, the gamma curve,
and each board view with its detections and reprojection residuals (:mod:`rig.calibrate.figures`)."""

from __future__ import annotations

import json
from typing import Any

from fastapi import APIRouter, Depends
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from calibration.errors import CalibrationError
from rig.calibrate import figures
from rig.console.results import encode_png
from rig.console.routes._common import session_of
from rig.console.session import ConsoleSession
from rig.errors import RigError

router = APIRouter(prefix="/api/calibrations/{name}", tags=["calibration"])


@router.get("/figures", summary="plane residuals and flatness, gamma curve, camera fit, board views")
async def calibration_figures(name: str, session: ConsoleSession = Depends(session_of)) -> dict[str, Any]:
    directory = session.data.existing("calibrations", name)
    return {"calibration": name, **await run_in_threadpool(figures.summary, directory)}


@router.get("/board/{view}.png", summary="a board view: detected corners (green lit, grey unlit), residuals x20 (red)")
async def board_png(name: str, view: str, session: ConsoleSession = Depends(session_of)) -> Response:
    directory = session.data.existing("calibrations", name)
    try:
        picture, found = await run_in_threadpool(figures.board_view, directory, view)
    except CalibrationError as exc:  # a session without a board, a view that cannot be read
        raise RigError(str(exc)) from None
    headers = {"X-Figures": json.dumps(found)}
    return Response(encode_png(picture), media_type="image/png", headers=headers)
