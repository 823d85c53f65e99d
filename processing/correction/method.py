"""The typed entry of a phase-correction registry: name, the function, what it needs, its help text.

A correction takes the unwrapped phase and the wrapped phase it came from and returns the
corrected phase and an info dict for the report. Most need nothing else; some need data a
calibration learnt (``needs`` names it, e.g. ``"phase_error"``: the projector-gamma ripple
table), which the caller passes as a keyword argument of that name.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

Result = tuple[np.ndarray, dict[str, Any]]


@dataclass(frozen=True)
class CorrectionMethod:
    """One registered correction; calling it calls ``run``.

    ``run``: ``f(absolute_phase, wrapped_phase, orders=None, mask=None, frequency=None, **params)
    -> (phase, info)``. ``needs``: inputs beyond the phase pair, passed by the caller as keyword
    arguments of these names (``"phase_error"``: a calibration's phase-error table).
    ``description``: one line for ``--help`` and the docs.
    """

    name: str
    run: Callable[..., Result]
    description: str
    needs: tuple[str, ...] = ()

    def __call__(self, absolute_phase: np.ndarray, wrapped_phase: np.ndarray, *args: Any, **kwargs: Any) -> Result:
        return self.run(absolute_phase, wrapped_phase, *args, **kwargs)
