"""The capture store: read, verify and atomically write capture directories (capture-format.md v1).

A capture is a directory holding ``capture.json`` and frame images. Reading validates the
manifest, checks every frame's sha256 and, when frames are loaded, their size and bit depth;
every problem is a :class:`rig.errors.CaptureError` whose one-line message names the file, the
field, what was expected and what was found.

Writing goes through :class:`CaptureWriter`: frames and a manifest with ``complete: false`` are
written into a temporary sibling directory ``<name>.incomplete-<random>``; the manifest is
rewritten (atomically, by rename) after every frame, so an interruption leaves a directory that
is visibly incomplete and that ``read_capture(..., salvage=True)`` can still read. That directory
is deliberately *left for salvage*, never removed: frames from a long scan are worth more than
the disk space. Only when every pattern has its frame is ``complete`` set to true, the manifest
and directories fsynced and the directory renamed to its final path, so a capture that claims
to be complete always is, power loss included. An existing capture is never overwritten unless
the caller asks for it.

Durability of an interrupted capture: each frame file is fsynced as it is written; the
``complete: false`` manifest is fsynced at most every :attr:`CaptureWriter.manifest_sync_s`
(1 s) and when the capture is left incomplete, not after every frame (each fsync of it costs
several milliseconds per frame). An exception or Ctrl-C loses nothing (the operating system
still writes the files); a power loss or kernel crash in the middle of a scan may leave a
manifest that lists only the frames of up to its last second, or, within the first second, none.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import logging
import os
import time
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path, PurePosixPath
from typing import Any, Literal

import numpy as np

from calibration.jsonfile import write_bytes_durable, write_json_atomic
from processing.projection.patterns import (
    CAPTURE_KINDS,
    PROJECTION_KEYS,
    PROJECTOR_ONLY_KINDS,
    Pattern,
    PatternError,
    parse_pattern,
    same_projection,
)
from rig.errors import CaptureError
from rig.store import files
from rig.store.exposures import exposure_sets

log = logging.getLogger(__name__)

FORMAT = "fpp-capture"
VERSION = 1
MANIFEST = "capture.json"
INCOMPLETE_MARK = files.INCOMPLETE_MARK


LOAD_THREADS = min(4, os.cpu_count() or 1)  # frame reading threads (I/O, sha256 and PNG decoding overlap)


def utc_now() -> str:
    """Current UTC time in the manifest's ISO 8601 form (seconds, trailing Z)."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def dtype_for_bit_depth(bit_depth: int) -> np.dtype:
    """Image dtype that stores ``bit_depth``: uint8 up to 8, uint16 up to 16, float32 for 32."""
    if 1 <= bit_depth <= 8:
        return np.dtype(np.uint8)
    if 9 <= bit_depth <= 16:
        return np.dtype(np.uint16)
    if bit_depth == 32:
        return np.dtype(np.float32)
    raise ValueError(f"bit_depth: expected 1..16 or 32, found {bit_depth}")


def bit_depth_of(dtype: np.dtype) -> int:
    """Nominal bit depth of an image dtype (uint8 -> 8, uint16 -> 16, float32 -> 32)."""
    table = {np.dtype(np.uint8): 8, np.dtype(np.uint16): 16, np.dtype(np.float32): 32}
    try:
        return table[np.dtype(dtype)]
    except KeyError:
        raise ValueError(f"image dtype: expected uint8, uint16 or float32, found {np.dtype(dtype)}") from None


# --------------------------------------------------------------------------- manifest validation


def _fail(where: str, field: str, expected: str, found: Any) -> CaptureError:
    return CaptureError(f"{where}: {field}: expected {expected}, found {found!r}")


def _int(where: str, obj: Mapping[str, Any], key: str, field: str, minimum: int | None = None) -> int:
    if key not in obj:
        raise CaptureError(f"{where}: {field}: missing")
    value = obj[key]
    if isinstance(value, bool) or not isinstance(value, int) or (minimum is not None and value < minimum):
        raise _fail(where, field, "an integer" + (f" >= {minimum}" if minimum is not None else ""), value)
    return value


def _mapping(where: str, obj: Mapping[str, Any], key: str) -> Mapping[str, Any]:
    if key not in obj:
        raise CaptureError(f"{where}: {key}: missing")
    if not isinstance(obj[key], Mapping):
        raise _fail(where, key, "an object", obj[key])
    return obj[key]


