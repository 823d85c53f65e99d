"""The batch's tables: ``index.csv`` (one row per capture) and ``compare.csv`` (one per capture and
correction), each rewritten whole and atomically so that a reader never sees half a table."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from calibration.jsonfile import write_text_atomic


@dataclass
class IndexRow:
    """One capture's line of ``index.csv``; ``message`` is the line ``rig process`` prints for an error."""

    capture: str
    status: str
    message: str = ""
    valid_fraction: float | None = None
    height_min_mm: float | None = None
    height_median_mm: float | None = None
    height_max_mm: float | None = None
    correction: str = ""
    seconds: float | None = None
    worker: str = ""


@dataclass
class CompareRow:
    """One capture processed with one correction: the figures ``compare.csv`` lists."""

    capture: str
    method: str
    status: str
    message: str = ""
    valid_fraction: float | None = None
    order_breaks: int | None = None
    height_min_mm: float | None = None
    height_median_mm: float | None = None
    height_max_mm: float | None = None
    nmse_h: float | None = None
    seconds: float | None = None


INDEX_COLUMNS = tuple(f.name for f in fields(IndexRow))
COMPARE_COLUMNS = tuple(f.name for f in fields(CompareRow))


def height_stats(report: Mapping[str, Any]) -> dict[str, float | None]:
    """``height_min_mm``/``median``/``max`` from a report's ``height_mm`` (None without a calibration)."""
    heights = report.get("height_mm") or {}
    return {f"height_{key}_mm": heights.get(key) for key in ("min", "median", "max")}


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def table_text(columns: tuple[str, ...], rows: Iterable[Mapping[str, Any]]) -> str:
    """CSV text (header + rows) of ``rows`` in ``columns`` order."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in columns])
    return buffer.getvalue()


def write_table_atomic(path: Path, text: str) -> Path:
    """Write ``text`` to a temporary sibling, sync it and rename it onto ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, text, newline="")
    return path


def write_index(path: Path, rows: Iterable[IndexRow]) -> Path:
    """``index.csv``: one row per capture, sorted by capture name."""
    ordered = sorted(rows, key=lambda r: r.capture)
    return write_table_atomic(path, table_text(INDEX_COLUMNS, (asdict(r) for r in ordered)))


def write_compare(path: Path, rows: Iterable[CompareRow], methods: tuple[str, ...]) -> Path:
    """``compare.csv``: one row per capture and method, captures sorted, methods in the order asked."""
    rank = {m: i for i, m in enumerate(methods)}
    ordered = sorted(rows, key=lambda r: (r.capture, rank.get(r.method, len(rank))))
    return write_table_atomic(path, table_text(COMPARE_COLUMNS, (asdict(r) for r in ordered)))


def read_table(path: Path) -> list[dict[str, str]]:
    """Rows of a CSV written here, as dicts of strings (for checks and tests)."""
    with open(path, encoding="utf-8", newline="") as handle:
        return list(csv.DictReader(handle))
