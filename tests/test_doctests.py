"""The examples in processing's docstrings run and print what they say (doctest)."""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
MODULES = sorted(
    ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
    for path in (ROOT / "processing").rglob("*.py")
)
WITH_EXAMPLES = [
    "processing.phase.shifting",
    "processing.unwrap.temporal",
    "processing.unwrap.spatial",
    "processing.geometry.height",
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_hold(name: str) -> None:
    module = importlib.import_module(name)
    with np.printoptions(legacy=False):
        failed, attempted = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert failed == 0, f"{failed} of {attempted} examples in {name} fail (run: python -m doctest -v on it)"
    if name in WITH_EXAMPLES:
        assert attempted > 0, f"{name} lost its examples"
