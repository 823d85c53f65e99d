"""Who puts each artefact in place during a verification: a person, or the simulated world.

A session calls ``place(placement)`` before each scan. :class:`PromptOperator` asks a person
through an ``ask`` callable (``input`` at a terminal; a browser can answer instead): "ball bar,
position 3 of 7: space diagonal ..., press Enter". The simulated rig brings its own operator that
builds the artefact in its virtual scene (:class:`rig.hardware.simulated.ArtefactWorld`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from rig.errors import ConfigError
from rig.verify.guideline import Placement


class Operator(Protocol):
    """Sets up the artefact in front of the rig for the next scan of a verification."""

    def place(self, placement: Placement) -> None:
        """Put ``placement``'s artefact where it says; return when it is there."""


class PromptOperator:
    """Asks a person (``ask(message)`` returns when they are done)."""

    def __init__(self, ask: Callable[[str], object] = input) -> None:
        self._ask = ask

    def place(self, placement: Placement) -> None:
        try:
            self._ask(placement.prompt())
        except EOFError:
            raise ConfigError(
                "verification needs an operator at the console to place the artefacts (no input)"
            ) from None
