"""Turn someone else's folder of fringe images into a capture (`rig import`).

The images are taken in natural order (``2.png`` before ``10.png``) and matched one to one with
the patterns of a short description, the *pattern spec*: groups separated by ``;``, each
``KIND:key=value,key=value``, expanding to consecutive files:

``sin:f=32,steps=12,phase=pi``
    12 phase-shifted sinusoids at 32 fringes across the projector; ``f=64/58/53`` makes one
    group per frequency. Keys: ``f`` (or ``frequency``), ``steps``, ``phase`` (the pattern's
    ``phase_rad``: a number, ``pi``, ``-pi``, ``pi/2``, ``90deg``), ``shifts`` (non-uniform or
    explicitly listed shifts, ``0/90/180/270deg`` or radians, ``/``-separated), ``axis`` (x|y).
``gray:bits=6`` (``binary:bits=6`` for a plain binary code)
    Code bit planes, most significant first (processing.projection.patterns' convention; ``order=lsb``
    for planes stored least significant first); ``inverted=after`` (all planes, then all inverted
    ones) or ``inverted=interleaved`` (plane, inverted plane, ...); ``period=P`` cells P projector
    pixels wide (default: the axis over 2**bits); ``axis``. Column bits then row bits (OpenCV's
    GrayCodePattern) are two groups: ``gray:bits=5,inverted=interleaved; gray:bits=4,inverted=interleaved,axis=y``.
``flat:level=1`` (also ``white``, ``black``)
    Constant frames. ``skip:N`` ignores N files.

With ``exposures_us`` (``--exposures 2000,8000,32000``) the folder holds the spec's files once per
exposure, each exposure's full sequence in turn: a capture at several exposures
(:mod:`rig.store.exposures`).

Instead of a spec string, ``--patterns`` may name a JSON file: ``{"patterns": [...]}`` with
capture-format pattern entries, optionally ``"files": [...]`` (names in the folder, in order).

The shift sign of other rigs is not always documented: ``shift_sign=-1`` stores every sinusoid
shift negated (I = A + B cos(phi - delta)). Colour images become single-channel (OpenCV's
BGR -> grey weights); the source folder, file names, their sha256, the spec and every
conversion are recorded in the capture's ``import`` key and each frame's ``source_file``.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from processing.projection.patterns import MAX_CODE_BITS, Binary, Flat, Gray, Pattern, Sinusoid
from rig.errors import CaptureError, ConfigError
from rig.store import files as files_layer
from rig.store.capture import (
    CaptureWriter,
    bit_depth_of,
    read_capture,
    utc_now,
    validate_pattern,
)
from rig.store.exposures import EXPOSURE_KEY

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm")


# --------------------------------------------------------------------------- the pattern spec


_ANGLE = re.compile(
    r"^(?P<sign>[+-]?)(?P<number>\d+(?:\.\d*)?|\.\d+)?\s*\*?\s*(?P<pi>pi)?(?:\s*/\s*(?P<div>\d+(?:\.\d*)?))?(?P<deg>deg)?$"
)


def parse_angle(text: str, where: str) -> float:
    """An angle in radians from ``1.2``, ``pi``, ``-pi``, ``pi/2``, ``2pi/3``, ``90deg``."""
    match = _ANGLE.match(text.strip().lower())
    if not match or (match["number"] is None and match["pi"] is None) or (match["pi"] and match["deg"]):
        raise ConfigError(f"{where}: expected an angle such as 1.57, pi, -pi/2 or 90deg, found {text!r}")
    value = float(match["number"]) if match["number"] is not None else 1.0
    if match["pi"]:
        value *= math.pi
    if match["div"]:
        divisor = float(match["div"])
        if divisor == 0:
            raise ConfigError(f"{where}: division by zero in {text!r}")
        value /= divisor
    if match["deg"]:
        value = math.radians(value)
    return -value if match["sign"] == "-" else value


def _angle_list(text: str, where: str) -> list[float]:
    """``/``-separated angles; a trailing ``deg`` applies to every item (``0/90/180/270deg``)."""
    items = [item.strip() for item in text.split("/")]
    if items[-1].lower().endswith("deg"):
        items = [item if item.lower().endswith("deg") else item + "deg" for item in items]
    return [parse_angle(item, where) for item in items]


def _positive_int(text: str, where: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise ConfigError(f"{where}: expected a positive integer, found {text!r}")
    return value


def _positive_number(text: str, where: str) -> float | int:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value > 0 and math.isfinite(value)):
        raise ConfigError(f"{where}: expected a positive number, found {text!r}")
    return int(value) if value.is_integer() else value


def _params(body: str, where: str, allowed: Sequence[str], flags: Sequence[str] = ()) -> dict[str, str]:
    params: dict[str, str] = {}
    for item in filter(None, (part.strip() for part in body.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip().lower()
        if not sep:
            if key in flags:
                params[key] = "true"
                continue
            if allowed and allowed[0] not in params:  # a bare value is the first key: skip:2, flat:1
                params[allowed[0]] = key
                continue
        if key not in allowed:
            raise ConfigError(f"{where}: unknown key {key!r}; expected {', '.join(allowed)}")
        params[key] = value.strip()
    return params


def _axis(params: dict[str, str], where: str) -> str:
    axis = params.get("axis", "x")
    if axis not in ("x", "y"):
        raise ConfigError(f"{where}: axis: expected x or y, found {axis!r}")
    return axis


def parse_spec(spec: str) -> list[Pattern | None]:
    """Patterns of a spec string, one per file; ``None`` marks a skipped file."""
    out: list[Pattern | None] = []
    groups = [g.strip() for g in spec.split(";") if g.strip()]
    if not groups:
        raise ConfigError("--patterns: empty spec; expected e.g. 'sin:f=32,steps=12,phase=pi; gray:bits=6'")
    for number, group in enumerate(groups, start=1):
        kind, _, body = group.partition(":")
        kind = kind.strip().lower()
        where = f"--patterns group {number} ({group!r})"
        parser = _GROUP_PARSERS.get(kind)
        if parser is None:
            raise ConfigError(f"{where}: unknown kind {kind!r}; expected sin, gray, binary, flat, white, black or skip")
        out.extend(parser(kind, body, where))
    return out


def _sinusoid_group(_kind: str, body: str, where: str) -> list[Pattern | None]:
    """``sin:f=F[/F2...],steps=N[,phase=..,shifts=..,axis=..]``: N shifted sinusoids per frequency."""
    p = _params(body, where, ("f", "frequency", "steps", "phase", "shifts", "axis"))
    freq_text = p.get("f", p.get("frequency"))
    if freq_text is None or "steps" not in p and "shifts" not in p:
        raise ConfigError(f"{where}: expected f=FRINGES and steps=N (or shifts=...)")
    frequencies = [_positive_number(f, f"{where}: f") for f in freq_text.split("/")]
    shifts = _angle_list(p["shifts"], f"{where}: shifts") if "shifts" in p else None
    steps = _positive_int(p["steps"], f"{where}: steps") if "steps" in p else len(shifts or [])
    if shifts is not None and len(shifts) != steps:
        raise ConfigError(f"{where}: shifts: expected {steps} values (steps), found {len(shifts)}")
    phase = parse_angle(p["phase"], f"{where}: phase") if "phase" in p else None
    axis = _axis(p, where)
    return [
        Sinusoid(
            axis=axis,
            frequency=frequency,
            steps=steps,
            step=j,
            phase_rad=0.0 if phase is None else phase,
            shift_rad=None if shifts is None else shifts[j],
        )
        for frequency in frequencies
        for j in range(steps)
    ]


def _gray_group(kind: str, body: str, where: str) -> list[Pattern | None]:
    """``gray:bits=N[,order=msb|lsb,inverted=after|interleaved,period=P,axis=..]`` (or ``binary:``): code
    bit planes, most significant first unless ``order=lsb``; ``period`` the cell width in projector pixels."""
    p = _params(body, where, ("bits", "order", "inverted", "period", "axis"))
    if "bits" not in p:
        raise ConfigError(f"{where}: expected bits=N")
    bits = _positive_int(p["bits"], f"{where}: bits")
    if bits > MAX_CODE_BITS:
        raise ConfigError(f"{where}: bits: expected 1 .. {MAX_CODE_BITS}, found {bits}")
    inverted = p.get("inverted", "none")
    if inverted not in ("none", "after", "interleaved"):
        raise ConfigError(f"{where}: inverted: expected none, after or interleaved, found {inverted!r}")
    significance = p.get("order", "msb")
    if significance not in ("msb", "lsb"):
        raise ConfigError(f"{where}: order: expected msb (most significant plane first) or lsb, found {significance!r}")
    period = _positive_number(p["period"], f"{where}: period") if "period" in p else None
    axis = _axis(p, where)
    planes = range(bits) if significance == "msb" else range(bits - 1, -1, -1)  # bit 0: the most significant
    if inverted == "interleaved":  # each bit, then its inverse
        order = [(b, inv) for b in planes for inv in (False, True)]
    else:  # every bit, then (after) every inverse
        order = [(b, inv) for inv in ((False, True) if inverted == "after" else (False,)) for b in planes]
    code = Binary if kind == "binary" else Gray
    return [code(axis=axis, bit=b, bits=bits, inverted=inv, period_px=period) for b, inv in order]


def _flat_group(kind: str, body: str, where: str) -> list[Pattern | None]:
    """``flat:level=L`` (0..1), ``white``, ``black``: one constant frame."""
    p = _params(body, where, ("level",))
    level = {"white": "1", "black": "0"}.get(kind, p.get("level"))
    try:
        value = float(level) if level is not None else float("nan")
    except ValueError:
        value = float("nan")
    if not 0.0 <= value <= 1.0:
        raise ConfigError(f"{where}: level: expected a number in 0..1, found {level!r}")
    return [Flat(level=value)]


def _skip_group(_kind: str, body: str, where: str) -> list[Pattern | None]:
    """``skip:N``: N files that are not patterns."""
    p = _params(body, where, ("n",))
    return [None] * _positive_int(p.get("n", "1"), f"{where}: n")


_GROUP_PARSERS: dict[str, Callable[[str, str, str], list[Pattern | None]]] = {
    "sin": _sinusoid_group,
    "sinusoid": _sinusoid_group,
    "gray": _gray_group,
    "binary": _gray_group,
    "flat": _flat_group,
    "white": _flat_group,
    "black": _flat_group,
    "skip": _skip_group,
}


def load_spec(text: str) -> tuple[list[Pattern | Mapping[str, Any] | None], list[str] | None]:
    """A spec string, or ``@FILE``/``FILE.json`` holding {"patterns": [...], "files": [...]}."""
    candidate = text[1:] if text.startswith("@") else text
    if text.startswith("@") or (candidate.endswith(".json") and Path(candidate).is_file()):
        path = Path(candidate)
        data = files_layer.read_json(path, ConfigError, "pattern file not found")
        if isinstance(data, list):
            data = {"patterns": data}
        patterns = data.get("patterns") if isinstance(data, dict) else None
        if not isinstance(patterns, list) or not patterns:
            raise ConfigError(f"{path}: patterns: expected a non-empty list of capture-format pattern entries")
        files = data.get("files")
        if files is not None and (not isinstance(files, list) or not all(isinstance(f, str) for f in files)):
            raise ConfigError(f"{path}: files: expected a list of file names")
        entries: list[Pattern | Mapping[str, Any] | None] = [dict(p) for p in patterns]
        return entries, files
    parsed: list[Pattern | Mapping[str, Any] | None] = list(parse_spec(text))
    return parsed, None


# --------------------------------------------------------------------------- files and images


def natural_key(name: str) -> list[Any]:
    """Sort key that orders embedded numbers by value: ``2.png`` < ``10.png``."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def list_images(folder: Path, glob: str | None = None, order: str = "natural") -> list[Path]:
    """Image files of ``folder`` (optionally matching ``glob``) in ``order``: natural, name or mtime."""
    if not folder.exists():
        raise ConfigError(f"{folder}: does not exist; expected the folder that holds the fringe images")
    if not folder.is_dir():
        raise ConfigError(f"{folder}: is a file, not a folder; give the folder that holds the fringe images")
    files = _images_in(folder, glob)
    if order == "natural":
        files.sort(key=lambda p: natural_key(p.name))
    elif order == "name":
        files.sort(key=lambda p: p.name)
    elif order == "mtime":
        files.sort(key=lambda p: (p.stat().st_mtime, natural_key(p.name)))
    else:
        raise ConfigError(f"--order: expected natural, name or mtime, found {order!r}")
    return files


