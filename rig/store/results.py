"""The result directory: written, read, listed and described here only; its file names exist once.

A result directory (``rig process -o OUT``, the console's ``DATA/results/NAME``, a batch's
``OUT/NAME``) holds::

    report.json    what was done and found (always)
    phase.npy      absolute (or unwrapped) phase, NaN where invalid (always)
    mask.npy       valid pixels (always)
    preview.png    colour-mapped height, or phase without a calibration (always)
    wrapped.npy    wrapped phase per frequency (without a calibration)
    height.npy     heights in mm, NaN where invalid (with a calibration)
    uncertainty.npy  predicted height sigma in mm, NaN where invalid (with a calibration, phase shifting)
    unresolved.npy   bool, valid pixels whose fringe orders no evidence settled (when the correction found any)
    exposure.npy   per pixel the exposure (us) that weighed most in the fused phase (captures at several exposures)
    + one file per output format asked for (with a calibration): :data:`FORMATS`

A new output format is one :class:`OutputFormat` entry in :data:`FORMATS` (copy ``"stl"``): its
``--format`` name, its file, what it needs and a function that writes it; ``rig process``,
``rig batch`` and the console's downloads pick it up from there.

Writing is atomic (a staging sibling renamed into place, :mod:`rig.store.files`) and never
replaces an existing result unless asked (:class:`ResultExistsError` otherwise). Reading goes
through the safe file layer: regular files only (no FIFO, device or symbolic link), inside the
directory, size-capped; staging names (``*.incomplete-*``, ``*.replaced-*``) are never results.

For a front-end: :func:`write_result` (map ResultExistsError to "409, choose another name"),
:func:`list_results`, :func:`read_result` (the map, mask, points and report of a saved result),
:func:`describe_result` (key figures and the files held, with media types), :func:`result_file`
(the checked path of a file to download) and :data:`MEDIA_TYPES` (every downloadable name).
"""

from __future__ import annotations

import hashlib
import io
import os
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rig.errors import ConfigError, OutputError, ResultExistsError
from rig.pipeline.result import ProcessResult, build_report
from rig.store import files
from rig.store import result_files as encode

REPORT = "report.json"
PHASE = "phase.npy"
MASK = "mask.npy"
PREVIEW = "preview.png"
WRAPPED = "wrapped.npy"
HEIGHT = "height.npy"
UNCERTAINTY = "uncertainty.npy"
UNRESOLVED = "unresolved.npy"
EXPOSURE = "exposure.npy"
POINTS = "points.ply"
MESH_PLY = "mesh.ply"
MESH_STL = "mesh.stl"
MESH_OBJ = "mesh.obj"
POINTS_E57 = "points.e57"

RESULT_KINDS = ("output",)  # what files.KINDS calls a result directory (its report.json says "fpp-rig ...")
OCTET = "application/octet-stream"


# --------------------------------------------------------------------------- output formats


@dataclass(frozen=True)
class OutputFormat:
    """One optional file of a result directory, written from the points of a calibrated result.

    ``write(result, path)`` writes the file; ``extra`` names the pip extra that provides
    ``module`` when the format needs a library beyond the core ones.
    """

    name: str  # the --format name
    file: str  # the file in the result directory
    key: str  # its key in report.json's "files"
    what: str  # one line for help and docs
    write: Callable[[ProcessResult, Path], Any]
    media_type: str = OCTET
    module: str | None = None
    extra: str | None = None

    def missing_library(self) -> str | None:
        """The one-line reason this format cannot be written here, or None when it can."""
        if self.module is None:
            return None
        try:
            __import__(self.module)
        except ImportError:
            return f"--format {self.name}: needs the {self.module} library: pip install 'fpp-rig[{self.extra}]'"
        return None


def _mesh(result: ProcessResult) -> tuple[np.ndarray, np.ndarray]:
    """The valid points (N, 3) in mm and the triangles (M, 3) joining grid neighbours (see processing.geometry.mesh)."""
    from processing.geometry.mesh import grid_triangles

    grid = result.points
    assert grid is not None
    return result.valid_points(), grid_triangles(grid, result.mask)


def _write_points_ply(result: ProcessResult, path: Path) -> None:
    encode.write_ply(
        path, result.valid_points(), encode.texture(result.object, result.mask), sigma=result.valid_sigma()
    )


def _write_mesh_ply(result: ProcessResult, path: Path) -> None:
    points, faces = _mesh(result)
    encode.write_ply(path, points, encode.texture(result.object, result.mask), faces=faces)


def _write_stl(result: ProcessResult, path: Path) -> None:
    encode.write_stl(path, *_mesh(result))


def _write_obj(result: ProcessResult, path: Path) -> None:
    encode.write_obj(path, *_mesh(result))


