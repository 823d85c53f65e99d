"""No function of the product is longer than a reader can hold: at most 80 lines.

Ruff's McCabe rule (pyproject.toml) bounds the branches; this bounds the length. Tests and
benchmarks are outside the rule, and so are the study report's writers, which set out one section
of the report after another (they carry ``noqa: C901`` for the same reason).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rig", "processing", "calibration", "drivers", "mock_devices")
MAX_LINES = 80
STUDY_REPORT = {
    ("rig/study/experiments.py", "write_report"),
    ("rig/study/experiments.py", "_figures"),
    ("rig/study/figures.py", "line_plot"),
}


def _long_functions(source: str, limit: int) -> list[tuple[str, int]]:
    """(name, lines) of each function or method in ``source`` longer than ``limit`` lines."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
            lines = (node.end_lineno or node.lineno) - first + 1
            if lines > limit:
                found.append((node.name, lines))
    return found


def test_the_measure_counts_decorators_and_nested_functions() -> None:
    source = "@decorator\ndef outer():\n" + "    x = 1\n" * 5 + "    def inner():\n" + "        y = 2\n" * 3
    assert _long_functions(source, 9) == [("outer", 11)]
    assert sorted(_long_functions(source, 3)) == [("inner", 4), ("outer", 11)]


def test_no_function_is_over_80_lines() -> None:
    too_long = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            relative = path.relative_to(ROOT).as_posix()
            for name, lines in _long_functions(path.read_text(encoding="utf-8"), MAX_LINES):
                if (relative, name) not in STUDY_REPORT:
                    too_long.append(f"{relative}:{name} ({lines} lines)")
    assert not too_long, "split into named steps: " + ", ".join(too_long)
