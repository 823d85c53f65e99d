"""The console's HTTP and websocket routes, one router per area of the page.

Each route is a few lines that translate a request into a call on the console session (or the
jobs service) found in ``request.app.state``; no rig logic lives here.
"""

from __future__ import annotations

from fastapi import APIRouter

from rig.console.routes import (
    calibration,
    calibration_figures,
    calibration_import,
    capture_views,
    data,
    docs,
    live,
    manage,
    measure,
    scan,
    settings,
    setup,
    verify,
)

ROUTERS: tuple[APIRouter, ...] = (
    live.router,
    settings.router,
    scan.router,
    setup.router,
    data.router,
    capture_views.router,
    measure.router,
    manage.router,
    calibration.router,
    calibration_import.router,
    calibration_figures.router,
    verify.router,
    docs.router,
)
