"""The one safe file layer: contained paths, regular files, bounded reads, atomic directory commits.

Every command reads and writes user data through these functions, so that the promises of
``docs/safety.md`` hold in one place:

- **Containment.** A path read from a manifest, a calibration (``reference``) or a pattern file
  must be relative, and after resolving every link it must still lie inside its base directory
  (:func:`contained`).
- **Regular files only.** Files are opened with ``O_NOFOLLOW | O_NONBLOCK`` and checked with
  ``fstat``: a FIFO, a device or a directory is refused instead of hanging or filling memory
  (:func:`read_regular`).
- **Limits.** Image sides, frame counts, manifest sizes and JSON nesting are bounded
  (:class:`Limits`, overridable through ``RIG_MAX_*`` environment variables); an image's header
  is parsed and its declared size checked before any pixel is decoded (:func:`decode_image`).
- **Atomic directory commit.** Outputs are written into a fresh temporary sibling
  ``<name>.incomplete-<random>`` and renamed onto the final name while a lock on the parent
  directory is held; the rename never replaces an existing name (``RENAME_NOREPLACE``), so of two
  concurrent writers one wins and the other is told. Replacing is allowed only for what this
  program wrote (a capture, a processing output, a calibration, a simulation, a demo) or an empty
  directory, and is done by an atomic exchange, so the name always holds the old or the new
  directory (:func:`commit_directory`).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import fcntl
import functools
import json
import os
import shutil
import stat
import struct
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from calibration.jsonfile import (
    INCOMPLETE_MARK,
    REPLACED_MARK,
    RESERVED_MARKS,
    naming_errors,
    staging_mark,
)
from calibration.jsonfile import (
    check_committed_input as check_committed_input,  # the store's rules for staging names
)
from calibration.jsonfile import (
    write_bytes_atomic as write_bytes_atomic,  # report files rewritten in place (verification)
)

MAX_NAME_BYTES = 255  # one path component (Linux NAME_MAX)
MAX_PATH_BYTES = 4096  # a whole path (Linux PATH_MAX)


class FileLayerError(Exception):
    """Fallback error type when a caller does not name its own (callers pass a RigError subclass)."""


ErrorType = Callable[[str], Exception]


# --------------------------------------------------------------------------- limits


@dataclass(frozen=True)
class Limits:
    """Sizes beyond which input is refused before it is read in full (see docs/safety.md).

    Each can be overridden by an environment variable of the same name in capitals with the
    prefix ``RIG_``, e.g. ``RIG_MAX_IMAGE_SIDE=32768``.
    """

    max_image_side: int = 16384  # pixels per side of a camera or projector image
    max_image_pixels: int = 100_000_000  # width x height of one image
    max_frames: int = 10_000  # patterns / frames of one capture
    max_manifest_bytes: int = 64 * 1024 * 1024  # capture.json, calibration.json, pattern files
    max_json_depth: int = 64  # nesting of objects and lists in those files
    max_file_bytes: int = 2 * 1024 * 1024 * 1024  # one frame or source image file

    @classmethod
    def from_environment(cls, environ: dict[str, str] | None = None) -> Limits:
        """Defaults with ``RIG_MAX_*`` overrides; a malformed override is an error naming the variable."""
        environ = dict(os.environ) if environ is None else environ
        values: dict[str, int] = {}
        for name in cls.__dataclass_fields__:
            key = "RIG_" + name.upper()
            if key in environ:
                text = environ[key]
                if not text.strip().isdigit() or int(text) < 1:
                    raise ValueError(f"environment {key}: expected a positive integer, found {text!r}")
                values[name] = int(text)
        return cls(**values)


def limits() -> Limits:
    """The limits in force (defaults, or the ``RIG_MAX_*`` environment)."""
    overrides = tuple((key, os.environ.get(key)) for key in _LIMIT_VARIABLES)
    return _limits_for(overrides)


_LIMIT_VARIABLES = tuple("RIG_" + name.upper() for name in Limits.__dataclass_fields__)


@functools.lru_cache(maxsize=8)
def _limits_for(overrides: tuple[tuple[str, str | None], ...]) -> Limits:
    """Limits for one set of ``RIG_MAX_*`` values (read on every file access: parsed once)."""
    return Limits.from_environment({key: value for key, value in overrides if value is not None})


def check_image_size(width: int, height: int, where: str, error: ErrorType) -> None:
    """Refuse an image size beyond the limits before anything of that size is allocated."""
    lim = limits()
    if width > lim.max_image_side or height > lim.max_image_side or width * height > lim.max_image_pixels:
        raise error(
            f"{where}: image size: expected at most {lim.max_image_side} pixels per side and "
            f"{lim.max_image_pixels} pixels in all (RIG_MAX_IMAGE_SIDE / RIG_MAX_IMAGE_PIXELS), found {width}x{height}"
        )


# --------------------------------------------------------------------------- names and containment


def shorten(text: str, keep: int = 60) -> str:
    """``text`` cut in the middle to about ``keep`` characters, for messages about absurd names."""
    return text if len(text) <= keep else f"{text[: keep // 2]}...{text[-keep // 4 :]}"


def check_path_text(text: str, where: str, error: ErrorType) -> None:
    """Refuse a path the operating system would reject anyway, with one line instead of an OSError."""
    where = shorten(where, 120)
    if "\0" in text:
        raise error(f"{where}: expected a path without NUL characters, found {text[:60]!r}")
    encoded = os.fsencode(text)
    if len(encoded) > MAX_PATH_BYTES:
        raise error(f"{where}: expected a path of at most {MAX_PATH_BYTES} bytes, found {len(encoded)}")
    for part in encoded.split(b"/"):
        if len(part) > MAX_NAME_BYTES:
            raise error(f"{where}: expected file names of at most {MAX_NAME_BYTES} bytes, found one of {len(part)}")


def relative_path(text: Any, where: str, field: str, error: ErrorType) -> PurePosixPath:
    """A relative POSIX path with no ``..`` (the form manifests and calibrations must use)."""
    if not isinstance(text, str) or not text:
        raise error(f"{where}: {field}: expected a relative file path, found {text!r}")
    check_path_text(text, f"{where}: {field}", error)
    posix = PurePosixPath(text.replace("\\", "/"))
    if posix.is_absolute() or text.startswith(("/", "\\")) or (len(text) > 1 and text[1] == ":"):
        raise error(f"{where}: {field}: expected a path relative to its directory, found {text!r}")
    if ".." in posix.parts:
        raise error(f"{where}: {field}: expected a path inside its directory (no '..'), found {text!r}")
    return posix


def contained(base: Path, text: Any, where: str, field: str, error: ErrorType) -> Path:
    """``base / text`` with every link resolved, refused unless it is still inside ``base``."""
    relative = relative_path(text, where, field, error)
    root = Path(base).resolve()
    target = (root / relative).resolve()
    if target != root and not target.is_relative_to(root):
        raise error(f"{where}: {field}: {text!r} leads outside {base} (to {target}) through a link")
    return target


# --------------------------------------------------------------------------- reading


def open_regular(path: Path, where: str, error: ErrorType, missing: str = "missing") -> int:
    """File descriptor of a regular file; no link as last component, no FIFO, device or directory."""
    check_path_text(str(path), where, error)
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise error(f"{where}: {missing}") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise error(f"{where}: expected a regular file, found a symbolic link") from None
        raise error(f"{where}: cannot open: {exc.strerror or exc}") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        kind = "a directory" if stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode) else "a device or socket"
        raise error(f"{where}: expected a regular file, found {kind}")
    return fd


def read_regular(
    path: Path, where: str, error: ErrorType, max_bytes: int | None = None, missing: str = "missing"
) -> bytes:
    """Whole content of a regular file of at most ``max_bytes`` (default the file limit)."""
    max_bytes = limits().max_file_bytes if max_bytes is None else max_bytes
    fd = open_regular(path, where, error, missing)
    try:
        size = os.fstat(fd).st_size
        if size > max_bytes:
            raise error(f"{where}: expected at most {max_bytes} bytes, found {size} (see RIG_MAX_* in docs/safety.md)")
        os.set_blocking(fd, True)
        chunks = []
        remaining = max_bytes + 1
        while remaining > 0:
            chunk = os.read(fd, min(remaining, 1 << 24))
            if not chunk:
                break
            chunks.append(chunk)
            remaining -= len(chunk)
        data = b"".join(chunks)
        if len(data) > max_bytes:
            raise error(f"{where}: grew beyond {max_bytes} bytes while being read")
        return data
    except OSError as exc:
        raise error(f"{where}: cannot read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)


def _depth(value: Any, limit: int) -> int:
    """Nesting depth of parsed JSON, walked without recursion; stops counting past ``limit``."""
    deepest = 0
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, (dict, list)):
            deepest = max(deepest, depth)
            if deepest > limit:
                return deepest
            children = item.values() if isinstance(item, dict) else item
            stack.extend((child, depth + 1) for child in children if isinstance(child, (dict, list)))
    return deepest


def parse_json(text: str, where: str, error: ErrorType, strict: bool = True) -> Any:
    """Parse JSON text with the depth limit; every failure is one line naming ``where``."""
    lim = limits()
    try:
        if strict:  # NaN / Infinity are not JSON; an older report may hold them (``strict=False``)
            value = json.loads(text, parse_constant=lambda name: _bad_constant(name, where, error))
        else:
            value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{where}: not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise error(f"{where}: expected JSON nested at most {lim.max_json_depth} deep, found deeper") from None
    except ValueError as exc:  # e.g. an integer of more digits than Python converts
        raise error(f"{where}: not valid JSON: {str(exc).splitlines()[0]}") from None
    if _depth(value, lim.max_json_depth) > lim.max_json_depth:
        raise error(f"{where}: expected JSON nested at most {lim.max_json_depth} deep (RIG_MAX_JSON_DEPTH)")
    return value


def _bad_constant(name: str, where: str, error: ErrorType) -> Any:
    raise error(f"{where}: not valid JSON: {name} is not a number JSON allows")


def read_json(path: Path, error: ErrorType, missing: str = "missing", strict: bool = True) -> Any:
    """Parse a JSON file (regular file, manifest size limit, depth limit); one-line errors."""
    data = read_regular(Path(path), str(path), error, limits().max_manifest_bytes, missing)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: cannot read: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    return parse_json(text, str(path), error, strict)


# --------------------------------------------------------------------------- images


def image_header(data: bytes) -> tuple[str, int, int, int | None] | None:
    """(format, width, height, bits per sample or None) from a PNG, TIFF, JPEG or BMP header.

    Returns None for a format this parser does not know; raises ValueError for a header that
    is cut short.
    """
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        if len(data) < 25 or data[12:16] != b"IHDR":
            raise ValueError("PNG header cut short")
        width, height, depth = struct.unpack(">IIB", data[16:25])
        return "PNG", width, height, depth
    if data[:4] in (b"II*\x00", b"MM\x00*"):
        return _tiff_header(data)
    if data[:2] == b"\xff\xd8":
        return _jpeg_header(data)
    if data[:2] == b"BM":
        if len(data) < 30:
            raise ValueError("BMP header cut short")
        width, height = struct.unpack("<ii", data[18:26])
        return "BMP", abs(width), abs(height), struct.unpack("<H", data[28:30])[0]
    return None


def _tiff_header(data: bytes) -> tuple[str, int, int, int | None]:
    order = "<" if data[:2] == b"II" else ">"
    try:
        (offset,) = struct.unpack(order + "I", data[4:8])
        (count,) = struct.unpack(order + "H", data[offset : offset + 2])
        tags: dict[int, int] = {}
        for i in range(count):
            entry = data[offset + 2 + 12 * i : offset + 14 + 12 * i]
            tag, kind, _n = struct.unpack(order + "HHI", entry[:8])
            value = struct.unpack(order + ("H" if kind == 3 else "I"), entry[8:10] if kind == 3 else entry[8:12])[0]
            tags[tag] = value
    except struct.error:
        raise ValueError("TIFF header cut short") from None
    if 256 not in tags or 257 not in tags:
        raise ValueError("TIFF header without image width/height")
    return "TIFF", tags[256], tags[257], tags.get(258)


def _jpeg_header(data: bytes) -> tuple[str, int, int, int | None]:
    i = 2
    while i + 9 < len(data):
        if data[i] != 0xFF:
            i += 1
            continue
        marker = data[i + 1]
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7 or marker == 0xFF:
            i += 1 if marker == 0xFF else 2
            continue
        (length,) = struct.unpack(">H", data[i + 2 : i + 4])
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            depth, height, width = struct.unpack(">BHH", data[i + 4 : i + 9])
            return "JPEG", width, height, depth
        i += 2 + length
    raise ValueError("JPEG without a frame header")


def decode_image(data: bytes, where: str, error: ErrorType) -> np.ndarray:
    """Decode image bytes unchanged after checking the header's declared size against the limits.

    A header this layer cannot parse is refused unless the whole file is small enough that its
    decoded image could not exceed the pixel limit anyway.
    """
    try:
        header = image_header(data)
    except ValueError as exc:
        raise error(f"{where}: corrupt or unreadable image: {exc}") from None
    if header is not None:
        check_image_size(header[1], header[2], where, error)
    import cv2  # imported on first use: OpenCV costs ~0.1 s, which commands that read no image skip

    _quiet_opencv(cv2)
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    except Exception as exc:  # OpenCV 4 raises cv2.error, OpenCV 5 other types for the same corrupt input
        raise error(
            f"{where}: corrupt or unreadable image ({len(data)} bytes): {str(exc).strip().splitlines()[-1:]}"
        ) from None
    if image is None:
        raise error(f"{where}: corrupt or unreadable image ({len(data)} bytes)")
    if header is None:
        check_image_size(image.shape[1], image.shape[0], where, error)
    return image


def _quiet_opencv(cv2: Any) -> None:
    """OpenCV prints WARN lines for corrupt images; the caller reports them as one error instead."""
    with contextlib.suppress(Exception):
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)


# --------------------------------------------------------------------------- what is ours

# kind -> (marker file, key, accepted values): a directory is of that kind when its marker says so.
KINDS: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "capture": ("capture.json", "format", ("fpp-capture",)),
    "output": ("report.json", "program", ("fpp-rig",)),
    "calibration": ("calibration.json", "format", ("fpp-calibration",)),
    "calibration-session": ("session.json", "heights_mm", ()),
    "demo": ("demo.json", "scene", ()),
    "simulation": ("object/capture.json", "format", ("fpp-capture",)),
    "verification": ("report.json", "format", ("fpp-verification",)),
}


def kind_of(path: Path) -> str | None:
    """Which of this program's outputs ``path`` is (a real directory, its marker file says so), or None."""
    try:
        if not stat.S_ISDIR(os.lstat(path).st_mode):
            return None
    except OSError:
        return None
    for kind, (marker, key, values) in KINDS.items():
        try:
            data = read_json(path / marker, FileLayerError, strict=False)
        except FileLayerError:
            continue
        if isinstance(data, dict) and key in data:
            found = str(data[key])
            if not values or any(found == v or found.startswith(v + " ") for v in values):
                return kind
    return None


