"""The scan service: open the rig a config describes, project each pattern, capture, write a capture.

Front-ends (``rig scan``, ``rig calibrate``, the console) call :func:`scan`; it never prints.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rig.acquisition.loop import AcquisitionSettings, FrameHandler, run_scan
from rig.config import RigConfig
from rig.errors import CaptureError
from rig.hardware.assembly import open_rig
from rig.store import files

if TYPE_CHECKING:
    from rig.acquisition.loop import ScanResult
    from rig.events import ProgressSink
    from rig.hardware.assembly import RigDevices

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
    patterns: Sequence[Mapping[str, Any]] | None = None,
    progress: ProgressSink | None = None,
) -> ScanResult:
    """Open the rig of ``config``, scan ``scene`` into ``output`` and close the rig.

    ``patterns``: the capture-format entries to project (default the config's ``[scan]`` set,
    :meth:`rig.config.ScanConfig.patterns`). ``progress`` gets ``begin(frames)`` then one step per
    stored frame; cancelling its token stops the scan at the next frame, leaving the capture
    visibly incomplete.
    """

    # fail before opening any device: an existing non-capture is never replaced, an unwritable place never tried
    files.check_writable(
        Path(output), ("capture",), overwrite, CaptureError, hint=" (choose another -o or pass --overwrite)"
    )
    patterns = config.scan.patterns() if patterns is None else list(patterns)
    if progress is not None:
        progress.begin(len(patterns), f"scan {output}")
    with open_rig(config, scene=scene) as devices:
        return scan_with(devices, output, patterns, scene=scene, overwrite=overwrite, progress=progress)


def scan_with(
    devices: RigDevices,
    output: Path,
    patterns: Sequence[Mapping[str, Any]] | None = None,
    scene: str = "object",
    overwrite: bool = False,
    progress: ProgressSink | None = None,
    exposure_us: float | None = None,
    gain: float | None = None,
    on_frame: FrameHandler | None = None,
) -> ScanResult:
    """Scan with devices that are already open (a console or a calibration session holds them).

    ``scene`` is the label capture.json records; what is really in front of the rig is whatever
    the operator (or the simulated world) put there. ``progress`` is stepped once per frame.
    ``exposure_us`` and ``gain`` override the config's camera settings (the console's controls).
    ``on_frame(index, image)`` receives each frame as it arrives (:func:`rig.acquisition.loop.run_scan`).
    """

    config = devices.config
    if output.exists() and not overwrite:
        raise CaptureError(f"{output}: already exists; refusing to overwrite (choose another -o or pass --overwrite)")
    patterns = config.scan.patterns() if patterns is None else list(patterns)
    settings = AcquisitionSettings(
        show_timeout_s=config.scan.show_timeout_s,
        fetch_timeout_s=config.scan.fetch_timeout_s,
        retries=config.scan.retries,
    )
    log.info("scanning %d patterns into %s (%s)", len(patterns), output, settings)
    extra: dict[str, Any] = {"rig_config": str(config.source) if config.source else "built-in simulated rig"}
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
        exposure_us=config.camera.exposure_us if exposure_us is None else exposure_us,
        gain=config.camera.gain if gain is None else gain,
        progress=progress,
        overwrite=overwrite,
        on_frame=on_frame,
    )