def _write_e57(result: ProcessResult, path: Path) -> None:
    encode.write_e57(path, result.valid_points(), encode.texture(result.object, result.mask))


FORMATS: dict[str, OutputFormat] = {
    entry.name: entry
    for entry in (
        OutputFormat("ply", POINTS, "points", "point cloud, binary PLY with grey texture", _write_points_ply),
        OutputFormat("mesh-ply", MESH_PLY, "mesh_ply", "triangle mesh, binary PLY with faces", _write_mesh_ply),
        OutputFormat("stl", MESH_STL, "mesh_stl", "triangle mesh, binary STL", _write_stl, "model/stl"),
        OutputFormat("obj", MESH_OBJ, "mesh_obj", "triangle mesh, Wavefront OBJ text", _write_obj, "model/obj"),
        OutputFormat(
            "e57",
            POINTS_E57,
            "points_e57",
            "point cloud, ASTM E57 (pip extra e57)",
            _write_e57,
            module="pye57",
            extra="e57",
        ),
    )
}
DEFAULT_FORMATS: tuple[str, ...] = ("ply",)  # what `rig process` writes without --format


def parse_formats(text: str | Iterable[str] | None) -> tuple[str, ...]:
    """``"ply,stl"`` (or names) to checked format names, in registry order; ConfigError naming what is wrong.

    None gives :data:`DEFAULT_FORMATS`. A format whose library is missing is refused here, before any work.
    """
    if text is None:
        return DEFAULT_FORMATS
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    unknown = [n for n in names if n not in FORMATS]
    if unknown or not names:
        raise ConfigError(f"--format: expected names from {', '.join(FORMATS)}, found {','.join(unknown) or 'none'}")
    for name in names:
        reason = FORMATS[name].missing_library()
        if reason:
            raise ConfigError(reason)
    return tuple(name for name in FORMATS if name in names)


MEDIA_TYPES: dict[str, str] = {
    POINTS: OCTET,
    HEIGHT: OCTET,
    UNCERTAINTY: OCTET,
    UNRESOLVED: OCTET,
    EXPOSURE: OCTET,
    PHASE: OCTET,
    MASK: OCTET,
    WRAPPED: OCTET,
    REPORT: "application/json",
    PREVIEW: "image/png",
    **{entry.file: entry.media_type for entry in FORMATS.values()},
}


# --------------------------------------------------------------------------- names


def is_staging_name(name: str) -> bool:
    """Whether ``name`` is a staging or set-aside name of the file layer (never a result, never an input)."""
    return files.staging_mark(name) is not None


# The longest default name: its staging sibling (NAME.incomplete-XXXXXXXX) must fit in one file name too.
NAME_LIMIT = files.MAX_NAME_BYTES - len(files.INCOMPLETE_MARK) - 8


def default_name(base: str, suffix: str, limit: int = NAME_LIMIT) -> str:
    """``base + suffix``, or when that is longer than ``limit`` bytes, ``base`` cut short with a short hash of it.

    Deterministic (the same base gives the same name) and distinct for bases that share their start.
    """
    name = base + suffix
    if len(name.encode()) <= limit:
        return name
    tag = "-" + hashlib.sha256(base.encode()).hexdigest()[:8]
    room = limit - len((tag + suffix).encode())
    head = base.encode()[: max(room, 0)].decode("utf-8", errors="ignore").rstrip(".-_")
    return head + tag + suffix


def default_output(capture: Path) -> Path:
    """Where ``rig process CAPTURE`` writes without ``-o``: ``CAPTURE-processed`` (a valid name however long)."""
    capture = Path(capture) if Path(capture).name else Path(capture).resolve()  # "." names its folder
    return capture.with_name(default_name(capture.name, "-processed"))


# --------------------------------------------------------------------------- writing


def check_target(out_dir: str | Path, overwrite: bool) -> None:
    """Before computing: ``out_dir`` can be written and is new or empty, or (``overwrite``) an earlier result.

    :class:`ResultExistsError` when it exists and ``overwrite`` is false; OutputError for anything else.
    """
    target = Path(out_dir)
    files.check_writable(target, RESULT_KINDS, True, OutputError)  # anything but an earlier result: refused
    if not overwrite and os.path.lexists(target) and not files.is_empty_directory(target):
        raise ResultExistsError(f"{target}: already exists; refusing to replace it (--overwrite replaces a result)")


