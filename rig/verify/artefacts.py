"""``ARTEFACTS.toml``: the calibrated values of the test artefacts, with their uncertainty.

::

    [sphere]
    diameter_mm = 60.000          # from the sphere's calibration certificate
    uncertainty_mm = 0.002
    [ball_bar]
    length_mm = 200.000           # distance between the two sphere centres
    sphere_diameter_mm = 40.000
    uncertainty_mm = 0.003
    [plane]
    length_mm = 300.0
    width_mm = 80.0
    flatness_mm = 0.002
    uncertainty_mm = 0.002
    [volume]                      # optional: the measuring volume's depth (default: the calibration's)
    depth_mm = 150.0

Every error names the file, the field, what was expected and what was found.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rig.errors import ConfigError
from rig.store import files

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


@dataclass(frozen=True)
class Artefacts:
    """Calibrated artefact values (mm) and their standard uncertainties (mm)."""

    sphere_diameter_mm: float = 60.0
    sphere_uncertainty_mm: float = 0.002
    ball_bar_length_mm: float = 200.0
    ball_bar_sphere_diameter_mm: float = 40.0
    ball_bar_uncertainty_mm: float = 0.003
    plane_length_mm: float = 300.0
    plane_width_mm: float = 80.0
    plane_flatness_mm: float = 0.002
    plane_uncertainty_mm: float = 0.002
    depth_mm: float | None = None  # the measuring volume's depth, when the file gives it
    source: str = "built-in artefacts of the simulated rig"

    def as_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "sphere": {"diameter_mm": self.sphere_diameter_mm, "uncertainty_mm": self.sphere_uncertainty_mm},
            "ball_bar": {
                "length_mm": self.ball_bar_length_mm,
                "sphere_diameter_mm": self.ball_bar_sphere_diameter_mm,
                "uncertainty_mm": self.ball_bar_uncertainty_mm,
            },
            "plane": {
                "length_mm": self.plane_length_mm,
                "width_mm": self.plane_width_mm,
                "flatness_mm": self.plane_flatness_mm,
                "uncertainty_mm": self.plane_uncertainty_mm,
            },
        }


# (table, key) -> Artefacts field; all required when the table is given
_FIELDS = {
    ("sphere", "diameter_mm"): "sphere_diameter_mm",
    ("sphere", "uncertainty_mm"): "sphere_uncertainty_mm",
    ("ball_bar", "length_mm"): "ball_bar_length_mm",
    ("ball_bar", "sphere_diameter_mm"): "ball_bar_sphere_diameter_mm",
    ("ball_bar", "uncertainty_mm"): "ball_bar_uncertainty_mm",
    ("plane", "length_mm"): "plane_length_mm",
    ("plane", "width_mm"): "plane_width_mm",
    ("plane", "flatness_mm"): "plane_flatness_mm",
    ("plane", "uncertainty_mm"): "plane_uncertainty_mm",
}


def _number(data: dict[str, Any], table: str, key: str, where: str, zero_ok: bool) -> float:
    section = data.get(table)
    if not isinstance(section, dict):
        raise ConfigError(f"{where}: [{table}]: missing (expected a table with {key})")
    value = section.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{where}: [{table}] {key}: expected a number in mm, found {value!r}")
    if not (value >= 0 if zero_ok else value > 0) or value != value or value == float("inf"):
        raise ConfigError(
            f"{where}: [{table}] {key}: expected a {'non-negative' if zero_ok else 'positive'} finite number, found {value!r}"
        )
    return float(value)


def parse_artefacts(data: dict[str, Any], where: str) -> Artefacts:
    """Artefacts from parsed TOML; unknown tables and keys are refused (a typo would go unnoticed)."""
    known = {"sphere", "ball_bar", "plane", "volume"}
    for table, section in data.items():
        if table not in known:
            raise ConfigError(f"{where}: [{table}]: unknown table, expected one of {', '.join(sorted(known))}")
        keys = {k for (t, k) in _FIELDS if t == table} | ({"depth_mm"} if table == "volume" else set())
        extra = sorted(set(section) - keys) if isinstance(section, dict) else []
        if extra:
            raise ConfigError(f"{where}: [{table}] {extra[0]}: unknown key, expected one of {', '.join(sorted(keys))}")
    values = {
        field: _number(data, table, key, where, zero_ok=key in ("uncertainty_mm", "flatness_mm"))
        for (table, key), field in _FIELDS.items()
    }
    depth = _number(data, "volume", "depth_mm", where, zero_ok=False) if "volume" in data else None
    return Artefacts(**values, depth_mm=depth, source=where)


def load_artefacts(path: Path | None) -> Artefacts:
    """``ARTEFACTS.toml`` read through the safe file layer; None gives the simulated rig's artefacts."""
    if path is None:
        return Artefacts()
    raw = files.read_regular(Path(path), str(path), ConfigError, files.limits().max_manifest_bytes, "missing")
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    return parse_artefacts(data, str(path))