def _images_in(folder: Path, glob: str | None = None) -> list[Path]:
    return [p for p in folder.glob(glob or "*") if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES]


def image_subfolders(folder: Path, glob: str | None = None) -> str:
    """The subfolders of ``folder`` holding images, as ``L/ (18 images), R/ (18 images)`` ('' if none):
    a user who names a data set's parent folder is pointed at the folders to import."""
    found = []
    for sub in sorted((p for p in folder.iterdir() if p.is_dir()), key=lambda p: natural_key(p.name)):
        count = len(_images_in(sub, glob))
        if count:
            found.append(f"{sub.name}/ ({count} image{'s' * (count != 1)})")
    return ", ".join(found)


@dataclass
class ImportOptions:
    """How `rig import` reads and converts the folder."""

    projector_width: int | None = None
    projector_height: int | None = None
    shift_sign: int = 1
    glob: str | None = None
    order: str = "natural"
    crop: tuple[int, int, int, int] | None = None  # x, y, width, height in source pixels
    downsample: int = 1
    scene: str = "object"
    overwrite: bool = False
    conversions: list[str] = field(default_factory=list)
    # several exposures: the folder holds each exposure's full sequence (as the spec describes it) in turn
    exposures_us: tuple[float, ...] = ()


def parse_crop(text: str) -> tuple[int, int, int, int]:
    """``X,Y,W,H`` in pixels."""
    try:
        x, y, w, h = (int(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--crop: expected X,Y,WIDTH,HEIGHT in pixels, found {text!r}") from None
    if x < 0 or y < 0 or w < 1 or h < 1:
        raise ConfigError(f"--crop: expected X, Y >= 0 and WIDTH, HEIGHT >= 1, found {text!r}")
    return x, y, w, h


def read_source_image(path: Path, options: ImportOptions) -> tuple[np.ndarray, list[str], str]:
    """One source image as single-channel uint8/uint16/float32, cropped and downsampled; notes of conversions;
    the sha256 of the file's bytes as read (the file is read once, through the safe layer)."""
    data = files_layer.read_regular(path, str(path), CaptureError)  # a regular file, size-limited
    digest = hashlib.sha256(data).hexdigest()
    image = files_layer.decode_image(data, str(path), CaptureError)  # header checked before decoding
    notes: list[str] = []
    if image.ndim == 3:
        channels = image.shape[2]
        if channels == 4:
            image = image[:, :, :3]
        if channels == 1:
            image = image[:, :, 0]
        else:
            image = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_BGR2GRAY)
            notes.append(f"{channels}-channel colour -> grey (0.299 R + 0.587 G + 0.114 B)")
    if image.dtype not in (np.uint8, np.uint16, np.float32):
        if np.issubdtype(image.dtype, np.floating):
            notes.append(f"{image.dtype} -> float32")
            image = image.astype(np.float32)
        else:
            raise CaptureError(f"{path}: expected an 8/16-bit integer or float image, found {image.dtype}")
    if options.crop is not None:
        x, y, w, h = options.crop
        if x + w > image.shape[1] or y + h > image.shape[0]:
            raise ConfigError(f"--crop: {x},{y},{w},{h} exceeds {path.name}'s {image.shape[1]}x{image.shape[0]}")
        image = image[y : y + h, x : x + w]
    if options.downsample > 1:
        k = options.downsample
        rows, cols = (image.shape[0] // k) * k, (image.shape[1] // k) * k
        blocks = image[:rows, :cols].astype(np.float64).reshape(rows // k, k, cols // k, k).mean(axis=(1, 3))
        image = np.rint(blocks).astype(image.dtype) if image.dtype != np.float32 else blocks.astype(np.float32)
    return np.ascontiguousarray(image), notes, digest


def import_folder(
    folder: str | os.PathLike[str], spec: str, output: str | os.PathLike[str], options: ImportOptions | None = None
):
    """Write a capture at ``output`` from the images of ``folder`` described by ``spec``; returns it, verified."""
    options = ImportOptions() if options is None else options
    folder = Path(folder)
    if options.shift_sign not in (1, -1):
        raise ConfigError(f"--shift-sign: expected +1 or -1, found {options.shift_sign}")
    if options.downsample < 1:
        raise ConfigError(f"--downsample: expected an integer >= 1, found {options.downsample}")
    entries, listed = load_spec(spec)
    entries = _at_exposures(entries, options.exposures_us)
    files = _source_files(folder, spec, listed, options)
    if len(files) != len(entries):
        kept = sum(e is not None for e in entries)
        times = f" at {len(options.exposures_us)} exposures" if len(options.exposures_us) > 1 else ""
        raise ConfigError(
            f"{folder}: the pattern spec describes {len(entries)} files{times} ({kept} patterns), found {len(files)} images"
            + (f" matching {options.glob!r}" if options.glob else "")
            + (f" ({files[0].name} .. {files[-1].name})" if files else "")
        )
    pairs = [(pattern, path) for pattern, path in zip(entries, files) if pattern is not None]
    patterns = _typed_patterns([entry for entry, _ in pairs], spec, options)
    images, digests, notes = _read_images([path for _, path in pairs], options)
    height, width = images[0].shape
    projector = {
        "width": int(options.projector_width or width),
        "height": int(options.projector_height or height),
    }
    provenance = {
        "source": str(folder.resolve()),
        "imported_utc": utc_now(),
        "spec": spec,
        "files": [path.name for _, path in pairs],
        "skipped": [path.name for pattern, path in zip(entries, files) if pattern is None],
        "shift_sign": options.shift_sign,
        "conversions": sorted(notes),
        "crop": list(options.crop) if options.crop else None,
        "downsample": options.downsample,
        "projector_given": options.projector_width is not None,
    }
    camera = {"width": int(width), "height": int(height), "bit_depth": bit_depth_of(images[0].dtype)}
    with CaptureWriter(
        output,
        camera,
        projector,
        patterns,
        scene=options.scene,
        extra={"import": provenance},
        overwrite=options.overwrite,
    ) as writer:
        for i, ((_, path), image, digest) in enumerate(zip(pairs, images, digests)):
            writer.add_frame(i, image, source_file=path.name, source_sha256=digest)
    return read_capture(output)


def _at_exposures(
    entries: list[Pattern | Mapping[str, Any] | None], exposures_us: Sequence[float]
) -> list[Pattern | Mapping[str, Any] | None]:
    """The spec's files once per exposure, each pattern tagged with its exposure (rig/store/exposures.py)."""
    if len(exposures_us) <= 1:
        return entries
    plain = [None if e is None else (e.to_dict() if isinstance(e, Pattern) else dict(e)) for e in entries]
    return [None if e is None else {**e, EXPOSURE_KEY: t} for t in exposures_us for e in plain]


def _source_files(folder: Path, spec: str, listed: list[str] | None, options: ImportOptions) -> list[Path]:
    """The files to import: those a pattern file lists (inside ``folder``), else the folder's images in order."""
    if listed is not None:
        # names relative to the folder, inside it once links are resolved (never /abs or ../..)
        files = [
            folder / files_layer.relative_path(name, f"{spec}", f"files[{i}]", ConfigError)
            for i, name in enumerate(listed)
        ]
        for i, name in enumerate(listed):
            files_layer.contained(folder, name, spec, f"files[{i}]", ConfigError)
        missing = [f.name for f in files if not f.is_file()]
        if missing:
            raise ConfigError(f"{folder}: files listed in the pattern file are missing: {', '.join(missing[:5])}")
        return files
    files = list_images(folder, options.glob, options.order)
    if not files:
        matching = f" matching {options.glob!r}" if options.glob else ""
        subfolders = image_subfolders(folder, options.glob)
        raise ConfigError(
            f"{folder}: found no images{matching} ({', '.join(IMAGE_SUFFIXES)})"
            + (f"; its subfolders hold images: {subfolders}; import one of them" if subfolders else "")
        )
    return files


def _typed_patterns(
    entries: Sequence[Pattern | Mapping[str, Any] | None], spec: str, options: ImportOptions
) -> list[Pattern]:
    """Each entry validated as a pattern; with ``shift_sign=-1`` every sinusoid's shift negated."""
    patterns: list[Pattern] = []
    for i, entry in enumerate(entries):
        pattern = validate_pattern(f"--patterns ({spec})", i, entry)
        if isinstance(pattern, Sinusoid) and options.shift_sign == -1:
            pattern = pattern.replace(shift_rad=-pattern.shift)  # the rig shifted the other way
        patterns.append(pattern)
    return patterns


def _read_images(paths: Sequence[Path], options: ImportOptions) -> tuple[list[np.ndarray], list[str], set[str]]:
    """The source images, converted (all of one size and type), their sha256 and the conversions made."""
    images: list[np.ndarray] = []
    digests: list[str] = []
    notes: set[str] = set()
    for path in paths:
        image, image_notes, digest = read_source_image(path, options)
        notes.update(image_notes)
        if images and (image.shape != images[0].shape or image.dtype != images[0].dtype):
            raise CaptureError(
                f"{path}: expected {images[0].shape[1]}x{images[0].shape[0]} {images[0].dtype} like {paths[0].name}, "
                f"found {image.shape[1]}x{image.shape[0]} {image.dtype}"
            )
        images.append(image)
        digests.append(digest)
    return images, digests, notes