def write_result(
    result: ProcessResult,
    out_dir: str | Path,
    formats: Sequence[str] = DEFAULT_FORMATS,
    overwrite: bool = False,
    extra: Mapping[str, Any] | None = None,
    staged_inputs: tuple[Path, Path] | None = None,
) -> dict[str, Any]:
    """Write ``result`` as the directory ``out_dir``; returns the report (also in report.json).

    The files are written into a fresh temporary sibling and renamed into place: after any
    interruption ``out_dir`` holds the complete old or the complete new result. An existing
    ``out_dir`` is replaced only with ``overwrite`` (and only an earlier result or an empty
    directory); :class:`ResultExistsError` otherwise. ``formats``: names of :data:`FORMATS`
    (written when the result has points, i.e. a calibration). ``extra`` keys are added to
    report.json (``rig batch`` records its input fingerprint there). ``staged_inputs``: see
    :func:`rig.pipeline.result.build_report`.
    """
    t0 = time.perf_counter()
    check_target(out_dir, overwrite)
    with files.staged_directory(Path(out_dir), RESULT_KINDS, overwrite, OutputError) as staging:
        report = _write_files(result, staging, parse_formats(formats), staged_inputs)
        report["timings_s"]["outputs"] = time.perf_counter() - t0
        report.update(extra or {})
        encode.write_report(staging / REPORT, report)
    return report


def _write_files(
    result: ProcessResult, out: Path, formats: Sequence[str], staged_inputs: tuple[Path, Path] | None
) -> dict[str, Any]:
    """Every file but report.json; returns the report with its ``preview`` and ``files``."""
    obj = result.object
    assert obj.unwrapped is not None
    report = build_report(result, staged_inputs)
    written: dict[str, str] = {}
    phase = obj.unwrapped.phase.astype(np.float64)  # a copy: NaN outside the mask
    np.copyto(phase, np.nan, where=~result.mask)
    if result.height is None:
        shows, unit, title, shown = "phase", "rad", "absolute phase" if obj.unwrapped.absolute else "phase", phase
    else:
        shows, unit, shown = report["quantity"], "mm", result.height
        title = shows
    # The preview (colour map and PNG encoding, which release the GIL) is drawn on a thread while
    # the arrays and the point files are written.
    with ThreadPoolExecutor(1) as pool:
        preview = pool.submit(encode.write_preview, out / PREVIEW, shown, unit, title)
        written["phase"] = encode.write_array(out / PHASE, phase).name
        written["mask"] = encode.write_array(out / MASK, np.asarray(result.mask, dtype=bool)).name
        if obj.unresolved is not None and obj.unresolved.any():
            written["unresolved"] = encode.write_array(out / UNRESOLVED, obj.unresolved & result.mask).name
        if obj.exposure_map is not None:
            exposure = np.where(result.mask, obj.exposure_map, np.float32(np.nan)).astype(np.float32)
            written["exposure"] = encode.write_array(out / EXPOSURE, exposure).name
        if result.height is None:
            written["wrapped"] = encode.write_array(out / WRAPPED, encode.wrapped_maps(obj)).name
        else:
            written["height"] = encode.write_array(out / HEIGHT, np.asarray(result.height, dtype=np.float32)).name
            if result.uncertainty is not None:
                written["uncertainty"] = encode.write_array(out / UNCERTAINTY, result.uncertainty).name
            for name in formats:
                entry = FORMATS[name]
                entry.write(result, out / entry.file)
                written[entry.key] = entry.file
        low, high = preview.result()
    report["preview"] = {"shows": shows, "unit": unit, "range": [low, high]}
    written["preview"] = PREVIEW
    written["report"] = REPORT
    report["files"] = written
    return report


# --------------------------------------------------------------------------- reading


def _inside(directory: Path, file: str, where: str) -> Path:
    """``directory/file`` for a plain file name of a result, the directory itself resolved and not a staging name."""
    if "/" in file or file in ("", ".", ".."):
        raise OutputError(f"{where}: {file!r}: expected a file name of a result")
    if is_staging_name(Path(directory).resolve().name):
        raise OutputError(f"{where}: never committed (a staging directory of an interrupted write), not a result")
    return Path(directory) / file


def read_bytes(directory: str | Path, file: str, where: str | None = None) -> bytes:
    """One file of a result directory: a regular file (no link, FIFO or device), size-capped."""
    where = where or str(directory)
    path = _inside(Path(directory), file, where)
    return files.read_regular(path, f"{where}/{file}", OutputError, missing="missing")


def read_report(directory: str | Path, where: str | None = None) -> dict[str, Any]:
    """A result's report.json (regular file, manifest size and depth limits, NaN tolerated from old reports)."""
    where = where or str(directory)
    data = read_bytes(directory, REPORT, where)
    if len(data) > files.limits().max_manifest_bytes:
        raise OutputError(f"{where}/{REPORT}: larger than {files.limits().max_manifest_bytes} bytes")
    report = files.parse_json(data.decode("utf-8", errors="replace"), f"{where}/{REPORT}", OutputError, strict=False)
    if not isinstance(report, dict):
        raise OutputError(f"{where}/{REPORT}: expected a JSON object, found {type(report).__name__}")
    return report


