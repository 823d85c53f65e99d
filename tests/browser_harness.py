"""What every browser test module of the console shares: the system Chromium driven by Playwright,
the module skipped with its reason when either is missing, and where screenshots go.

With ``RIG_SCREENSHOTS=1`` the frames are 640x480 and screenshots go to docs/console/ (the
README's pictures), else the frames are 320x240 and screenshots go to a temporary folder.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
playwright_api = pytest.importorskip(
    "playwright.sync_api", reason="playwright not installed (pip install -e '.[test]')"
)
if CHROMIUM is None:
    pytest.skip("no chromium browser (apt-get install chromium)", allow_module_level=True)

SCREENSHOTS = os.environ.get("RIG_SCREENSHOTS") == "1"
SHOTS = (
    Path(__file__).resolve().parent.parent / "docs" / "console"
    if SCREENSHOTS
    else Path(tempfile.gettempdir()) / "rig-console-screenshots"
)
WIDTH, HEIGHT = (640, 480) if SCREENSHOTS else (320, 240)


def shot(page: Any, name: str, full_page: bool = False) -> None:
    """A screenshot of ``page`` as ``SHOTS/name.png``."""
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / f"{name}.png"), full_page=full_page)