def is_empty_directory(path: Path) -> bool:
    try:
        return stat.S_ISDIR(os.lstat(path).st_mode) and not any(os.scandir(path))
    except OSError:
        return False


def _either(kinds: tuple[str, ...]) -> str:
    text = " or ".join(kinds)
    return ("an " if text[0] in "aeiou" else "a ") + text


def check_target(target: Path, kinds: tuple[str, ...], replace: bool, error: ErrorType, hint: str = "") -> None:
    """Refuse a target that exists unless replacing is asked and it is ``kinds`` (or an empty directory)."""
    check_path_text(str(target), str(target), error)
    check_not_reserved(target, error)
    try:
        info = os.lstat(target)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise error(f"{target}: cannot use as output: {exc.strerror}") from None
    if stat.S_ISLNK(info.st_mode):
        raise error(f"{target}: is a symbolic link; refusing to write through it (choose another output)")
    if not stat.S_ISDIR(info.st_mode):
        raise error(f"{target}: exists and is a file, not {_either(kinds)} directory; choose another output")
    if is_empty_directory(target):
        return
    if not replace:
        raise error(f"{target}: already exists; refusing to overwrite{hint}")
    found = kind_of(target)
    if found not in kinds:
        what = f"{_either((found,))} directory" if found else "not written by this program"
        raise error(
            f"{target}: exists and is {what}; only {_either(kinds)} directory is ever replaced (choose another output)"
        )


