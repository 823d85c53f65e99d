"""The scan service: open the rig a config describes, project each pattern, capture, write a capture.

Front-ends (``rig scan``, ``rig calibrate``, the console) call :func:`scan`; it never prints.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rig.acquisition.exposure_plan import ExposurePlan, plan_exposures
from rig.acquisition.loop import AcquisitionSettings, FrameHandler, run_scan
from rig.config import RigConfig
from rig.errors import CaptureError, ConfigError
from rig.hardware.assembly import open_rig
from rig.store import files
from rig.store.exposures import with_exposures

if TYPE_CHECKING:
    from rig.acquisition.loop import ScanResult
    from rig.events import ProgressSink
    from rig.hardware.assembly import RigDevices

log = logging.getLogger(__name__)

# A scan's exposures: times in microseconds, "auto" (the exposure assistant), or None
Exposures = Sequence[float] | str | None


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
    exposures: Exposures = None,
) -> ScanResult:
    """Open the rig of ``config``, scan ``scene`` into ``output`` and close the rig.

    ``patterns``: the capture-format entries to project (default the config's ``[scan]`` set,
    :meth:`rig.config.ScanConfig.patterns`). ``progress`` gets ``begin(frames)`` then one step per
    stored frame; cancelling its token stops the scan at the next frame, leaving the capture
    visibly incomplete. ``exposures``: exposure times in microseconds (each exposure's full
    sequence in turn), ``"auto"`` for the exposure assistant's choice
    (:mod:`rig.acquisition.exposure_plan`), None for ``[scan] exposures_us`` (empty: one exposure).
    """

    # fail before opening any device: an existing non-capture is never replaced, an unwritable place never tried
    files.check_writable(
        Path(output), ("capture",), overwrite, CaptureError, hint=" (choose another -o or pass --overwrite)"
    )
    patterns = config.scan.patterns() if patterns is None else list(patterns)
    exposures = config.scan.exposures_us if exposures is None else exposures
    with open_rig(config, scene=scene) as devices:
        chosen, plan = resolve_exposures(devices, exposures)
        if progress is not None:
            progress.begin(len(patterns) * max(len(chosen), 1), f"scan {output}")
        return scan_with(
            devices, output, patterns, scene=scene, overwrite=overwrite, progress=progress, exposures=chosen, plan=plan
        )


def resolve_exposures(
    devices: RigDevices, exposures: Exposures, progress: ProgressSink | None = None
) -> tuple[tuple[float, ...], ExposurePlan | None]:
    """The exposures of a scan (the assistant's plan for ``"auto"``), checked against the camera's limits."""
    if exposures is None:
        return (), None
    plan = None
    if isinstance(exposures, str):
        if exposures != "auto":
            raise ConfigError(f"exposures: expected a list of times in microseconds or 'auto', found {exposures!r}")
        plan = plan_exposures(devices, progress)
        chosen: tuple[float, ...] = plan.exposures_us
    else:
        chosen = tuple(float(e) for e in exposures)
    low, high = devices.camera.exposure_limits_us
    outside = [e for e in chosen if not low <= e <= high]
    if outside:
        raise ConfigError(
            f"exposures: {', '.join(f'{e:g}' for e in outside)} us outside {devices.camera.name}'s limits "
            f"{low:g} .. {high:g} us"
        )
    return chosen, plan


def scan_with(
    devices: RigDevices,
    output: Path,
    patterns: Sequence[Mapping[str, Any]] | None = None,
    scene: str = "object",
    overwrite: bool = False,
    progress: ProgressSink | None = None,
    exposure_us: float | None = None,
    gain: float | None = None,
    exposures: Exposures = None,
    plan: ExposurePlan | None = None,
    on_frame: FrameHandler | None = None,
    extra: Mapping[str, Any] | None = None,
) -> ScanResult:
    """Scan with devices that are already open (a console or a calibration session holds them).

    ``scene`` is the label capture.json records; what is really in front of the rig is whatever
    the operator (or the simulated world) put there. ``progress`` is stepped once per frame.
    ``exposure_us`` and ``gain`` override the config's camera settings (the console's controls).
    ``exposures``: several exposure times (each exposure's full sequence in turn) or ``"auto"``
    (the exposure assistant chooses, after a pre-capture); None: one. ``plan``: the assistant's
    plan that chose ``exposures``, recorded in capture.json. ``on_frame(index, image)`` receives
    each frame as it arrives (:func:`rig.acquisition.loop.run_scan`). ``extra``: more top-level
    keys for capture.json (the console's part name and notes).
    """

    config = devices.config
    if output.exists() and not overwrite:
        raise CaptureError(f"{output}: already exists; refusing to overwrite (choose another -o or pass --overwrite)")
    patterns = config.scan.patterns() if patterns is None else list(patterns)
    chosen, auto_plan = resolve_exposures(devices, exposures)
    plan = auto_plan or plan
    patterns = with_exposures(patterns, chosen)
    if len(chosen) == 1:  # one exposure asked for: the whole scan at it
        exposure_us = chosen[0]
    settings = AcquisitionSettings(
        show_timeout_s=config.scan.show_timeout_s,
        fetch_timeout_s=config.scan.fetch_timeout_s,
        retries=config.scan.retries,
    )
    log.info("scanning %d patterns into %s (%s)", len(patterns), output, settings)
    keys: dict[str, Any] = {"rig_config": str(config.source) if config.source else "built-in simulated rig"}
    keys.update(extra or {})
    if devices.simulation is not None:
        keys["simulation"] = devices.simulation.description()
    if plan is not None:
        keys["exposure_plan"] = plan.to_dict()
    result = run_scan(
        output,
        patterns,
        devices.projector,
        devices.camera,
        devices.trigger,
        settings,
        scene=scene,
        extra=keys,
        exposure_us=config.camera.exposure_us if exposure_us is None else exposure_us,
        gain=config.camera.gain if gain is None else gain,
        progress=progress,
        overwrite=overwrite,
        on_frame=on_frame,
    )
    result.exposure_plan = plan
    return result
