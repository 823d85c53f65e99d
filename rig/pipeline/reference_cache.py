"""The calibration's reference plane, processed once and reused by every scan it serves.

A reference-plane or polynomial calibration subtracts the reference capture's absolute phase from
each object's. That capture never changes between scans, yet every ``rig process`` used to load,
phase, unwrap and correct it again (1.5 s of 3.5 s with the ``auto`` correction). Its processed
phase, mask and predicted phase sigma are kept:

- in memory, for a long-running process (the console, a batch worker): the last few entries;
- on disk, in the user's cache directory (``$RIG_CACHE_DIR``, else ``$XDG_CACHE_HOME/fpp-rig``,
  else ``~/.cache/fpp-rig``; ``RIG_CACHE_DIR=off`` disables it), as
  ``reference/reference-<source>-<options>.npz``, written atomically (temporary file, fsync,
  rename) by ``rig process`` and ``rig scan --process`` (:func:`rig.api.process_to`)
  and read by every run. Nothing is written into the user's calibration or capture directories; a
  cache that cannot be written just goes without (a log line says so). In-memory processing
  (:func:`rig.api.process`) writes no file.

The key is a SHA-256 of everything the result depends on: this cache's format, the program
version, the reference capture's manifest (its frames' checksums, patterns and camera) and the
size and modification time of each frame file, the calibration directory's files (calibration.json
and any table beside it) and the processing options. Recapturing the reference, recalibrating or
choosing another option misses the cache. The newest entries are kept, the oldest removed.
Single-shot references (which keep more than a phase) are not cached.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
from collections import OrderedDict
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from rig import __version__
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.state import SceneState, UnwrappedPhase

log = logging.getLogger(__name__)

FORMAT = 3  # 2: entries keep the predicted phase sigma (processing.geometry.uncertainty); 3: fused frequencies
DIRECTORY = "reference"  # below the cache root
PREFIX = "reference-"
CACHE_ENV = "RIG_CACHE_DIR"
_MEMORY: OrderedDict[str, dict[str, Any]] = OrderedDict()
_MEMORY_ENTRIES = 4
_DISK_ENTRIES = 16  # entries kept on disk (references, calibrations and option sets together)


def cacheable(state: SceneState) -> bool:
    """Whether the reference ``state`` can be cached (a phase-shifting capture in a calibration directory)."""
    return not state.groups.single_shot and state.calibration is not None and state.calibration.path is not None


def _stats(paths: list[Path]) -> list[list[Any]]:
    out: list[list[Any]] = []
    for path in paths:
        try:
            info = path.stat()
        except OSError:
            out.append([path.name, None])
            continue
        out.append([path.name, info.st_size, info.st_mtime_ns])
    return out


def cache_key(state: SceneState, options: ProcessOptions) -> str:
    """The entry's key: ``<source>-<options>``, two hex SHA-256 prefixes (see the module docstring).

    ``source`` covers the program, the reference capture and the calibration: when it changes,
    every entry of the directory is stale. ``options`` covers the processing options and the fringe
    axis: runs with other options (``--correction none`` and the default) keep entries side by side.
    """
    calibration = state.calibration
    assert calibration is not None and calibration.path is not None
    capture = state.capture
    cal_files = sorted(p for p in calibration.path.iterdir() if p.is_file())
    # only stat'ed for the key (reading them goes through the capture's contained paths)
    frames = [capture.path / str(frame.get("file", "")) for frame in capture.frames]
    source = {
        "format": FORMAT,
        "program": __version__,
        "reference_manifest": capture.manifest,
        "reference_frames": _stats(frames),
        "calibration": calibration.to_dict(),
        "calibration_files": _stats(cal_files),
    }
    chosen = {"options": asdict(options), "axis": state.axis}
    return f"{_digest(source)}-{_digest(chosen)}"


def _digest(content: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(content, sort_keys=True, default=str).encode("utf-8")).hexdigest()[:32]


def cache_root() -> Path | None:
    """The user's cache directory for fpp-rig, or None when ``RIG_CACHE_DIR=off`` disables it."""
    chosen = os.environ.get(CACHE_ENV)
    if chosen is not None:
        return None if chosen.strip().lower() in ("", "off", "none", "0") else Path(chosen)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fpp-rig"


def _cache_dir() -> Path | None:
    root = cache_root()
    return None if root is None else root / DIRECTORY


