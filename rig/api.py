"""The public Python API: what a notebook, a script, the console and the batch runner call.

Everything here is a thin, typed entry to a service; nothing prints and nothing is written unless
asked for (:func:`write_outputs`, :func:`process_to`, :func:`scan`, :func:`scan_then_process`)::

    from rig import api

    capture = api.load_capture("part-001")                 # checked manifest, frames not decoded yet
    result = api.process(capture, calibration="cal")        # in memory: no file written
    result.height, result.phase, result.mask, result.points, result.report
    api.write_outputs(result, "part-001-processed")         # the files of `rig process`

    stack = api.FrameStack(frames, patterns, projector_size=(1280, 800))  # frames held in memory
    result = api.process(stack, calibration="cal")

    scan = api.scan("part-002", config="rig.toml")          # the simulated rig when config is None

``api.process`` is the one processing entry of every front-end (``rig process``, ``rig scan
--process``, ``rig demo``, ``rig batch``, the calibration session, the console): its defaults are
``rig process``'s defaults (``ProcessOptions()`` corrects with ``auto``).

Long calls take ``progress``: a :class:`rig.events.Reporter` whose sink receives
:class:`rig.events.Event` objects and whose cancel token stops the work cleanly.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

import numpy as np

from calibration.errors import CalibrationError
from rig.errors import CaptureError, ConfigError, OutputError, ResultExistsError
from rig.events import Cancelled, CancelToken, Event, ProgressSink, Reporter
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions

if TYPE_CHECKING:
    from calibration.store import Calibration
    from rig.acquisition.loop import ScanResult
    from rig.config import RigConfig
    from rig.pipeline.result import ProcessResult
    from rig.store.capture import Capture

__all__ = [
    "DEFAULT_CORRECTION",
    "CalibrationError",
    "CaptureError",
    "CancelToken",
    "Cancelled",
    "Event",
    "FrameStack",
    "OutputError",
    "ProcessOptions",
    "Reporter",
    "ResultExistsError",
    "check_scan_then_process",
    "load_capture",
    "load_calibration",
    "load_config",
    "process",
    "process_steps",
    "process_to",
    "write_outputs",
    "scan",
    "scan_then_process",
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


@dataclass(frozen=True)
class FrameStack:
    """Frames held in memory with the patterns they were taken under: a capture without files.

    ``frames``: (N, H, W) camera images, one per pattern in pattern order (uint8 or uint16 for
    8..16-bit cameras, float32 for 32-bit); ``patterns``: N capture-format pattern entries (dicts
    as in capture.json, or :class:`processing.projection.patterns.Pattern` objects); ``projector_size``:
    (width, height) of the projector the patterns were made for. ``name`` is what report.json
    records as the capture.
    """

    frames: np.ndarray
    patterns: Sequence[Mapping[str, Any]]
    projector_size: tuple[int, int]
    bit_depth: int | None = None  # default: 8 for uint8, 16 for uint16, 32 for float32
    scene: str = "object"
    name: str = "in-memory"

    def capture(self) -> Capture:
        """A :class:`Capture` describing the stack (no directory, no frame files); CaptureError if it does not fit."""
        from rig.store.capture import Capture, bit_depth_of, validate_pattern

        frames = np.asarray(self.frames)
        where = f"{self.name} (frames in memory)"
        if frames.ndim != 3 or len(frames) != len(self.patterns):
            raise CaptureError(
                f"{where}: frames: expected (N, H, W) with N = {len(self.patterns)} patterns, found shape {frames.shape}"
            )
        models = [validate_pattern(where, i, dict(p)) for i, p in enumerate(self.patterns)]
        width, height = (int(v) for v in self.projector_size)
        manifest = {
            "format": "fpp-capture",
            "version": 1,
            "scene": self.scene,
            "complete": True,
            "camera": {
                "width": frames.shape[2],
                "height": frames.shape[1],
                "bit_depth": self.bit_depth or bit_depth_of(frames.dtype),
            },
            "projector": {"width": width, "height": height},
            "patterns": [m.to_dict() for m in models],
            "frames": [],
        }
        capture = Capture(path=Path(self.name), manifest=manifest)
        capture.__dict__["pattern_models"] = models
        return capture


Source = Union["Capture", FrameStack, str, Path]


def process(
    source: Source,
    calibration: PathLike | None = None,
    options: ProcessOptions | None = None,
    progress: ProgressSink | None = None,
    *,
    salvage: bool = False,
    quick: Callable[[ProcessResult], None] | None = None,
    cache_reference: bool = False,
) -> ProcessResult:
    """Process a capture (a path, a loaded :class:`Capture`, or a :class:`FrameStack`) in memory.

    The same pipeline and defaults as ``rig process``: ``options`` None is ``ProcessOptions()``
    (``--correction auto``). A loaded capture is not read from disk again; its frames are decoded
    (and checked) by the run. The result carries ``height`` (mm, NaN where invalid; None without a
    calibration), ``phase``, ``mask``, ``points`` and ``report`` (report.json's content).

    ``quick``: called first with a result computed without the correction (fast, on screen in
    seconds) when the options ask for one; then the full run is returned. That is the console's
    quick-then-full pass: ``progress`` receives both runs, each starting with its own ``begin``::

        result = api.process(capture_dir, calibration_dir, options, progress=reporter,
                             quick=lambda first: show(first, final=False))
        show(result, final=True)
        api.write_outputs(result, data / "results" / name)  # ResultExistsError (HTTP 409) if taken

    ``cache_reference``: also write the processed reference plane to the on-disk reference cache
    (what ``rig process`` does; memory is always used; see :mod:`rig.pipeline.reference_cache`).
    """
    from rig.pipeline.run import process as run

    options = ProcessOptions() if options is None else options
    capture, frames = _capture_of(source, salvage)
    if quick is not None and options.correction != "none":
        quick(run(capture, calibration, replace(options, correction="none"), progress=progress, frames=frames))
    return run(capture, calibration, options, progress=progress, reference_cache_to_disk=cache_reference, frames=frames)


def _capture_of(source: Source, salvage: bool) -> tuple[Capture, np.ndarray | None]:
    """The capture of a source (read once when a path) and its frames when they are held in memory."""
    from rig.store.capture import Capture

    if isinstance(source, FrameStack):
        return source.capture(), np.asarray(source.frames)
    if isinstance(source, Capture):
        return source, None
    return load_capture(source, salvage=salvage), None


def process_steps(with_reference: bool) -> int:
    """Progress steps of one :func:`process` run (stages of each capture, then height)."""
    from rig.pipeline.run import total_steps

    return total_steps(with_reference)


def write_outputs(
    result: ProcessResult,
    out_dir: PathLike,
    formats: Sequence[str] | None = None,
    overwrite: bool = False,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Write the files of ``rig process`` (height.npy, points.ply, report.json, ...); returns the report.

    ``formats``: output format names of :data:`rig.store.results.FORMATS` (default: points.ply only).
    An existing ``out_dir`` is replaced only with ``overwrite`` (an earlier result, never anything
    else); :class:`rig.store.results.ResultExistsError` otherwise.
    """
    from rig.store.results import parse_formats, write_result

    return write_result(result, out_dir, parse_formats(formats), overwrite=overwrite, extra=extra)


def process_to(
    source: Source,
    out_dir: PathLike,
    calibration: PathLike | None = None,
    options: ProcessOptions | None = None,
    progress: ProgressSink | None = None,
    *,
    formats: Sequence[str] | None = None,
    overwrite: bool = False,
    salvage: bool = False,
) -> dict[str, Any]:
    """:func:`process` then :func:`write_outputs`, the output checked before any work; returns the report.

    What ``rig process`` does: the processed reference plane is cached in the calibration directory.
    """
    from rig.store.results import check_target, parse_formats

    chosen = parse_formats(formats)
    if calibration is None and formats is not None:
        raise ConfigError(f"--format {','.join(chosen)}: points and meshes need a calibration (--calibration CAL)")
    check_target(out_dir, overwrite)  # an unwritable or taken output fails now, not after the computation
    result = process(source, calibration, options, progress, salvage=salvage, cache_reference=True)
    return write_outputs(result, out_dir, chosen, overwrite=overwrite)


def scan(
    output: PathLike,
    config: RigConfig | PathLike | None = None,
    scene: str = "object",
    overwrite: bool = False,
    progress: ProgressSink | None = None,
    exposures: Sequence[float] | str | None = None,
) -> ScanResult:
    """Scan with the rig of ``config`` (the simulated rig when None) into a new capture ``output``.

    ``exposures``: times in microseconds (each exposure's full sequence in turn), ``"auto"`` (the
    exposure assistant chooses; its plan is ``result.exposure_plan``), None: ``[scan] exposures_us``.
    """
    from rig.acquisition.scan import scan as _scan
    from rig.config import RigConfig as _RigConfig

    rig_config = config if isinstance(config, _RigConfig) else load_config(config)
    return _scan(rig_config, Path(output), scene=scene, overwrite=overwrite, progress=progress, exposures=exposures)


def check_scan_then_process(
    capture: PathLike, calibration: PathLike | None, process_output: PathLike, overwrite: bool = False
) -> None:
    """Everything that would stop "scan, then process" after the scan, checked before it starts.

    The capture's and the result's places are free or empty (or, with ``overwrite``, an earlier
    capture and an earlier result) and the calibration reads and validates. Raises the one-line
    error of the first problem.
    """
    from rig.store import files
    from rig.store.results import check_target

    if calibration is None:
        raise ConfigError("process: needs a calibration (to turn phase into height)")
    if files.same_path(Path(capture), Path(process_output)):
        raise ConfigError(f"{process_output}: the result cannot be written over its own capture")
    files.check_writable(
        Path(capture), ("capture",), overwrite, CaptureError, hint=" (choose another name or overwrite)"
    )
    load_calibration(calibration)
    check_target(process_output, overwrite)


def scan_then_process(
    output: PathLike,
    calibration: PathLike,
    process_output: PathLike | None = None,
    config: RigConfig | PathLike | None = None,
    scene: str = "object",
    overwrite: bool = False,
    options: ProcessOptions | None = None,
    scan_progress: ProgressSink | None = None,
    process_progress: ProgressSink | None = None,
    exposures: Sequence[float] | str | None = None,
) -> tuple[ScanResult, dict[str, Any]]:
    """Scan into ``output``, then process it with ``calibration`` into ``process_output``
    (default ``OUTPUT-processed``); every pre-check (:func:`check_scan_then_process`) runs before
    the rig is opened. Returns the scan and the result's report."""
    from rig.store.results import default_output

    destination = Path(process_output) if process_output is not None else default_output(Path(output))
    check_scan_then_process(output, calibration, destination, overwrite)
    scanned = scan(output, config, scene=scene, overwrite=overwrite, progress=scan_progress, exposures=exposures)
    report = process_to(scanned.path, destination, calibration, options, process_progress, overwrite=overwrite)
    return scanned, report
