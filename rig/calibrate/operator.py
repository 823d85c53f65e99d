"""Who sets up each step of a calibration session: a person, a motorised stage, or the simulated world.

A session calls ``plane(height_mm)``, ``board(index, on_plane)``, ``pose(index)`` (stereo board
poses) and ``clear()`` before each capture. :class:`ConsoleOperator` asks a person through an
``ask`` callable (``input`` at a terminal; the console answers from a browser) and can drive a
:class:`StageCommand`; the simulated rig brings its own operator that places its virtual scene
(:class:`rig.hardware.simulated.WorldOperator`).
"""

from __future__ import annotations

import logging
import shlex
import subprocess
from collections.abc import Callable
from typing import Protocol

from rig.errors import ConfigError

log = logging.getLogger(__name__)


class Operator(Protocol):
    """Sets up the scene in front of the rig for the next capture of a session."""

    def plane(self, height_mm: float) -> None:
        """Put the flat plane at ``height_mm`` above the reference plane (0: the reference itself)."""

    def board(self, index: int, on_plane: bool) -> None:
        """Put the calibration board in view: flat on the reference plane, or tilted (view ``index``)."""

    def pose(self, index: int) -> None:
        """Hold the board in stereo pose ``index`` (model ``stereo``)."""

    def clear(self) -> None:
        """Clear the view down to the bare reference plane (for the gamma ramp)."""


class ConsoleOperator:
    """Asks a person (``ask(message)`` returns when they are done) and optionally drives a stage."""

    def __init__(self, ask: Callable[[str], object] = input, stage: StageCommand | None = None) -> None:
        self._ask = ask
        self.stage = stage

    def ask(self, message: str) -> None:
        try:
            self._ask(message)
        except EOFError:
            raise ConfigError(
                "calibration needs an operator at the console (no input); use --stage-command for a motorised stage"
            ) from None

    def plane(self, height_mm: float) -> None:
        if self.stage is not None:
            self.stage.move(height_mm)
            return
        where = "the reference position (0 mm)" if height_mm == 0 else f"{height_mm:g} mm"
        self.ask(f"move the plane to {where}, press Enter ")

    def board(self, index: int, on_plane: bool) -> None:
        if on_plane:
            self.ask("lay the board flat on the reference plane, press Enter ")
        else:
            self.ask(f"hold the board tilted in view (view {index}), press Enter ")

    def pose(self, index: int) -> None:
        self.ask(f"hold the board in pose {index} (tilted, fully in view of camera and projector), press Enter ")

    def clear(self) -> None:
        self.ask("clear the view down to the bare reference plane, press Enter ")


class StageCommand:
    """A motorised stage moved by a shell command template, e.g. ``"stage-move --mm {height_mm}"``."""

    def __init__(self, template: str, timeout_s: float = 120.0) -> None:
        if "{height_mm" not in template:
            raise ConfigError(f"--stage-command: expected a '{{height_mm}}' placeholder, found {template!r}")
        self.template = template
        self.timeout_s = timeout_s

    def move(self, height_mm: float) -> None:
        """Run the command for ``height_mm``; ConfigError if it fails or times out."""
        command = shlex.split(self.template.format(height_mm=height_mm))
        log.info("stage: %s", " ".join(command))
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=self.timeout_s, check=False)
        except FileNotFoundError:
            raise ConfigError(f"--stage-command: {command[0]}: not found") from None
        except subprocess.TimeoutExpired:
            raise ConfigError(f"--stage-command: moving to {height_mm:g} mm took over {self.timeout_s:g} s") from None
        if done.returncode != 0:
            tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or [""]
            raise ConfigError(f"--stage-command: moving to {height_mm:g} mm failed (exit {done.returncode}): {tail[0]}")
