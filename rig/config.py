"""The rig configuration file: which backends drive the rig, their parameters, and the scan.

A TOML file with the sections ``[projector]``, ``[camera]``, ``[trigger]``, ``[scan]`` and
``[simulation]``; every key is optional and defaults to the built-in simulated rig (moderngl
off-screen projector, simulated camera, simulated trigger box on a real pseudo-terminal). Every
wrong value raises :class:`~rig.errors.ConfigError` with one line naming the file, the key, what
was expected and what was found. See ``examples/rig.toml`` for a commented example.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from processing.projection.patterns import AXES, Gray, Pattern, Sinusoid, SpeckleSinusoid
from rig.errors import ConfigError
from rig.store import files

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

PROJECTOR_BACKENDS = ("gl-offscreen", "window", "dlp4500")
CAMERA_BACKENDS = ("simulated", "opencv", "pylon")
TRIGGER_BACKENDS = ("software", "serial", "simulated-serial")
PATTERN_AXES = AXES
MAX_BAUDRATE = 12_000_000  # beyond any UART a trigger box uses; larger values overflow the serial driver
# [scan] pattern_set: temporal phase shifting (several frames) or the thesis' single-shot
# speckle-embedded fringe (one frame, ch. 2.3; rig process recognises it by its kind).
PATTERN_SETS = ("phase-shifting", "speckle")

# The simulated rig's field of view on the reference plane, kept whatever the camera resolution.
SIMULATED_VIEW_WIDTH_MM = 409.6


@dataclass(frozen=True)
class ProjectorConfig:
    backend: str = "gl-offscreen"
    width: int = 912
    height: int = 1140
    monitor: int = 0
    gamma_lut: Path | None = None

    @property
    def size(self) -> tuple[int, int]:
        return (self.width, self.height)


@dataclass(frozen=True)
class CameraConfig:
    backend: str = "simulated"
    exposure_us: float = 10000.0
    gain: float | None = None  # None: leave the camera's gain as it is (units are the backend's)
    index: int = 0
    serial: str | None = None
    width: int = 1024
    height: int = 768
    pixel_format: str = "Mono8"


@dataclass(frozen=True)
class TriggerConfig:
    backend: str = "simulated-serial"
    port: str | None = None
    baudrate: int = 115200
    timeout_s: float = 1.0


@dataclass(frozen=True)
class ScanConfig:
    frequencies: tuple[float, ...] = (1.0, 8.0, 64.0)
    steps: int = 4
    axis: str = "x"
    gray_bits: int = 0
    show_timeout_s: float = 1.0
    fetch_timeout_s: float = 2.0
    retries: int = 2
    pattern_set: str = "phase-shifting"
    speckle_frequency: float = 16.0
    speckle_seed: int = 0
    speckle_dot_px: int = 3
    speckle_gain: float = 0.3
    # several exposures: each exposure's full pattern sequence in turn (docs/hdr.md); empty: [camera] exposure_us
    exposures_us: tuple[float, ...] = ()

    def patterns(self) -> list[dict[str, Any]]:
        """The capture-format pattern entries of one scan, in projection order.

        ``pattern_set = "speckle"``: one ``speckle-sinusoid`` frame (``speckle_frequency`` fringes
        along ``axis``, speckle field of ``speckle_seed``, ``speckle_dot_px``, ``speckle_gain``).
        Otherwise sinusoids of every frequency (``steps`` shifts each), then, if ``gray_bits`` > 0,
        the Gray code bit planes with their inverses (for per-pixel thresholding).
        """
        return [pattern.to_dict() for pattern in self.pattern_models()]

    def pattern_models(self) -> list[Pattern]:
        """The typed patterns of one scan (see :meth:`patterns`)."""
        if self.pattern_set == "speckle":
            return [
                SpeckleSinusoid(
                    axis=self.axis,
                    frequency=_plain_number(self.speckle_frequency),
                    steps=1,
                    step=0,
                    seed=self.speckle_seed,
                    dot_px=self.speckle_dot_px,
                    speckle_gain=self.speckle_gain,
                )
            ]
        out: list[Pattern] = [
            Sinusoid(axis=self.axis, frequency=_plain_number(f), steps=self.steps, step=j)
            for f in self.frequencies
            for j in range(self.steps)
        ]
        for bit in range(self.gray_bits):
            for inverted in (False, True):
                out.append(Gray(axis=self.axis, bit=bit, bits=self.gray_bits, inverted=inverted))
        return out


@dataclass(frozen=True)
class SimulationConfig:
    scene: str = "hemisphere"
    scene_variant: int = 0  # a scene drawn from a family (shiny-and-dark): 0 the nominal one
    snr_db: float | None = 35.0
    seed: int = 0
    l0_mm: float = 1000.0
    d0_mm: float = 250.0
    f0_per_mm: float = 0.015625
    f0_frequency: float = 8.0
    pixel_mm: float | None = None  # default: SIMULATED_VIEW_WIDTH_MM / camera width
    gamma: float = 1.0
    ambient: float = 0.1
    camera_gain: float = 200.0
    # the sensor's full well (electrons at the top grey level): set, it replaces snr_db by shot and read noise
    full_well_e: float | None = None
    read_noise_e: float = 8.0


@dataclass(frozen=True)
class RigConfig:
    projector: ProjectorConfig = field(default_factory=ProjectorConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    trigger: TriggerConfig = field(default_factory=TriggerConfig)
    scan: ScanConfig = field(default_factory=ScanConfig)
    simulation: SimulationConfig = field(default_factory=SimulationConfig)
    source: Path | None = None  # the file it came from; None for the built-in simulated rig

    @property
    def simulated(self) -> bool:
        """True when the camera is simulated: the rig needs the simulation's scene and geometry."""
        return self.camera.backend == "simulated"

    def pixel_mm(self) -> float:
        """Camera pixel size on the reference plane for the simulated geometry."""
        if self.simulation.pixel_mm is not None:
            return self.simulation.pixel_mm
        return SIMULATED_VIEW_WIDTH_MM / self.camera.width