def _sized(where: str, manifest: Mapping[str, Any], key: str) -> Mapping[str, Any]:
    """``manifest[key]`` (camera or projector): an object whose width and height are within the image limits."""
    block = _mapping(where, manifest, key)
    files.check_image_size(
        _int(where, block, "width", f"{key}.width", minimum=1),
        _int(where, block, "height", f"{key}.height", minimum=1),
        f"{where}: {key}",
        CaptureError,
    )
    return block


def validate_pattern(where: str, index: int, pattern: Any) -> Pattern:
    """Check one ``patterns[index]`` entry against the pattern model; return it typed.

    Only capture-format v1 kinds: a projector-only kind (the alignment grid) is refused by name.
    """
    field = f"patterns[{index}]"
    if not isinstance(pattern, Mapping):
        raise _fail(where, field, "an object", pattern)
    kind = pattern.get("kind")
    if isinstance(kind, str) and kind in PROJECTOR_ONLY_KINDS:
        raise CaptureError(
            f"{where}: {field}.kind: {kind!r} is a projector-only alignment pattern, not part of capture-format v1 "
            f"(expected one of {', '.join(CAPTURE_KINDS)})"
        )
    try:
        return parse_pattern(pattern)
    except PatternError as exc:
        raise CaptureError(f"{where}: {field}{'.' + exc.key if exc.key else ''}: {exc.detail}") from None


def check_relative_path(where: str, field: str, file: Any) -> PurePosixPath:
    """A frame path must be relative and stay inside the capture directory (no absolute, no ``..``)."""
    return files.relative_path(file, where, field, CaptureError)


_HEX_DIGITS = frozenset("0123456789abcdef")


def validate_manifest(manifest: Any, where: str) -> list[Pattern]:
    """Check a parsed capture.json against capture-format.md v1; raise CaptureError on the first problem.

    Every pattern must have exactly one frame and every frame must name an existing pattern.
    Returns the patterns typed (parsed once here, kept by :func:`read_capture`).
    """
    if not isinstance(manifest, Mapping):
        raise _fail(where, "top level", "a JSON object", type(manifest).__name__)
    _check_header(manifest, where)
    patterns = manifest.get("patterns")
    if not isinstance(patterns, list) or not patterns:
        raise _fail(where, "patterns", "a non-empty list", patterns)
    max_frames = files.limits().max_frames
    if len(patterns) > max_frames:
        raise _fail(where, "patterns", f"at most {max_frames} entries (RIG_MAX_FRAMES)", len(patterns))
    models = [validate_pattern(where, i, pattern) for i, pattern in enumerate(patterns)]
    frames = manifest.get("frames")
    if not isinstance(frames, list):
        raise _fail(where, "frames", "a list", frames)
    exposure_sets(models, where)  # a multi-exposure capture's sequences line up (rig/store/exposures.py)
    owner = _check_frames(frames, len(patterns), where)
    if manifest["complete"]:
        missing = [i for i in range(len(patterns)) if i not in owner]
        if missing:
            listed = ", ".join(str(i) for i in missing[:8]) + (" ..." if len(missing) > 8 else "")
            raise CaptureError(
                f"{where}: frames: expected one frame for each of {len(patterns)} patterns, "
                f"found {len(frames)}; no frame for pattern(s) {listed}"
            )
    return models


def _check_header(manifest: Mapping[str, Any], where: str) -> None:
    """The manifest's format, version, scene, completeness flag, camera and projector."""
    if manifest.get("format") != FORMAT:
        raise _fail(where, "format", repr(FORMAT), manifest.get("format"))
    if manifest.get("version") != VERSION:
        raise _fail(where, "version", f"{VERSION} (the version this program reads)", manifest.get("version"))
    if not isinstance(manifest.get("scene"), str):
        raise _fail(where, "scene", "a string such as 'object' or 'reference'", manifest.get("scene"))
    if not isinstance(manifest.get("complete"), bool):
        raise _fail(where, "complete", "true or false", manifest.get("complete"))
    camera = _sized(where, manifest, "camera")
    depth = _int(where, camera, "bit_depth", "camera.bit_depth", minimum=1)
    if not (depth <= 16 or depth == 32):
        raise _fail(where, "camera.bit_depth", "1..16 or 32", depth)
    _sized(where, manifest, "projector")


