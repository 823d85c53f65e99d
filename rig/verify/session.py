"""`rig verify`: scan the artefacts at the guideline's positions, then compute PF, PS, SD and F.

A verification directory is also the record of the session that made it::

    REPORT/session.json             the placements, artefacts, volume and calibration (for --from)
    REPORT/captures/sphere-01/ ...  one capture per artefact position
    REPORT/report.json              the result (see rig.verify.results), rewritten by --from
    REPORT/report.md, figures/      the human report: table, residual maps, positions, history

Acquisition (:func:`acquire`) asks an :class:`~rig.verify.operator.Operator` to place each
artefact; on the simulated rig its world does it unattended. Computation (:func:`compute`) only
reads captures, so :func:`recompute` (``rig verify --from``) gives the figures again, with another
calibration or MPE. Everything reports progress through a :class:`rig.events.Reporter`, whose
cancel token stops the session between frames; a stopped or failed session leaves no report.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rig.errors import CaptureError, ConfigError, OutputError
from rig.store import files
from rig.verify import guideline
from rig.verify.artefacts import Artefacts, parse_artefacts
from rig.verify.guideline import Placement, Volume
from rig.verify.measure import ArtefactNotFound, PositionResult, measure
from rig.verify.plan import VerificationPlan
from rig.verify.results import Failed, Verification

if TYPE_CHECKING:
    from rig.config import RigConfig
    from rig.events import Reporter
    from rig.pipeline.plan import ProcessOptions
    from rig.verify.operator import Operator

SESSION_FILE = "session.json"
SESSION_FORMAT = "fpp-verification-session"
CAPTURES_DIR = "captures"
VERIFICATION_KINDS = ("verification",)


def volume_for(calibration_dir: Path, artefacts: Artefacts) -> Volume:
    """The measuring volume: the calibrated view up to the highest calibration plane (or ``[volume] depth_mm``)."""
    from calibration.store import read_calibration
    from rig.store.capture import read_capture

    cal = read_calibration(calibration_dir)
    if cal.pixel_mm is None or cal.reference is None:
        raise ConfigError(
            f"{calibration_dir}: the measuring volume needs a calibration with pixel_mm and a reference capture"
        )
    depth = artefacts.depth_mm
    if depth is None:
        session = Path(calibration_dir) / "session.json"
        heights = files.read_json(session, ConfigError, strict=False).get("heights_mm") if session.is_file() else None
        if not heights:
            raise ConfigError(
                f"{artefacts.source}: [volume] depth_mm: missing (the calibration records no plane heights)"
            )
        depth = float(max(heights))
    reference = read_capture(Path(calibration_dir) / cal.reference, verify=False)
    try:
        return guideline.volume_of_view(reference.width, reference.height, cal.pixel_mm, cal.l0_mm, depth)
    except ValueError as exc:
        raise ConfigError(f"{artefacts.source}: [volume] {exc}") from None


def placements(volume: Volume, artefacts: Artefacts, plan: VerificationPlan) -> list[Placement]:
    """Every artefact position of ``plan`` in ``volume``, in the order they are scanned."""
    try:
        spheres = guideline.sphere_placements(volume, artefacts.sphere_diameter_mm, plan.sphere_positions)
        bars = guideline.ball_bar_placements(
            volume, artefacts.ball_bar_length_mm, artefacts.ball_bar_sphere_diameter_mm
        )
        planes = guideline.plane_placements(volume, artefacts.plane_length_mm, artefacts.plane_width_mm)
    except ValueError as exc:
        raise ConfigError(f"{artefacts.source}: {exc}") from None
    bars = [_renumber(p, plan.ball_bar_positions) for p in bars[: plan.ball_bar_positions]]
    planes = [_renumber(p, plan.plane_positions) for p in planes[: plan.plane_positions]]
    return spheres + bars + planes


def _renumber(p: Placement, total: int) -> Placement:
    return Placement(p.kind, p.index, total, p.where, p.centres, p.along, p.across)


def _session_record(
    volume: Volume, artefacts: Artefacts, plan: VerificationPlan, spots: list[Placement], calibration_dir: Path
) -> dict[str, Any]:
    return {
        "format": SESSION_FORMAT,
        "version": 1,
        "calibration": str(calibration_dir),
        "volume": volume.as_dict(),
        "artefacts": artefacts.as_dict(),
        "plan_notes": plan.notes(),
        "placements": [p.as_dict() for p in spots],
    }


def acquire(
    config: RigConfig,
    plan: VerificationPlan,
    artefacts: Artefacts,
    calibration_dir: Path,
    directory: Path,
    operator: Operator | None = None,
    progress: Reporter | None = None,
) -> list[Placement]:
    """Scan every position of ``plan`` into ``directory/captures/`` and write ``session.json``.

    The rig is opened once. Before each scan ``operator`` (a person) and, on the simulated rig,
    its world put the artefact in place; a session with neither is refused.
    """
    from rig.acquisition.scan import scan_with
    from rig.hardware.assembly import artefact_world, open_rig

    volume = volume_for(calibration_dir, artefacts)
    spots = placements(volume, artefacts, plan)
    record = _session_record(volume, artefacts, plan, spots, calibration_dir)
    patterns = config.scan.patterns()
    if progress is not None:
        progress.begin(len(spots) * len(patterns), f"verify {directory}")
    with open_rig(config, scene="reference") as devices:
        hands = [h for h in (operator, artefact_world(devices, artefacts)) if h is not None]
        if not hands:
            raise ConfigError("verification needs an operator to place the artefacts")
        (directory / CAPTURES_DIR).mkdir(parents=True, exist_ok=True)
        (directory / SESSION_FILE).write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
        for spot in spots:
            if progress is not None:
                progress.message(spot.prompt().removesuffix(", press Enter "), step=spot.name)
                progress.check()
            for hand in hands:
                hand.place(spot)
            scan_with(devices, directory / CAPTURES_DIR / spot.name, patterns, scene=spot.name, progress=progress)
    return spots


def load_session(directory: Path) -> tuple[list[Placement], Artefacts, dict[str, Any]]:
    """The placements and artefacts a stored verification recorded."""
    path = Path(directory) / SESSION_FILE
    data = files.read_json(path, CaptureError, "missing (not a verification directory?)")
    if not isinstance(data, dict) or data.get("format") != SESSION_FORMAT:
        raise CaptureError(
            f"{path}: format: expected {SESSION_FORMAT!r}, found {data.get('format') if isinstance(data, dict) else data!r}"
        )
    try:
        spots = [Placement.from_dict(p) for p in data["placements"]]
        a = data["artefacts"]
        artefacts = parse_artefacts({k: a[k] for k in ("sphere", "ball_bar", "plane")}, f"{path} artefacts")
    except (KeyError, TypeError, ValueError) as exc:
        raise CaptureError(f"{path}: not a verification session: {exc}") from None
    return spots, artefacts, data


def stored_captures(directory: Path, spots: Sequence[Placement]) -> list[tuple[Placement, Path]]:
    """Each placement of a stored verification with its capture directory."""
    return [(spot, Path(directory) / CAPTURES_DIR / spot.name) for spot in spots]


def named_captures(directory: Path) -> list[tuple[Placement, Path]]:
    """Captures taken outside a verification session: ``DIR`` itself or its capture subdirectories,
    each named after the artefact it holds (``sphere...``, ``ball-bar...``, ``plane...``)."""
    directory = Path(directory)
    found = (
        [directory]
        if (directory / "capture.json").is_file()
        else sorted(p for p in directory.iterdir() if (p / "capture.json").is_file())
        if directory.is_dir()
        else []
    )
    if not found:
        raise CaptureError(f"{directory}: no session.json and no capture (capture.json) in it or below it")
    out = []
    for path in found:
        kind = next((k for k in sorted(guideline.KINDS, key=len, reverse=True) if path.name.startswith(k)), None)
        if kind is None:
            raise CaptureError(
                f"{path}: name: expected it to start with what the capture holds ({', '.join(guideline.KINDS)}), found {path.name!r}"
            )
        same = [p for p in found if p.name.startswith(kind)]
        index = same.index(path) + 1
        out.append((Placement(kind, index, len(same), f"capture {path.name}", ()), path))
    return out


def compute(
    captures: Sequence[tuple[Placement, Path]],
    calibration_dir: Path,
    artefacts: Artefacts,
    options: ProcessOptions | None = None,
    progress: Reporter | None = None,
) -> tuple[list[PositionResult], list[Failed]]:
    """Process each position's capture with ``calibration_dir`` and measure its artefact."""
    from rig import api

    results, failed = [], []
    if progress is not None:  # after an acquisition in the same session, these steps come on top of its frames
        progress.begin(progress.done + len(captures), f"compute {len(captures)} positions")
    for spot, capture in captures:
        result = api.process(capture, calibration=calibration_dir, options=options)
        try:
            if result.points is None:
                raise ArtefactNotFound("the calibration gives no point coordinates")
            results.append(measure(result.points, result.mask, spot, artefacts))
        except ArtefactNotFound as exc:
            failed.append(Failed(spot, str(exc)))
        if progress is not None:
            progress.step(spot.name)
    return results, failed


