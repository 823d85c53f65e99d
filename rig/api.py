"""The public Python API: what a notebook, a script, the console and the batch runner call.

Everything here is a thin, typed entry to a service; nothing prints and nothing is written unless
asked for (:func:`write_outputs`, :func:`scan`, :func:`calibrate`)::

    from rig import api

    capture = api.load_capture("part-001")                 # checked manifest, frames not decoded yet
    result = api.process(capture, calibration="cal")        # in memory: no file written
    result.height, result.phase, result.mask, result.points, result.report
    api.write_outputs(result, "part-001-processed")         # the files of `rig process`

    scan = api.scan("part-002", config="rig.toml")          # the simulated rig when config is None

Long calls take ``progress``: a :class:`rig.events.Reporter` whose sink receives
:class:`rig.events.Event` objects and whose cancel token stops the work cleanly.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from rig.events import Cancelled, CancelToken, Event, Reporter
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions

if TYPE_CHECKING:
    from calibration.store import Calibration
    from rig.acquisition.loop import ScanResult
    from rig.config import RigConfig
    from rig.pipeline.run import ProcessResult
    from rig.store.capture import Capture

__all__ = [
    "DEFAULT_CORRECTION",
    "CancelToken",
    "Cancelled",
    "Event",
    "ProcessOptions",
    "Reporter",
    "load_capture",
    "load_calibration",
    "load_config",
    "process",
    "write_outputs",
    "scan",
]

PathLike = str | Path


def load_config(path: PathLike | None = None) -> RigConfig:
    """A rig config file (TOML), validated; ``None`` gives the built-in simulated rig."""
    from rig.config import load_config as _load

    return _load(None if path is None else Path(path))


def load_capture(path: PathLike, salvage: bool = False) -> Capture:
    """A capture's manifest, checked against the format (frames are decoded when processed)."""
    from rig.store.capture import read_capture

    return read_capture(path, salvage=salvage, verify=False)


def load_calibration(path: PathLike) -> Calibration:
    """A calibration directory's ``calibration.json``, validated."""
    from calibration.store import read_calibration

    return read_calibration(path)


def process(
    capture: Capture | PathLike,
    calibration: PathLike | None = None,
    options: ProcessOptions | None = None,
    progress: Reporter | None = None,
    salvage: bool = False,
) -> ProcessResult:
    """Process a capture in memory (no file written) with the same pipeline as ``rig process``.

    ``options`` default to what ``rig process`` does without flags (``--correction auto``). The
    result carries ``height`` (mm, NaN where invalid; None without a calibration), ``phase``,
    ``mask``, ``points`` and ``report`` (report.json's content).
    """
    from rig.pipeline.run import process as _process

    path = capture.path if not isinstance(capture, (str, Path)) else Path(capture)
    options = ProcessOptions(correction=DEFAULT_CORRECTION) if options is None else options
    return _process(path, calibration, options, progress=progress, salvage=salvage)


def write_outputs(result: ProcessResult, out_dir: PathLike) -> dict[str, Any]:
    """Write the files of ``rig process`` (height.npy, points.ply, report.json, ...); returns the report."""
    from rig.pipeline.outputs import write_outputs as _write

    return _write(result, out_dir)


def scan(
    output: PathLike,
    config: RigConfig | PathLike | None = None,
    scene: str = "object",
    overwrite: bool = False,
    progress: Reporter | None = None,
) -> ScanResult:
    """Scan with the rig of ``config`` (the simulated rig when None) into a new capture ``output``."""
    from rig.acquisition.scan import scan as _scan
    from rig.config import RigConfig as _RigConfig

    rig_config = config if isinstance(config, _RigConfig) else load_config(config)
    return _scan(rig_config, Path(output), scene=scene, overwrite=overwrite, progress=progress)