def _check_frames(frames: list[Any], count: int, where: str) -> dict[int, int]:
    """Each frame entry names one of ``count`` patterns (at most one frame each), a file used once and
    its sha256; returns which frame index holds each pattern."""
    owner: dict[int, int] = {}
    names: dict[str, int] = {}
    for i, frame in enumerate(frames):
        field = f"frames[{i}]"
        if not isinstance(frame, Mapping):
            raise _fail(where, field, "an object", frame)
        pattern = _int(where, frame, "pattern", f"{field}.pattern", minimum=0)
        if pattern >= count:
            raise _fail(where, f"{field}.pattern", f"an index 0 .. {count - 1} into patterns", pattern)
        if pattern in owner:
            raise CaptureError(
                f"{where}: {field}: extra frame for pattern {pattern} (frames[{owner[pattern]}] already has it); "
                "expected exactly one frame per pattern"
            )
        owner[pattern] = i
        file = str(check_relative_path(where, f"{field}.file", frame.get("file")))
        if file in names:
            raise CaptureError(f"{where}: {field}.file: {file!r} is also frames[{names[file]}].file")
        names[file] = i
        digest = frame.get("sha256")
        if not isinstance(digest, str) or len(digest) != 64 or not _HEX_DIGITS.issuperset(digest.lower()):
            raise _fail(where, f"{field}.sha256", "a 64-digit hex sha256 digest", digest)
    return owner


# --------------------------------------------------------------------------- reading


def decode_image(data: bytes, where: str) -> np.ndarray:
    """Decode PNG/TIFF bytes unchanged (8/16-bit integer or 32-bit float); CaptureError if corrupt or too large."""
    return files.decode_image(data, where, CaptureError)


@dataclass
class Capture:
    """A capture directory read from disk. ``manifest`` is the whole capture.json, extra keys included."""

    path: Path
    manifest: dict[str, Any]

    @property
    def manifest_path(self) -> Path:
        return self.path / MANIFEST

    @property
    def scene(self) -> str:
        return self.manifest["scene"]

    @property
    def complete(self) -> bool:
        return bool(self.manifest["complete"])

    @property
    def width(self) -> int:
        return int(self.manifest["camera"]["width"])

    @property
    def height(self) -> int:
        return int(self.manifest["camera"]["height"])

    @property
    def shape(self) -> tuple[int, int]:
        """Camera image shape (height, width)."""
        return (self.height, self.width)

    @property
    def bit_depth(self) -> int:
        return int(self.manifest["camera"]["bit_depth"])

    @property
    def projector_size(self) -> tuple[int, int]:
        projector = self.manifest["projector"]
        return (int(projector["width"]), int(projector["height"]))

    @property
    def patterns(self) -> list[dict[str, Any]]:
        """The manifest's pattern entries as written (extra keys included)."""
        return self.manifest["patterns"]

    @functools.cached_property
    def pattern_models(self) -> list[Pattern]:
        """The patterns, typed (the manifest was validated when read, so they parse); parsed once."""
        return [parse_pattern(p) for p in self.patterns]

    @property
    def frames(self) -> list[dict[str, Any]]:
        return self.manifest["frames"]

    def frame_index(self) -> dict[int, dict[str, Any]]:
        """Frame entry of each pattern index that has one."""
        return {int(frame["pattern"]): frame for frame in self.frames}

    def frame_path(self, frame: Mapping[str, Any]) -> Path:
        """Where a frame's file is, every link resolved; CaptureError unless it is inside the capture."""
        field = f"frame of pattern {frame.get('pattern')}: file"
        return files.contained(self.path, frame["file"], str(self.manifest_path), field, CaptureError)

    def read_frame_bytes(self, frame: Mapping[str, Any]) -> bytes:
        """The file of one frame (a regular file inside the capture), its sha256 checked."""
        path = self.frame_path(frame)
        where = str(self.path / str(frame["file"]))
        data = files.read_regular(path, where, CaptureError, missing=f"frame file missing (pattern {frame['pattern']})")
        digest = hashlib.sha256(data).hexdigest()
        if digest != str(frame["sha256"]).lower():
            raise CaptureError(f"{where}: checksum mismatch: expected sha256 {frame['sha256']}, found {digest}")
        return data

    def verify_checksums(self) -> None:
        """Read every frame file and check its sha256; CaptureError names the first bad file."""
        for frame in self.frames:
            self.read_frame_bytes(frame)

    def load_frame(self, pattern: int, frame: Mapping[str, Any] | None = None) -> np.ndarray:
        """Image of one pattern, checked for checksum, size, channels and bit depth: (H, W)."""
        if frame is None:
            frame = self.frame_index().get(pattern)
        if frame is None:
            raise CaptureError(f"{self.manifest_path}: frames: no frame for pattern {pattern}")
        where = str(self.path / str(frame["file"]))
        image = decode_image(self.read_frame_bytes(frame), where)
        if image.ndim != 2:
            channels = image.shape[2] if image.ndim == 3 else image.ndim
            raise CaptureError(f"{where}: expected a single-channel image, found {channels} channels")
        if image.shape != self.shape:
            raise CaptureError(
                f"{where}: image size: expected {self.width}x{self.height} (camera.width x camera.height), "
                f"found {image.shape[1]}x{image.shape[0]}"
            )
        expected = dtype_for_bit_depth(self.bit_depth)
        if image.dtype != expected:
            raise CaptureError(
                f"{where}: bit depth: expected {expected} for camera.bit_depth {self.bit_depth}, found {image.dtype}"
            )
        return image

    def load_frames(self, patterns: Iterable[int] | None = None, threads: int | None = None) -> np.ndarray:
        """Frames of the given pattern indices (default all, in pattern order) as an (N, H, W) array.

        Reading, checksums and decoding run on ``threads`` threads (hashlib and OpenCV release
        the GIL: about twice as fast on two cores); each frame lands in its slot of the stack.
        The first failing frame in pattern order is the one reported, as when loading in turn.
        """
        threads = LOAD_THREADS if threads is None else threads
        indices = list(range(len(self.patterns)) if patterns is None else patterns)
        if not indices:
            raise CaptureError(f"{self.manifest_path}: frames: no pattern to load")
        index = self.frame_index()
        stack = np.empty((len(indices), *self.shape), dtype=dtype_for_bit_depth(self.bit_depth))

        def load(slot: int) -> None:
            stack[slot] = self.load_frame(indices[slot], index.get(indices[slot]))

        if threads <= 1 or len(indices) == 1:
            for slot in range(len(indices)):
                load(slot)
            return stack

        with ThreadPoolExecutor(min(threads, len(indices))) as pool:
            futures = [pool.submit(load, slot) for slot in range(len(indices))]
            for future in futures:  # in pattern order: the first bad frame is the one named
                future.result()
        return stack

    def write_manifest(self) -> None:
        """Rewrite capture.json from ``manifest`` (extra keys kept), atomically."""
        write_json_atomic(self.manifest_path, self.manifest)