def load(state: SceneState, key: str) -> bool:
    """Fill ``state`` (unwrapped phase, info, notes) from memory or the cache directory; False on a miss."""
    entry = _MEMORY.get(key)
    if entry is None:
        directory = _cache_dir()
        entry = None if directory is None else _read(directory / f"{PREFIX}{key}.npz", key)
        if entry is None:
            return False
        _remember(key, entry)
    else:
        _MEMORY.move_to_end(key)
    meta = entry["meta"]
    state.unwrapped = UnwrappedPhase(
        phase=entry["phase"],
        valid=entry["valid"],
        frequency=meta["frequency"],
        method=meta["method"],
        absolute=meta["absolute"],
        orders=None,
    )
    state.phase_sigma = entry.get("phase_sigma")  # the predicted phase noise, as when processed
    state.info = dict(meta["info"])  # the same report as when processed; timings say "cached"
    state.notes = list(meta["notes"])
    state.timings = {"cached": 0.0}
    return True


def _read(path: Path, key: str) -> dict[str, Any] | None:
    if path.is_symlink() or not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            if meta.get("key") != key:
                return None
            entry = {"phase": data["phase"], "valid": data["valid"], "meta": meta}
            if "phase_sigma" in data.files:
                entry["phase_sigma"] = data["phase_sigma"]
    except (OSError, ValueError, KeyError) as exc:
        log.info("reference cache %s unreadable (%s); processing the reference again", path, exc)
        return None
    for name in ("phase", "valid", "phase_sigma"):
        if name in entry:
            entry[name].flags.writeable = False  # shared between runs: nobody may change it in place
    return entry


def store(state: SceneState, key: str, to_disk: bool = True) -> None:
    """Keep the processed reference in memory and, with ``to_disk`` when the directory allows it, on disk."""
    unwrapped = state.unwrapped
    assert unwrapped is not None
    meta = {
        "key": key,
        "frequency": unwrapped.frequency,
        "method": unwrapped.method,
        "absolute": unwrapped.absolute,
        "info": state.info,
        "notes": state.notes,
    }
    try:
        meta_text = json.dumps(meta, default=_json_default)
    except TypeError:
        return  # a stage recorded something JSON cannot hold: do not cache what we could not reload
    phase, valid = np.array(unwrapped.phase), np.array(unwrapped.valid, dtype=bool)
    arrays = {"phase": phase, "valid": valid}
    if state.phase_sigma is not None:
        arrays["phase_sigma"] = np.array(state.phase_sigma, dtype=np.float32)
    for arr in arrays.values():
        arr.flags.writeable = False
    _remember(key, {**arrays, "meta": json.loads(meta_text)})
    if not to_disk:
        return
    directory = _cache_dir()
    if directory is None:
        return
    try:
        _write_atomic(directory, key, arrays, meta_text)
    except OSError as exc:
        log.info("reference cache not written in %s (%s); the reference is processed again next time", directory, exc)


def _write_atomic(directory: Path, key: str, arrays: dict[str, Any], meta_text: str) -> None:
    """Write the entry of ``key`` (temporary file, fsync, rename); drop stale entries and the oldest beyond a few."""
    if directory.is_symlink():
        raise OSError(f"{directory} is a link; not writing through it")
    directory.mkdir(parents=True, exist_ok=True)
    name = f"{PREFIX}{key}.npz"
    handle, temp = tempfile.mkstemp(prefix=".tmp-", suffix=".npz", dir=directory)
    try:
        with os.fdopen(handle, "wb") as out:
            np.savez(out, meta=np.array(meta_text), **arrays)
            out.flush()
            os.fsync(out.fileno())
        os.replace(temp, directory / name)
    except BaseException:
        Path(temp).unlink(missing_ok=True)
        raise
    others = [entry for entry in directory.glob(f"{PREFIX}*.npz") if not entry.is_symlink() and entry.name != name]
    others.sort(key=lambda p: p.stat().st_mtime_ns, reverse=True)
    for entry in others[_DISK_ENTRIES - 1 :]:
        entry.unlink(missing_ok=True)


def _remember(key: str, entry: dict[str, Any]) -> None:
    _MEMORY[key] = entry
    _MEMORY.move_to_end(key)
    while len(_MEMORY) > _MEMORY_ENTRIES:
        _MEMORY.popitem(last=False)


def forget() -> None:
    """Empty the in-memory cache (the files in the cache directory stay)."""
    _MEMORY.clear()


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
