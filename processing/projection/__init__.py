"""What the projector shows: the pattern model (fringes, Gray codes, speckle) and its rendering.

Main entry points:

- :class:`Pattern` and its kinds (``patterns``): :class:`Sinusoid`, :class:`SpeckleSinusoid`,
  :class:`Gray`, :class:`Binary`, :class:`Flat`, :class:`Grid`; :func:`parse_pattern` reads one from JSON and
  :func:`pattern_image` renders it.
- :func:`speckle_field` (``speckle``): the binary speckle of the single-shot pattern.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from processing._lazy import lazy_exports

if TYPE_CHECKING:
    from processing.projection.patterns import (
        Binary,
        Flat,
        Gray,
        Grid,
        Pattern,
        PatternError,
        Sinusoid,
        SpeckleSinusoid,
        parse_pattern,
        pattern_image,
    )
    from processing.projection.speckle import speckle_field

_SOURCES = {
    "Binary": "patterns",
    "Flat": "patterns",
    "Gray": "patterns",
    "Grid": "patterns",
    "Pattern": "patterns",
    "PatternError": "patterns",
    "Sinusoid": "patterns",
    "SpeckleSinusoid": "patterns",
    "parse_pattern": "patterns",
    "pattern_image": "patterns",
    "speckle_field": "speckle",
}

__all__ = [
    "Binary",
    "Flat",
    "Gray",
    "Grid",
    "Pattern",
    "PatternError",
    "Sinusoid",
    "SpeckleSinusoid",
    "parse_pattern",
    "pattern_image",
    "speckle_field",
]

__getattr__, __dir__ = lazy_exports(__name__, _SOURCES)
