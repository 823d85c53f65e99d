"""The scan service: open the rig a config describes, project each pattern, capture, write a capture.

Front-ends (``rig scan``, ``rig calibrate``, the console) call :func:`scan`; it never prints.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rig.config import RigConfig
from rig.errors import CaptureError
from rig.progress import Progress

if TYPE_CHECKING:
    from rig.acquisition.loop import ScanResult

log = logging.getLogger(__name__)


def default_capture_path(now: datetime | None = None) -> Path:
    """``capture-YYYYmmdd-HHMMSS`` in the current directory (UTC)."""
    now = now or datetime.now(timezone.utc)
    return Path(f"capture-{now.strftime('%Y%m%d-%H%M%S')}")


def scan(
    config: RigConfig,
    output: Path,
    scene: str = "object",
    overwrite: bool = False,
    show_progress: bool = True,
    patterns: Sequence[Mapping[str, Any]] | None = None,
    label: str = "scan",
) -> ScanResult:
    """Open the rig of ``config``, scan ``scene`` into ``output`` and close the rig.

    ``patterns``: the capture-format entries to project (default the config's ``[scan]`` set,
    :meth:`rig.config.ScanConfig.patterns`); ``label`` starts the progress line.
    """
    from rig.acquisition.loop import AcquisitionSettings, run_scan
    from rig.hardware.assembly import open_rig

    if output.exists() and not overwrite:  # fail before opening any device
        raise CaptureError(f"{output}: already exists; refusing to overwrite (choose another -o or pass --overwrite)")
    patterns = config.scan.patterns() if patterns is None else list(patterns)
    settings = AcquisitionSettings(
        show_timeout_s=config.scan.show_timeout_s,
        fetch_timeout_s=config.scan.fetch_timeout_s,
        retries=config.scan.retries,
    )
    log.info("scanning %d patterns into %s (%s)", len(patterns), output, settings)
    with open_rig(config, scene=scene) as devices, Progress(f"{label} {output}", total=len(patterns), quiet=not show_progress) as progress:
        extra = {"rig_config": str(config.source) if config.source else "built-in simulated rig"}
        if devices.simulation is not None:
            extra["simulation"] = devices.simulation.description()
        return run_scan(
            output,
            patterns,
            devices.projector,
            devices.camera,
            devices.trigger,
            settings,
            scene=scene,
            extra=extra,
            exposure_us=config.camera.exposure_us,
            gain=config.camera.gain,
            progress=progress,
            overwrite=overwrite,
        )