def check_not_reserved(target: Path, error: ErrorType) -> None:
    """Refuse an output name holding a staging mark: every reader would take it for an unfinished write."""
    mark = staging_mark(Path(target).name)
    if mark is not None:
        raise error(
            f"{target}: names containing {' or '.join(map(repr, RESERVED_MARKS))} are reserved for unfinished "
            f"writes (found {mark!r}); choose another name"
        )


def leftovers(target: Path) -> str:
    """A note naming what an interrupted commit or replacement left beside ``target`` ("" if nothing)."""
    parent = target.parent if str(target.parent) else Path(".")
    try:
        names = sorted(os.listdir(parent))
    except OSError:
        return ""
    replaced = [n for n in names if n.startswith(target.name + REPLACED_MARK)]
    incomplete = [n for n in names if n.startswith(target.name + INCOMPLETE_MARK)]
    notes = []
    if replaced:
        notes.append(f"an interrupted replacement left the previous version at {parent / replaced[-1]}")
    if incomplete:
        notes.append(f"an interrupted write left {parent / incomplete[-1]} (read it with --salvage)")
    return "; ".join(notes)


# --------------------------------------------------------------------------- writing


def _fsync(path: Path, directory: bool = False) -> None:
    flags = os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0)
    try:
        fd = os.open(path, flags)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def fsync_tree(root: Path) -> None:
    """fsync every file and directory under ``root`` (before it is renamed into place)."""
    for directory, _dirs, names in os.walk(root):
        for name in names:
            _fsync(Path(directory) / name)
        _fsync(Path(directory), directory=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def make_parent(target: Path, error: ErrorType) -> Path:
    """Create the parent directories of ``target``; one-line error if they cannot be."""
    parent = target.parent if str(target.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise error(f"{target}: cannot create its folder {parent}: {exc.strerror or exc}") from None
    if not parent.is_dir():
        raise error(f"{target}: {parent} is not a directory")
    return parent


def make_staging(target: Path, error: ErrorType) -> Path:
    """A fresh ``<target>.incomplete-XXXX`` beside ``target``, with ordinary permissions (not 0700)."""
    parent = make_parent(target, error)
    try:
        staging = Path(tempfile.mkdtemp(prefix=target.name + INCOMPLETE_MARK, dir=parent))
    except OSError as exc:
        raise error(f"{target}: cannot write in {parent}: {exc.strerror or exc}") from None
    os.chmod(staging, 0o777 & ~_umask())
    return staging


def check_writable(target: Path, kinds: tuple[str, ...], replace: bool, error: ErrorType, hint: str = "") -> None:
    """Before any work: the target is acceptable (:func:`check_target`, with its ``hint``) and a
    staging directory can be made beside it."""
    check_target(target, kinds, replace, error, hint)
    staging = make_staging(target, error)
    os.rmdir(staging)


def check_writable_directory(directory: Path, error: ErrorType) -> None:
    """Before any work: files can be created in the existing ``directory`` (a probe file, removed)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".write-probe-", dir=directory)
    except OSError as exc:
        raise error(f"{directory}: cannot write in it: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)


def committed_path(path: Path, staging: Path, target: Path) -> Path:
    """Where ``path``, written inside ``staging``, lies once ``staging`` is committed as ``target``.

    A path outside ``staging`` is returned as it is; relative and absolute spellings both work.
    """
    path, staging, target = Path(path), Path(staging), Path(target)
    for base, final in (
        (staging, target),
        (staging.absolute(), target.absolute()),
        (staging.resolve(), staging.resolve().parent / target.name),
    ):
        if path.is_relative_to(base):
            return final / path.relative_to(base)
    return path


def same_path(first: Path, second: Path) -> bool:
    """Whether two paths name the same place (after resolving links)."""
    return Path(first).resolve() == Path(second).resolve()


@contextlib.contextmanager
def parent_lock(parent: Path) -> Iterator[None]:
    """Exclusive lock on a directory (flock on its descriptor; no file is created)."""
    fd = os.open(parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100
_libc: Any = None


def _renameat2(source: Path, target: Path, flags: int) -> bool:
    """renameat2(2) with ``flags``; False when the system or the filesystem does not offer it."""
    global _libc
    if _libc is None:
        try:
            _libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        except OSError:
            _libc = False
    function = getattr(_libc, "renameat2", None) if _libc else None
    if function is None:
        return False
    result = function(_AT_FDCWD, os.fsencode(source), _AT_FDCWD, os.fsencode(target), flags)
    if result == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(code, os.strerror(code), str(target))


def rename_noreplace(source: Path, target: Path) -> None:
    """Rename ``source`` to ``target``; FileExistsError if ``target`` exists (even an empty directory)."""
    if _renameat2(source, target, _RENAME_NOREPLACE):
        return
    if os.path.lexists(target):  # no renameat2: the parent lock keeps our own writers out
        raise FileExistsError(errno.EEXIST, "File exists", str(target))
    os.rename(source, target)


def commit_directory(
    staging: Path,
    target: Path,
    kinds: tuple[str, ...],
    replace: bool,
    error: ErrorType,
    before_rename: Callable[[], None] | None = None,
    kept: bool = True,
) -> None:
    """Move a finished staging directory onto ``target`` atomically, under the parent's lock.

    ``target`` must not exist, or (``replace``) be a ``kinds`` directory or an empty one: it is
    then exchanged with the new directory in one step and removed afterwards. ``before_rename``
    runs under the lock after the checks (the capture writer marks itself complete there).
    A refusal raises ``error`` and leaves ``staging`` as it is.
    """
    fsync_tree(staging)
    parent = target.parent if str(target.parent) else Path(".")
    with parent_lock(parent):
        left = f"; the new data is left at {staging}" if kept else ""
        check_target(target, kinds, replace, error, hint=f" (it appeared while writing){left}")
        if before_rename is not None:
            before_rename()
            _fsync(staging, directory=True)
        if not os.path.lexists(target):
            try:
                rename_noreplace(staging, target)
            except FileExistsError:
                raise error(f"{target}: appeared while writing (another writer got there first){left}") from None
        else:
            _replace(staging, target)
        _fsync(parent, directory=True)


def _replace(staging: Path, target: Path) -> None:
    """Swap ``staging`` in for ``target``; the old directory is removed after the swap."""
    old = Path(tempfile.mkdtemp(prefix=target.name + REPLACED_MARK, dir=target.parent))
    os.rmdir(old)
    if _renameat2(staging, target, _RENAME_EXCHANGE):
        os.rename(staging, old)  # the old directory now sits at the staging name
    else:  # two renames: a kill in between is reported by leftovers()
        os.rename(target, old)
        os.rename(staging, target)
    shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def staged_directory(
    target: Path, kinds: tuple[str, ...], replace: bool, error: ErrorType, keep_on_error: bool = False
) -> Iterator[Path]:
    """Write a directory atomically: yields a staging directory, committed to ``target`` on success.

    On an exception the staging directory is removed (``keep_on_error`` keeps it for salvage).
    """
    target = Path(target)
    check_target(target, kinds, replace, error)
    staging = make_staging(target, error)
    try:
        with naming_errors(target):  # a full disk while writing a file of the output names the output
            yield staging
            commit_directory(staging, target, kinds, replace, error, kept=keep_on_error)
    except BaseException:
        if not keep_on_error:
            shutil.rmtree(staging, ignore_errors=True)
        raise


def append_line(path: Path, line: str, error: ErrorType) -> None:
    """Append one line of text to a regular file (created if missing) in a single write, then fsync.

    The last component may not be a link; a file that is not regular is refused. Lines shorter
    than the pipe buffer are written whole by one ``O_APPEND`` write, so concurrent appenders
    never interleave inside a line.
    """
    path = Path(path)
    check_path_text(str(path), str(path), error)
    if "\n" in line:
        raise error(f"{path}: expected one line, found a line break inside it")
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags, 0o666)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise error(f"{path}: expected a regular file, found a symbolic link") from None
        raise error(f"{path}: cannot append: {exc.strerror or exc}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise error(f"{path}: expected a regular file")
        data = (line + "\n").encode("utf-8")
        if os.write(fd, data) != len(data):
            raise error(f"{path}: short write while appending (disk full?)")
        os.fsync(fd)
    finally:
        os.close(fd)