# --- field checkers: each returns the normalised value or raises _Bad("expected ...") ------------


class _Bad(Exception):
    """A value does not fit; the message says what was expected."""


def _plain_number(value: float) -> int | float:
    return int(value) if float(value).is_integer() else float(value)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _positive_number(value: Any) -> float:
    if not _is_number(value) or value <= 0:
        raise _Bad("a positive number")
    return float(value)


def _non_negative_number(value: Any) -> float:
    if not _is_number(value) or value < 0:
        raise _Bad("a number >= 0")
    return float(value)


def _number(value: Any) -> float:
    if not _is_number(value):
        raise _Bad("a number")
    return float(value)


def _non_zero_number(value: Any) -> float:
    if not _is_number(value) or value == 0:
        raise _Bad("a non-zero number")
    return float(value)


def _fraction(value: Any) -> float:
    if not _is_number(value) or not 0 <= value <= 1:
        raise _Bad("a number in [0, 1]")
    return float(value)


def _int_range(low: int, high: int | None = None) -> Callable[[Any], int]:
    def check(value: Any) -> int:
        if not isinstance(value, int) or isinstance(value, bool) or value < low or (high is not None and value > high):
            raise _Bad(f"an integer {low}..{high}" if high is not None else f"an integer >= {low}")
        return value

    return check


def _choice(options: tuple[str, ...]) -> Callable[[Any], str]:
    def check(value: Any) -> str:
        if value not in options:
            raise _Bad("one of " + ", ".join(repr(o) for o in options))
        return value

    return check