def read_capture(path: str | os.PathLike[str], salvage: bool = False, verify: bool = True) -> Capture:
    """Open a capture directory (or its capture.json) and validate it.

    Parameters
    ----------
    path : path
        The capture directory, or its ``capture.json``.
    salvage : bool
        Accept a capture whose ``complete`` is false (frames that exist are still checked).
    verify : bool
        Check every frame's sha256 now (images are decoded and size-checked when loaded).
    """
    path = Path(path)
    files.check_path_text(str(path), "capture path", CaptureError)
    if path.name == MANIFEST and path.is_file():
        path = path.parent
    manifest_path = path / MANIFEST
    if not path.exists():
        note = files.leftovers(path)
        raise CaptureError(f"{path}: capture directory not found" + (f" ({note})" if note else ""))
    if not path.is_dir():
        raise CaptureError(f"{path}: expected a capture directory, found a file")
    manifest = files.read_json(manifest_path, CaptureError, "missing (not a capture directory?)")
    models = validate_manifest(manifest, str(manifest_path))
    capture = Capture(path=path, manifest=manifest)
    capture.__dict__["pattern_models"] = models  # the cached property, already parsed
    if not salvage and not capture.complete:
        raise CaptureError(
            f"{manifest_path}: complete: expected true, found false (interrupted or still being written; "
            "salvage it explicitly to read what is there)"
        )
    if not salvage:
        files.check_committed_input(path, "capture", CaptureError, "salvage it explicitly to read what is there")
    if verify:
        capture.verify_checksums()
    return capture


def pattern_signature(pattern: Mapping[str, Any]) -> dict[str, Any]:
    """The keys of a pattern that determine what is projected."""
    return {key: pattern[key] for key in PROJECTION_KEYS if key in pattern}


