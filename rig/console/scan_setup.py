"""The console's scan setup: part name and notes, pattern set, frequencies, steps and exposures.

Remembered per data folder in ``DATA/scan-setup.json`` (written atomically; a file that does not
read is set aside for the defaults, and the status says so). Values are checked by the rig
config's own rules (:func:`rig.config.parse_config`), so the page and a config file accept the
same things; a refusal names the field in a sentence.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from calibration.jsonfile import write_json_atomic
from rig.config import RigConfig, parse_config
from rig.errors import ConfigError, RigError

log = logging.getLogger(__name__)

SETUP_FILE = "scan-setup.json"
NOTES_LENGTH = 2000
PART_LENGTH = 60
_NOT_NAME = re.compile(r"[^A-Za-z0-9._-]+")


class SetupError(RigError):
    """A scan setup value the console cannot take (the message names the field)."""


@dataclass
class ScanSetup:
    """What the next scan from the console projects and records; empty fields keep the rig config's."""

    part: str = ""  # the capture's name starts with it; recorded in capture.json
    notes: str = ""
    pattern_set: str = "phase-shifting"
    frequencies: list[float] = field(default_factory=list)  # empty: [scan] frequencies
    steps: int | None = None  # None: [scan] steps
    exposures_us: list[float] = field(default_factory=list)  # empty: the camera's one exposure

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def config(self, base: RigConfig) -> RigConfig:
        """``base`` with this setup's scan settings."""
        scan = dataclasses.replace(base.scan, pattern_set=self.pattern_set)
        if self.frequencies:
            scan = dataclasses.replace(scan, frequencies=tuple(self.frequencies))
        if self.steps is not None:
            scan = dataclasses.replace(scan, steps=self.steps)
        return dataclasses.replace(base, scan=dataclasses.replace(scan, exposures_us=tuple(self.exposures_us)))

    def capture_prefix(self) -> str:
        """The start of a capture's default name: the part name made a plain name, else ``scan``."""
        plain = _NOT_NAME.sub("-", self.part).strip("-._")[:PART_LENGTH]
        return plain or "scan"

    def capture_extra(self) -> dict[str, Any]:
        """What capture.json records of the setup (``part``: name and notes), when there is any."""
        if not (self.part or self.notes):
            return {}
        return {"part": {"name": self.part, "notes": self.notes}}


FIELD_NAMES = {
    "part": "part name",
    "notes": "notes",
    "pattern_set": "pattern set",
    "frequencies": "frequencies",
    "steps": "steps",
    "exposures_us": "exposures",
}


def checked(current: ScanSetup, changes: dict[str, Any]) -> ScanSetup:
    """``current`` with ``changes``; :class:`SetupError` naming the first field that does not fit."""
    values = {**current.to_dict(), **changes}
    unknown = sorted(set(changes) - set(FIELD_NAMES))
    if unknown:
        raise SetupError(f"{unknown[0]}: not a scan setup field; expected one of {', '.join(FIELD_NAMES)}")
    for key in ("part", "notes"):
        if not isinstance(values[key], str):
            raise SetupError(f"{FIELD_NAMES[key]}: expected text, found {values[key]!r}")
    if len(values["part"]) > PART_LENGTH:
        raise SetupError(f"part name: expected at most {PART_LENGTH} characters, found {len(values['part'])}")
    if len(values["notes"]) > NOTES_LENGTH:
        raise SetupError(f"notes: expected at most {NOTES_LENGTH} characters, found {len(values['notes'])}")
    scan: dict[str, Any] = {"pattern_set": values["pattern_set"]}
    if values["frequencies"]:
        scan["frequencies"] = values["frequencies"]
    if values["steps"] is not None:
        scan["steps"] = values["steps"]
    if values["exposures_us"]:
        scan["exposures_us"] = values["exposures_us"]
    try:
        parsed = parse_config({"scan": scan}, where="scan setup").scan
    except ConfigError as exc:
        raise SetupError(_sentence(str(exc))) from None
    return ScanSetup(
        part=values["part"].strip(),
        notes=values["notes"],
        pattern_set=parsed.pattern_set,
        frequencies=list(parsed.frequencies) if values["frequencies"] else [],
        steps=parsed.steps if values["steps"] is not None else None,
        exposures_us=list(parsed.exposures_us),
    )


def _sentence(message: str) -> str:
    """``scan setup: [scan] steps: expected ...`` as ``steps: expected ...`` (the page's field names)."""
    text = message.removeprefix("scan setup: ").removeprefix("[scan] ")
    for key, label in FIELD_NAMES.items():
        if text.startswith(key + ":"):
            return label + text[len(key) :]
    return text


def load(root: Path) -> tuple[ScanSetup, str | None]:
    """The setup remembered in ``root`` (defaults when there is none) and a note if the file did not read."""
    path = Path(root) / SETUP_FILE
    if not path.is_file():
        return ScanSetup(), None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict):
            raise SetupError(f"expected a JSON object, found {type(data).__name__}")
        return checked(ScanSetup(), data), None
    except (OSError, ValueError, SetupError) as exc:
        log.warning("%s: not used (%s); the scan setup starts from the defaults", path, exc)
        return ScanSetup(), f"{path.name}: not used ({exc}); the scan setup starts from the defaults"


def save(root: Path, setup: ScanSetup) -> None:
    """Remember ``setup`` in ``root`` (atomically)."""
    try:
        write_json_atomic(Path(root) / SETUP_FILE, setup.to_dict())
    except OSError as exc:
        raise SetupError(f"{Path(root) / SETUP_FILE}: cannot be written: {exc.strerror or exc}") from None
