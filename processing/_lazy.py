"""Lazy public names of a package: each is imported from its module on first use.

A subpackage's ``__init__`` lists its public API explicitly, but importing the package (or any
module in it) must not import every module of the group: some pull in OpenCV or SciPy, which
``rig --help`` and the phase-shifting path do without. The package keeps a ``name -> module``
table; :func:`lazy_exports` turns it into the module-level ``__getattr__`` and ``__dir__`` of
PEP 562, so ``from processing.phase import wrapped_phase`` imports ``processing.phase.phase_shift``
only then.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping


def lazy_exports(package: str, sources: Mapping[str, str]) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``: ``sources`` maps a public name to its module (relative)."""

    def __getattr__(name: str) -> object:
        module = sources.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{module}"), name)

    def __dir__() -> list[str]:
        return sorted(sources)

    return __getattr__, __dir__