def _string(value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise _Bad("a non-empty string")
    return value


def _string_or_int(value: Any) -> str:
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    return _string(value)


MAX_FREQUENCY = 16384.0  # fringes across the projector: more than its pixels cannot be projected


def _frequencies(value: Any) -> tuple[float, ...]:
    if not isinstance(value, list) or not value or not all(_is_number(v) and 0 < v <= MAX_FREQUENCY for v in value):
        raise _Bad(f"a non-empty list of positive numbers up to {MAX_FREQUENCY:g}")
    if len(set(value)) != len(value):
        raise _Bad("distinct frequencies")
    return tuple(float(v) for v in value)


def _frequency(value: Any) -> float:
    if not _is_number(value) or not 0 < value <= MAX_FREQUENCY:
        raise _Bad(f"a positive number up to {MAX_FREQUENCY:g}")
    return float(value)


MAX_EXPOSURES = 8  # exposures of one scan: more multiplies the scan time for little more range


def exposure_list(value: Any) -> tuple[float, ...]:
    """Exposures in microseconds: distinct positive numbers, at most :data:`MAX_EXPOSURES`, in the order given."""
    if not isinstance(value, list) or not 1 <= len(value) <= MAX_EXPOSURES:
        raise _Bad(f"a list of 1 to {MAX_EXPOSURES} exposure times in microseconds")
    out = tuple(_positive_number(v) for v in value)
    if len(set(out)) != len(out):
        raise _Bad("distinct exposure times")
    return out


def parse_exposures(text: str, where: str = "--exposures") -> tuple[float, ...]:
    """Exposures from a comma-separated list in microseconds (``2000,8000,32000``); ConfigError in one line."""
    expected = "comma-separated exposure times in microseconds such as 2000,8000,32000"
    try:
        values = [float(part) for part in str(text).split(",")]
    except ValueError:
        raise ConfigError(f"{where}: expected {expected}, found {_found(text)}") from None
    try:
        return exposure_list(values)
    except _Bad as bad:
        raise ConfigError(f"{where}: expected {bad} ({expected}), found {_found(text)}") from None


def _size(value: Any) -> tuple[int, int]:
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in value)
    ):
        raise _Bad("[width, height] in pixels, two positive integers")
    side = files.limits().max_image_side
    if max(value) > side or value[0] * value[1] > files.limits().max_image_pixels:
        raise _Bad(f"[width, height] of at most {side} pixels per side (RIG_MAX_IMAGE_SIDE, docs/safety.md)")
    return (value[0], value[1])


def _snr(value: Any) -> float | None:
    if value == "none":
        return None
    if not _is_number(value):
        raise _Bad('a number in dB or "none"')
    return float(value)


# Section -> key -> checker. Keys absent from the file keep the dataclass defaults.
_SCHEMA: dict[str, dict[str, Callable[[Any], Any]]] = {
    "projector": {
        "backend": _choice(PROJECTOR_BACKENDS),
        "size": _size,
        "monitor": _int_range(0),
        "gamma_lut": _string,
    },
    "camera": {
        "backend": _choice(CAMERA_BACKENDS),
        "exposure_us": _positive_number,
        "gain": _non_negative_number,
        "index": _int_range(0),
        "serial": _string_or_int,
        "size": _size,
        "pixel_format": _choice(("Mono8", "Mono12", "Mono16")),
    },
    "trigger": {
        "backend": _choice(TRIGGER_BACKENDS),
        "port": _string,
        "baudrate": _int_range(1, MAX_BAUDRATE),
        "timeout_s": _positive_number,
    },
    "scan": {
        "frequencies": _frequencies,
        "steps": _int_range(3, 64),
        "axis": _choice(PATTERN_AXES),
        "gray_bits": _int_range(0, 12),
        "show_timeout_s": _positive_number,
        "fetch_timeout_s": _positive_number,
        "retries": _int_range(0, 20),
        "pattern_set": _choice(PATTERN_SETS),
        "speckle_frequency": _frequency,
        "speckle_seed": _int_range(0),
        "speckle_dot_px": _int_range(1, 64),
        "speckle_gain": _fraction,
        "exposures_us": exposure_list,
    },
    "simulation": {
        "scene": _string,
        "scene_variant": _int_range(0),
        "snr_db": _snr,
        "seed": _int_range(0),
        "l0_mm": _positive_number,
        "d0_mm": _non_zero_number,
        "f0_per_mm": _positive_number,
        "f0_frequency": _positive_number,
        "pixel_mm": _positive_number,
        "gamma": _positive_number,
        "ambient": _non_negative_number,
        "camera_gain": _positive_number,
        "full_well_e": _positive_number,
        "read_noise_e": _non_negative_number,
    },
}


