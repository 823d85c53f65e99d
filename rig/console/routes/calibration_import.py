"""Importing a calibration made elsewhere from the page: an OpenCV FileStorage projector-camera
calibration (YAML or XML text the page read from a file) becomes DATA/calibrations/NAME, through
the same service as ``rig calibrate --import-opencv``."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Depends, Request
from pydantic import Field
from starlette.concurrency import run_in_threadpool

from calibration.errors import CalibrationError
from rig.calibrate.imports import import_opencv
from rig.console.routes._common import Body, session_of
from rig.console.routes.manage import announce
from rig.console.session import Conflict, ConsoleSession
from rig.errors import RigError

router = APIRouter(prefix="/api", tags=["calibration"])

MAX_TEXT = 4 * 1024 * 1024  # characters: a FileStorage calibration is a few kB
SUFFIXES = (".yml", ".yaml", ".xml", ".json")


class ImportBody(Body):
    name: str = Field(..., description="the new calibration's name in DATA/calibrations")
    file_name: str = Field("calibration.yml", description="the file's name (its suffix tells YAML from XML)")
    text: str = Field(..., description="the FileStorage file's content", max_length=MAX_TEXT)
    projector_size: tuple[int, int] | None = Field(None, description="projector WxH (default: the rig's)")
    camera_size: tuple[int, int] | None = Field(
        None, description="camera WxH when the file holds none (default: the rig's)"
    )
    pixel_centre: float = Field(
        0.5, description="where projector pixel k sits (0.5: this product's patterns; 0: SLMaster)"
    )


def _import(session: ConsoleSession, body: ImportBody) -> str:
    target = session.data.path("calibrations", body.name)
    if target.exists() or session.data.staged("calibrations", body.name):
        raise Conflict(f"calibrations/{body.name}: the name is taken; choose another")
    suffix = Path(body.file_name).suffix.lower()
    if suffix not in SUFFIXES:
        raise RigError(f"file {body.file_name!r}: expected an OpenCV FileStorage file ({', '.join(SUFFIXES)})")
    config = session.config
    with tempfile.TemporaryDirectory(prefix="rig-import-") as folder:
        source = Path(folder) / f"imported{suffix}"
        source.write_text(body.text)
        try:
            import_opencv(
                source,
                target,
                body.projector_size or config.projector.size,
                camera_size=body.camera_size or (config.camera.width, config.camera.height),
                pixel_centre=body.pixel_centre,
            )
        except CalibrationError as exc:  # the file's own complaint, about the file the operator chose
            raise RigError(str(exc).replace(str(source), body.file_name)) from None
    return body.name


@router.post("/calibrations/import", summary="import an OpenCV FileStorage projector-camera calibration")
async def import_calibration(
    body: ImportBody, request: Request, session: ConsoleSession = Depends(session_of)
) -> dict[str, Any]:
    name = await run_in_threadpool(_import, session, body)
    return announce(request, "imported", kind="calibrations", name=name)
