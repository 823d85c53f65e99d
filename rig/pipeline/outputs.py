"""Where the writers of ``rig process``'s files used to live; kept so that older imports still work.

The result directory belongs to :mod:`rig.store.results` (write, read, list, describe; every file
name and the output format registry); the file encoders are in :mod:`rig.store.result_files`;
the report is built by :mod:`rig.pipeline.result`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rig.pipeline.result import ProcessResult, build_report
from rig.store import results
from rig.store.result_files import (
    PREVIEW_BAR_PX,
    colour_map,
    preview_range,
    read_ply_points,
    write_array,
    write_ply,
    write_preview,
    write_report,
)

__all__ = [
    "PREVIEW_BAR_PX",
    "build_report",
    "check_output_directory",
    "colour_map",
    "preview_range",
    "read_ply_points",
    "write_array",
    "write_outputs",
    "write_ply",
    "write_preview",
    "write_report",
]


def check_output_directory(out_dir: str | Path) -> None:
    """Before computing: ``out_dir`` can be written and is new, empty or an earlier result (OutputError if not)."""
    results.check_target(out_dir, overwrite=True)


def write_outputs(
    result: ProcessResult,
    out_dir: str | Path,
    extra: Mapping[str, Any] | None = None,
    staged_inputs: tuple[Path, Path] | None = None,
) -> dict[str, Any]:
    """:func:`rig.store.results.write_result` with the default formats, replacing an earlier result."""
    return results.write_result(result, out_dir, overwrite=True, extra=extra, staged_inputs=staged_inputs)