def _found(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _section(data: Mapping[str, Any], name: str, where: str) -> dict[str, Any]:
    """Checked values of one section, keyed like the dataclass fields."""
    raw = data.get(name, {})
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: [{name}]: expected a table, found {_found(raw)}")
    schema = _SCHEMA[name]
    values: dict[str, Any] = {}
    for key, value in raw.items():
        if key not in schema:
            raise ConfigError(f"{where}: [{name}] {key}: unknown key; expected one of {', '.join(schema)}")
        try:
            values[key] = schema[key](value)
        except _Bad as bad:
            raise ConfigError(f"{where}: [{name}] {key}: expected {bad}, found {_found(value)}") from None
    if "size" in values:
        values["width"], values["height"] = values.pop("size")
    return values


def parse_config(data: Mapping[str, Any], source: Path | None = None, where: str | None = None) -> RigConfig:
    """Validated :class:`RigConfig` from parsed TOML; relative paths resolve against ``source``'s folder.

    ``where`` starts every error message (default: the source file, else "rig config").
    """
    where = where or (str(source) if source is not None else "rig config")
    unknown = sorted(set(data) - set(_SCHEMA))
    if unknown:
        raise ConfigError(f"{where}: [{unknown[0]}]: unknown section; expected one of {', '.join(_SCHEMA)}")
    projector = _section(data, "projector", where)
    if "gamma_lut" in projector:
        lut = Path(projector["gamma_lut"]).expanduser()
        if not lut.is_absolute() and source is not None:
            lut = source.parent / lut
        if not lut.is_file():
            raise ConfigError(f"{where}: [projector] gamma_lut: expected an existing file, found {str(lut)!r}")
        projector["gamma_lut"] = lut
    camera = _section(data, "camera", where)
    trigger = _section(data, "trigger", where)
    if "backend" not in trigger and camera.get("backend", CameraConfig.backend) != "simulated":
        trigger["backend"] = "software"  # the fake trigger box can only pulse the simulated camera
    if trigger.get("backend") == "serial" and "port" not in trigger:
        raise ConfigError(
            f"{where}: [trigger] port: expected a serial port or pyserial URL for backend 'serial', found nothing"
        )
    scan = _section(data, "scan", where)
    simulation = _section(data, "simulation", where)
    config = RigConfig(
        projector=ProjectorConfig(**projector),
        camera=CameraConfig(**camera),
        trigger=TriggerConfig(**trigger),
        scan=ScanConfig(**scan),
        simulation=SimulationConfig(**simulation),
        source=source,
    )
    _check_consistency(config, where)
    return config


def _check_consistency(config: RigConfig, where: str) -> None:
    """Rules that tie several keys together."""
    if not config.simulated and config.trigger.backend == "simulated-serial":
        raise ConfigError(
            f"{where}: [trigger] backend: expected 'software' or 'serial' with camera backend "
            f"{config.camera.backend!r} ('simulated-serial' pulses the simulated camera only), found 'simulated-serial'"
        )
    if config.simulated:  # [simulation] scene is checked by the simulated rig (rig.hardware.scenes), which has them
        if config.trigger.backend == "serial":
            raise ConfigError(
                f"{where}: [trigger] backend: expected 'simulated-serial' or 'software' with the simulated camera "
                "(a real trigger box cannot expose it), found 'serial'"
            )
        if config.projector.backend != "gl-offscreen":
            raise ConfigError(
                f"{where}: [projector] backend: expected 'gl-offscreen' with the simulated camera "
                f"(it looks at the off-screen rendering), found {config.projector.backend!r}"
            )


def load_config(path: str | Path | None) -> RigConfig:
    """Read and validate a rig config file; ``None`` gives the built-in simulated rig."""
    if path is None:
        return RigConfig()
    path = Path(path)
    try:
        with path.open("rb") as handle:
            data = tomllib.load(handle)
    except FileNotFoundError:
        raise ConfigError(f"{path}: rig config file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: expected a rig config file, found a directory") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except (ValueError, RecursionError) as exc:  # integers of thousands of digits, arrays nested thousands deep
        raise ConfigError(f"{path}: not valid TOML: {files.shorten(str(exc) or type(exc).__name__, 120)}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the rig config: {exc.strerror}") from None
    return parse_config(data, source=path)
