"""processing's subpackages: each public name comes from the module its table names, lazily."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import processing

SUBPACKAGES = processing.__all__


@pytest.mark.parametrize("package", SUBPACKAGES)
def test_public_names_resolve_to_their_module(package: str) -> None:
    module = importlib.import_module(f"processing.{package}")
    assert sorted(module.__all__) == sorted(module._SOURCES) == sorted(dir(module))
    for name in module.__all__:
        source = importlib.import_module(f"processing.{package}.{module._SOURCES[name]}")
        assert getattr(module, name) is getattr(source, name), f"processing.{package}.{name}"
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        getattr(module, "no_such_name")  # noqa: B009


def test_importing_a_subpackage_imports_none_of_its_modules() -> None:
    code = (
        "import sys, processing.phase, processing.unwrap, processing.correction;"
        "print(sorted(m for m in sys.modules if m.count('.') >= 2 and m.startswith('processing.')))"
    )
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert loaded.strip() == "[]"