def _read_array(directory: Path, file: str, where: str) -> np.ndarray:
    data = read_bytes(directory, file, where)
    try:
        return np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise OutputError(f"{where}/{file}: not a NumPy array file: {exc}") from None


def has_file(directory: str | Path, file: str) -> bool:
    """Whether the result has an entry named ``file`` (reading it then insists on a regular file)."""
    return os.path.lexists(Path(directory) / file)


@dataclass
class StoredResult:
    """A result directory read back: the map it shows, its mask, points and report."""

    values: np.ndarray  # (H, W) float32: heights in mm, or phase in rad without a calibration
    unit: str  # "mm" or "rad"
    shows: str  # "height" or "phase"
    mask: np.ndarray  # (H, W) bool
    points: np.ndarray | None  # (H, W, 3) float32 mm, NaN where invalid
    report: dict[str, Any]
    exposure: np.ndarray | None = None  # (H, W) float32 us: the exposure each pixel drew on most (several exposures)


def read_result(directory: str | Path, where: str | None = None) -> StoredResult:
    """Read a result directory through the safe file layer; OutputError (one line) if anything does not fit."""
    directory = Path(directory)
    where = where or str(directory)
    report = read_report(directory, where)
    mask = _read_array(directory, MASK, where).astype(bool, copy=False)
    if has_file(directory, HEIGHT):
        values, unit, shows = _read_array(directory, HEIGHT, where), "mm", "height"
    else:
        values, unit, shows = _read_array(directory, PHASE, where), "rad", "phase"
    if values.shape != mask.shape or values.ndim != 2:
        raise OutputError(
            f"{where}: expected the map and mask.npy of the same (H, W), found {values.shape} and {mask.shape}"
        )
    points = None
    if has_file(directory, POINTS):
        try:
            valid = encode.parse_ply_points(read_bytes(directory, POINTS, where))
        except (ValueError, StopIteration, IndexError) as exc:
            raise OutputError(f"{where}/{POINTS}: not a point cloud of this program: {exc}") from None
        if len(valid) != int(np.count_nonzero(mask)):
            raise OutputError(
                f"{where}/{POINTS}: expected {int(np.count_nonzero(mask))} points (mask.npy), found {len(valid)}"
            )
        points = np.full((*mask.shape, 3), np.nan, dtype=np.float32)
        points[mask] = valid
    exposure = None
    if has_file(directory, EXPOSURE):
        exposure = np.asarray(_read_array(directory, EXPOSURE, where), dtype=np.float32)
        if exposure.shape != mask.shape:
            raise OutputError(
                f"{where}/{EXPOSURE}: expected the (H, W) of mask.npy {mask.shape}, found {exposure.shape}"
            )
    return StoredResult(np.asarray(values, dtype=np.float32), unit, shows, mask, points, report, exposure)


def result_file(directory: str | Path, file: str) -> Path:
    """The path of a downloadable file of a result (a name of :data:`MEDIA_TYPES`), checked to be a
    regular file of the directory itself (no symbolic link out of it, no FIFO); OutputError otherwise."""
    if file not in MEDIA_TYPES:
        raise OutputError(f"file: expected one of {', '.join(MEDIA_TYPES)}, found {file!r}")
    path = _inside(Path(directory), file, str(directory))
    os.close(files.open_regular(path, str(path), OutputError, missing="not written"))
    return path


# --------------------------------------------------------------------------- listing


def is_result(directory: str | Path) -> bool:
    """Whether ``directory`` is a committed result: a real directory, not a staging name, with a report.json."""
    directory = Path(directory)
    if is_staging_name(directory.name) or directory.is_symlink() or not directory.is_dir():
        return False
    return has_file(directory, REPORT)


def list_results(root: str | Path) -> list[str]:
    """Names of the committed results directly inside ``root``, newest first (by report.json's time)."""
    entries = []
    with os.scandir(root) as children:
        for child in children:
            if is_result(child.path):
                entries.append((os.lstat(Path(child.path) / REPORT).st_mtime, child.name))
    return [name for _, name in sorted(entries, reverse=True)]


def describe_result(directory: str | Path) -> dict[str, Any]:
    """What the page or a script shows of a result: its key figures and the files it holds (with media types)."""
    report = read_report(directory)
    held = [name for name in MEDIA_TYPES if has_file(directory, name)]
    return {
        "capture": report.get("capture"),
        "calibration": report.get("calibration"),
        "valid_fraction": report.get("valid_fraction"),
        "height_mm": report.get("height_mm"),
        "methods": report.get("methods", {}),
        "files": [{"name": name, "media_type": MEDIA_TYPES[name]} for name in held],
    }


def capture_name(report: Mapping[str, Any]) -> str | None:
    """The name of the capture a result was made from, when it lies in a ``captures`` folder (the console's)."""
    capture = Path(str(report.get("capture") or ""))
    return capture.name if capture.parent.name == "captures" else None