def check_same_patterns(reference: Capture, capture: Capture) -> None:
    """A reference capture must use the patterns and camera size of the capture it serves."""
    if reference.shape != capture.shape:
        raise CaptureError(
            f"{reference.manifest_path}: camera size: expected {capture.width}x{capture.height} "
            f"like {capture.manifest_path}, found {reference.width}x{reference.height}"
        )
    if (
        reference.projector_size[0] != capture.projector_size[0]
        or reference.projector_size[1] != capture.projector_size[1]
    ):
        raise CaptureError(
            f"{reference.manifest_path}: projector: expected {capture.projector_size} like "
            f"{capture.manifest_path}, found {reference.projector_size}"
        )
    # a capture taken at several exposures projects its base sequence at each: the reference needs that sequence once
    ref_base = exposure_sets(reference.pattern_models, str(reference.manifest_path)).base
    obj_base = exposure_sets(capture.pattern_models, str(capture.manifest_path)).base
    if len(ref_base) != len(obj_base):
        raise CaptureError(
            f"{reference.manifest_path}: patterns: expected the {len(obj_base)} patterns of "
            f"{capture.manifest_path}, found {len(ref_base)}"
        )
    for i, (ref, obj) in enumerate(zip(ref_base, obj_base)):
        if not same_projection(ref, obj):
            raise CaptureError(
                f"{reference.manifest_path}: patterns[{i}]: expected {pattern_signature(obj)} like "
                f"{capture.manifest_path}, found {pattern_signature(ref)}"
            )


# --------------------------------------------------------------------------- writing


def encode_image(image: np.ndarray, bit_depth: int) -> tuple[bytes, str]:
    """Encode a frame losslessly: PNG for 8/16-bit integers, TIFF for float32. Returns (bytes, suffix)."""
    expected = dtype_for_bit_depth(bit_depth)
    if image.dtype != expected:
        raise ValueError(f"image: expected dtype {expected} for bit_depth {bit_depth}, found {image.dtype}")
    import cv2  # as in decode_image

    suffix = ".tiff" if expected == np.float32 else ".png"
    ok, buffer = cv2.imencode(suffix, np.ascontiguousarray(image))
    if not ok:
        raise CaptureError(f"cannot encode a {image.dtype} frame as {suffix}")
    return buffer.tobytes(), suffix


