"""The console's Verify view on the server side: the checked plan of a verification, its run, its report.

The session is the one ``rig verify`` runs (:func:`rig.verify.session.verify`), into
``DATA/verifications/NAME``: on the simulated rig its world places the artefacts; on a real rig
each placement is a prompt in the page, answered with Done (the calibration wizard's prompt). The
artefacts' calibrated values come from ``DATA/artefacts.toml`` when it exists, else they are the
simulated rig's; the MPE is the request's (the simulated rig's by default, required on a real rig).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from rig.config import RigConfig
from rig.console.datadir import DataDir
from rig.errors import RigError
from rig.events import Reporter
from rig.verify import guideline
from rig.verify.plan import SIMULATED_MPE_MM, VerificationPlan

VERIFICATIONS = "verifications"
ARTEFACTS_FILE = "artefacts.toml"
SPHERE_POSITIONS_MAX = 30
FIGURE_NAME_CHARS = frozenset("abcdefghijklmnopqrstuvwxyz0123456789-.")


def verification_plan(
    config: RigConfig,
    spheres: int = guideline.SPHERE_POSITIONS,
    ball_bars: int = guideline.BALL_BAR_POSITIONS,
    planes: int = guideline.PLANE_POSITIONS,
    mpe_mm: Mapping[str, float] | None = None,
) -> VerificationPlan:
    """The checked plan of a console verification (bounds first: nothing sized by a request before)."""
    from rig.hardware.assembly import rig_sets_up_scenes

    counts = (
        ("spheres", spheres, SPHERE_POSITIONS_MAX),
        ("ball_bars", ball_bars, guideline.BALL_BAR_POSITIONS),
        ("planes", planes, guideline.PLANE_POSITIONS),
    )
    for field, count, most in counts:
        if not 1 <= count <= most:
            raise RigError(f"{field}: expected 1 .. {most} positions, found {count}")
    if mpe_mm is None:
        if not rig_sets_up_scenes(config):
            raise RigError("mpe_mm: missing: declare the rig's maximum permissible errors PF, PS, SD, F in mm")
        mpe_mm = SIMULATED_MPE_MM
    if set(mpe_mm) != set(guideline.QUANTITIES) or not all(math.isfinite(v) and v > 0 for v in mpe_mm.values()):
        raise RigError(f"mpe_mm: expected a positive MPE in mm for each of PF, PS, SD, F, found {dict(mpe_mm)}")
    return VerificationPlan(spheres, ball_bars, planes, {q: float(mpe_mm[q]) for q in guideline.QUANTITIES})


def run_verification(
    config: RigConfig,
    data: DataDir,
    plan: VerificationPlan,
    calibration_dir: Path,
    output: Path,
    reporter: Reporter,
    ask: Callable[[str], object],
) -> dict[str, Any]:
    """Run the guided session into ``output``; its report. ``ask`` prompts the operator (real rig only)."""
    from rig.hardware.assembly import rig_sets_up_scenes
    from rig.verify.artefacts import load_artefacts
    from rig.verify.operator import PromptOperator
    from rig.verify.session import verify

    artefacts_file = data.root / ARTEFACTS_FILE
    artefacts = load_artefacts(artefacts_file if artefacts_file.is_file() else None)
    operator = None if rig_sets_up_scenes(config) else PromptOperator(ask)
    result = verify(config, plan, artefacts, calibration_dir, output, operator, reporter)
    return result.report


def read_verification(data: DataDir, name: str) -> dict[str, Any]:
    """The report of ``DATA/verifications/NAME`` with the names of its figures."""
    from rig.verify.report import FIGURES_DIR, read_report

    directory = data.existing(VERIFICATIONS, name)
    report = read_report(directory)
    folder = directory / FIGURES_DIR
    names = sorted(p.name for p in folder.iterdir() if _is_figure_name(p.name)) if folder.is_dir() else []
    return {"name": name, "report": report, "figures": names}


def figure_path(data: DataDir, name: str, figure: str) -> Path:
    """The checked path of one PNG figure of a verification (a regular file inside its figures folder)."""
    from rig.errors import OutputError
    from rig.store import files
    from rig.verify.report import FIGURES_DIR

    if not _is_figure_name(figure):
        raise FileNotFoundError(
            f"verifications/{name}/{figure}: not a figure name (lower-case letters, digits, '-', .png)"
        )
    path = data.existing(VERIFICATIONS, name) / FIGURES_DIR / figure
    if path.is_symlink() or not path.resolve().is_relative_to(data.root):
        raise FileNotFoundError(f"verifications/{name}/{figure}: not a figure of this verification (a link)")
    try:
        os.close(files.open_regular(path, str(path), OutputError, missing="not written"))
    except OutputError as exc:
        raise FileNotFoundError(str(exc)) from None
    return path


def _is_figure_name(name: str) -> bool:
    return name.endswith(".png") and not name.startswith(".") and set(name) <= FIGURE_NAME_CHARS


def verification_history(data: DataDir, calibration: str) -> dict[str, Any]:
    """The verification history of a calibration: its entries, oldest first, and the series to plot."""
    from rig.verify.history import history_series, read_history

    entries = read_history(data.existing("calibrations", calibration))
    series = {q: [{"created": t, "worst_mm": v} for t, v in points] for q, points in history_series(entries).items()}
    return {"calibration": calibration, "entries": entries, "series": series}