def verify(
    config: RigConfig,
    plan: VerificationPlan,
    artefacts: Artefacts,
    calibration_dir: Path,
    output: Path,
    operator: Operator | None = None,
    progress: Reporter | None = None,
    overwrite: bool = False,
) -> Verification:
    """:func:`acquire` and :func:`compute` into a staging sibling of ``output``, write the report, commit.

    ``output`` appears whole or not at all; the calibration's history gets a line once it has.
    """
    from rig.verify.report import finish

    output = Path(output)
    files.check_writable(output, VERIFICATION_KINDS, overwrite, OutputError)
    with files.staged_directory(output, VERIFICATION_KINDS, overwrite, OutputError) as staging:
        spots = acquire(config, plan, artefacts, calibration_dir, staging, operator, progress)
        results, failed = compute(stored_captures(staging, spots), calibration_dir, artefacts, plan.options, progress)
        volume = volume_for(calibration_dir, artefacts)
        verification = finish(staging, output, results, failed, plan, artefacts, volume, calibration_dir, CAPTURES_DIR)
    return _commit_history(verification, calibration_dir, output)


def recompute(
    from_dir: Path,
    calibration_dir: Path,
    plan: VerificationPlan,
    output: Path | None = None,
    progress: Reporter | None = None,
    overwrite: bool = False,
    artefacts: Artefacts | None = None,
) -> Verification:
    """The figures of stored captures (``rig verify --from``), written to ``output`` or in place.

    ``from_dir`` is a stored verification (its session.json says what each capture holds), or
    captures named after their artefact (:func:`named_captures`), which need ``artefacts``.
    ``artefacts`` given replaces the values a session recorded.
    """
    from rig.verify.report import finish, write_in_place

    from_dir = Path(from_dir)
    session = (from_dir / SESSION_FILE).is_file()
    if session:
        spots, recorded, record = load_session(from_dir)
        depth = float(record.get("volume", {}).get("depth_mm", 0)) or None
        chosen = artefacts or Artefacts(**{**recorded.__dict__, "source": str(from_dir / SESSION_FILE)})
        artefacts = Artefacts(**{**chosen.__dict__, "depth_mm": chosen.depth_mm or depth})
        captures = stored_captures(from_dir, spots)
    elif artefacts is None:
        raise ConfigError(f"{from_dir}: no session.json: give the artefacts' calibrated values (--artefacts)")
    else:
        captures = named_captures(from_dir)
    volume = volume_for(calibration_dir, artefacts)
    results, failed = compute(captures, calibration_dir, artefacts, plan.options, progress)
    if output is None or files.same_path(output, from_dir):
        where = CAPTURES_DIR if session else str(from_dir)  # a session's captures are under captures/
        verification = write_in_place(from_dir, results, failed, plan, artefacts, volume, calibration_dir, where)
        return _commit_history(verification, calibration_dir, from_dir)
    with files.staged_directory(output, VERIFICATION_KINDS, overwrite, OutputError) as staging:
        verification = finish(staging, output, results, failed, plan, artefacts, volume, calibration_dir, str(from_dir))
    return _commit_history(verification, calibration_dir, output)


def _commit_history(verification: Verification, calibration_dir: Path, output: Path) -> Verification:
    from rig.verify.history import append_history

    verification.directory = output
    append_history(calibration_dir, verification.report)
    return verification