class CaptureWriter:
    """Write a capture atomically; use as a context manager.

    >>> with CaptureWriter(path, camera={...}, projector={...}, patterns=[...]) as writer:
    ...     for i, image in enumerate(images):
    ...         writer.add_frame(i, image)

    On a clean exit with every pattern captured, the capture appears at ``path`` with
    ``complete: true``. On an exception (or missing frames), the temporary directory
    ``<path>.incomplete-XXXX`` stays, with ``complete: false`` and an ``interrupted`` note, for
    salvage (``read_capture(dir, salvage=True)``); it is never renamed to ``path``.
    See the module docstring for what survives a power loss.
    """

    manifest_sync_s = 1.0  # longest time between fsyncs of an incomplete capture's manifest

    def __init__(
        self,
        path: str | os.PathLike[str],
        camera: Mapping[str, Any],
        projector: Mapping[str, Any],
        patterns: Sequence[Mapping[str, Any]],
        scene: str = "object",
        extra: Mapping[str, Any] | None = None,
        overwrite: bool = False,
    ) -> None:
        self.path = Path(path)
        self.overwrite = overwrite
        manifest: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "scene": scene,
            "created_utc": utc_now(),
            "complete": False,
            "camera": dict(camera),
            "projector": dict(projector),
            "patterns": [dict(p) for p in patterns],
            "frames": [],
        }
        for key, value in (extra or {}).items():
            manifest.setdefault(key, copy.deepcopy(value))
        validate_manifest(manifest, f"{self.path}/{MANIFEST} (being written)")
        self.manifest = manifest
        self.bit_depth = int(manifest["camera"]["bit_depth"])
        self.shape = (int(manifest["camera"]["height"]), int(manifest["camera"]["width"]))
        self.temp_path: Path | None = None
        self._done: set[int] = set()
        self._manifest_synced_at = 0.0  # time.monotonic() of the last fsynced manifest

    def __enter__(self) -> CaptureWriter:
        files.check_target(
            self.path, ("capture",), self.overwrite, CaptureError, hint=" (choose another path or remove it)"
        )
        self.temp_path = files.make_staging(self.path, CaptureError)
        (self.temp_path / "frames").mkdir()
        self._manifest_synced_at = time.monotonic()
        self._write_manifest(durable=False)
        return self

    def _write_manifest(self, durable: bool = True) -> None:
        """Rewrite the manifest; a non-durable rewrite is fsynced anyway once manifest_sync_s has passed."""
        assert self.temp_path is not None
        now = time.monotonic()
        durable = durable or now - self._manifest_synced_at >= self.manifest_sync_s
        write_json_atomic(self.temp_path / MANIFEST, self.manifest, durable=durable)
        if durable:
            self._manifest_synced_at = now

    def add_frame(self, pattern: int, image: np.ndarray, **metadata: Any) -> Path:
        """Store the frame of pattern index ``pattern`` (metadata: timestamp_s, exposure_us, ...)."""
        if self.temp_path is None:
            raise RuntimeError("CaptureWriter.add_frame called outside its 'with' block")
        if not 0 <= pattern < len(self.manifest["patterns"]):
            raise ValueError(f"pattern: expected 0 .. {len(self.manifest['patterns']) - 1}, found {pattern}")
        if pattern in self._done:
            raise ValueError(f"pattern: frame {pattern} was already written")
        image = np.asarray(image)
        if image.shape != self.shape:
            raise ValueError(f"image: expected shape {self.shape} (camera), found {image.shape}")
        data, suffix = encode_image(image, self.bit_depth)
        relative = f"frames/{pattern:03d}{suffix}"
        write_bytes_durable(self.temp_path / relative, data)
        entry = {"pattern": pattern, "file": relative, "sha256": hashlib.sha256(data).hexdigest()}
        entry.update(metadata)
        self.manifest["frames"].append(entry)
        self._done.add(pattern)
        self._write_manifest(durable=False)
        return self.temp_path / relative

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> Literal[False]:
        if self.temp_path is None:
            return False
        if exc_type is not None:
            self._leave_incomplete(f"{exc_type.__name__}: {exc}" if str(exc) else exc_type.__name__)
            return False
        missing = len(self.manifest["patterns"]) - len(self._done)
        if missing:
            self._leave_incomplete(f"{missing} pattern(s) without a frame")
            raise CaptureError(
                f"{self.path}: {missing} of {len(self.manifest['patterns'])} patterns have no frame; "
                f"partial capture left at {self.temp_path}"
            )
        self._commit()
        return False

    def _leave_incomplete(self, reason: str) -> None:
        assert self.temp_path is not None
        self.manifest["interrupted"] = reason
        try:
            self._write_manifest()
        except OSError:  # the frames stay; the last manifest written still says complete: false
            pass
        log.warning("capture %s not completed (%s); partial data left at %s", self.path, reason, self.temp_path)

    def _commit(self) -> None:
        """Rename the finished directory onto ``path`` (see :func:`rig.store.files.commit_directory`).

        ``complete: true`` is written only under the commit lock, just before the rename; the
        ``.incomplete-`` name keeps a directory killed in between from passing for a capture.
        """
        assert self.temp_path is not None
        self.manifest["frames"].sort(key=lambda frame: frame["pattern"])

        def mark_complete() -> None:
            self.manifest["complete"] = True
            self._write_manifest()

        try:
            files.commit_directory(self.temp_path, self.path, ("capture",), self.overwrite, CaptureError, mark_complete)
        except BaseException as exc:
            self.manifest["complete"] = False
            self._leave_incomplete(f"not committed: {exc}")
            raise
        self.temp_path = None


def write_capture(
    path: str | os.PathLike[str],
    frames: np.ndarray | Sequence[np.ndarray],
    patterns: Sequence[Mapping[str, Any]],
    projector: Mapping[str, Any],
    scene: str = "object",
    bit_depth: int | None = None,
    extra: Mapping[str, Any] | None = None,
    overwrite: bool = False,
) -> Capture:
    """Write a whole capture at once: frame ``i`` belongs to ``patterns[i]``. Returns it, re-read."""
    frames = [np.asarray(f) for f in frames]
    if len(frames) != len(patterns):
        raise ValueError(f"frames: expected one per pattern ({len(patterns)}), found {len(frames)}")
    if not frames:
        raise ValueError("frames: expected at least one")
    height, width = frames[0].shape[:2]
    depth = bit_depth if bit_depth is not None else bit_depth_of(frames[0].dtype)
    camera = {"width": int(width), "height": int(height), "bit_depth": depth}
    with CaptureWriter(path, camera, projector, patterns, scene=scene, extra=extra, overwrite=overwrite) as writer:
        for i, image in enumerate(frames):
            writer.add_frame(i, image)
    return read_capture(path)
