"""`rig calibrate`: acquire the calibration captures of a rig, then compute calibration.json from them.

A calibration directory is also the record of the session that made it::

    CAL/calibration.json          the result (capture-format.md), rewritten by --from
    CAL/session.json              what was asked: heights, target, model (for --from)
    CAL/reference/                the flat reference plane, with the scan's pattern set
    CAL/planes/plane-at-25mm/     the plane at each known height (scene label carries the height)
    CAL/board/plane/              a chessboard lying on the reference plane (pixel size on the plane)
    CAL/board/view-01/ ...        more board views, tilted (camera intrinsics and distortion); each
                                  under the projector's white, then its black (room light only), so
                                  that only the corners the projector lights are used
    CAL/gamma/                    flat levels 0 .. 1 (projector gamma); CAL/gamma-lut.npy its LUT
    CAL/stereo/pose-01/ ...       model "stereo": a board pose, white + fringes along x and y

Acquisition (:func:`acquire`) asks an :class:`Operator` to set up each step: on the simulated rig
nothing needs doing (the virtual scene follows the capture's label); on a real rig a console
prompt ("move the plane to 25 mm, press Enter") or a motorised-stage command does it.
Computation (:func:`compute`) only reads captures, so ``rig calibrate --from CAL`` reproduces a
calibration from stored data and tries another model on the same captures.
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace
from operator import methodcaller
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from calibration.camera import (
    MIN_CORNERS,
    BoardSpec,
    CameraCalibration,
    calibrate_camera,
    detect_board,
    lit_corners,
    undistort_map,
    undistort_pixels,
)
from calibration.errors import CalibrationError
from calibration.gamma import (
    compensate_phase,
    fit_gamma,
    inverse_lut,
    mean_response,
    ramp_patterns,
    ripple_table_from_plane,
)
from calibration.geometry import MIN_HEIGHTS, fit_f0, fit_l0_d0, lit_interior, pixel_mm_from_corners
from calibration.plane_axes import sensitivity_rad_per_mm
from calibration.polynomial import COEFFICIENTS_FILE, POLYNOMIAL, fit_polynomial
from calibration.reference import REFERENCE_DIR, check_same_patterns
from calibration.stereo import (
    STEREO,
    board_phase_view,
    calibrate_stereo,
    fit_plane,
    triangulate,
)
from calibration.store import REFERENCE_PLANE, Calibration, write_calibration
from rig.config import RigConfig
from rig.errors import CaptureError, ConfigError
from rig.store import files
from rig.store.capture import read_capture

if TYPE_CHECKING:
    from rig.calibrate.operator import Operator
    from rig.events import Reporter
    from rig.hardware.assembly import RigDevices

log = logging.getLogger(__name__)

SESSION_FILE = "session.json"
PLANES_DIR = "planes"
BOARD_DIR = "board"
GAMMA_DIR = "gamma"
GAMMA_LUT_FILE = "gamma-lut.npy"
STEREO_DIR = "stereo"
# Reference-plane ripple above which the calibration planes are compensated before the fit: a
# gamma ripple (0.2 rad for gamma 2.2 under 3 steps) reads as planes that are not flat; the few
# hundredths of a radian projector pixelation leaves do not move with the fringe phase alone, and
# compensating them would bias l0.
RIPPLE_COMPENSATION_RAD = 0.08
PLANE_LABEL = re.compile(r"plane-at-(-?\d+(?:\.\d+)?)mm")
MODELS = (REFERENCE_PLANE, POLYNOMIAL, STEREO)
# A board view: under the projector's white (the board image), then its black (room light alone):
# their difference shows where the projector lights the board, the only corners trusted.
BOARD_PATTERNS = [{"kind": "flat", "level": 1.0}, {"kind": "flat", "level": 0.0}]


def plane_label(height_mm: float) -> str:
    """Scene label of the plane at ``height_mm`` (``plane-at-25mm``; the simulated rig shows it)."""
    return f"plane-at-{height_mm:g}mm"


@dataclass
class CalibrationPlan:
    """What a calibration session measures and which model it fits."""

    heights_mm: tuple[float, ...] = (25.0, 50.0, 100.0, 150.0)
    model: str = REFERENCE_PLANE
    degree: int = 3
    board: BoardSpec | None = field(default_factory=BoardSpec)
    board_views: int = 6  # tilted views for intrinsics (0: pixel size only)
    pixel_mm: float | None = None  # given instead of measured with the board
    gamma_levels: int = 0  # flat levels of the gamma ramp (0: skip)
    flatness_tolerance_mm: float = 1.0

    def check(self) -> None:
        """Raise ConfigError naming the option when the plan cannot give a calibration of its model."""
        if self.model not in MODELS:
            raise ConfigError(f"--model: expected one of {', '.join(MODELS)}, found {self.model!r}")
        if self.model == STEREO:
            if self.board is None or self.board.kind != "chessboard":
                raise ConfigError("--model stereo: needs a chessboard (--board chessboard:COLSxROWS:SQUARE_MM)")
            if self.board_views < 3:
                raise ConfigError(
                    f"--model stereo: needs at least 3 board poses (--board-views), found {self.board_views}"
                )
            return
        heights = [float(h) for h in self.heights_mm]
        if len(heights) < MIN_HEIGHTS:
            raise ConfigError(f"--heights: need at least {MIN_HEIGHTS} plane heights, found {len(heights)}")
        if len(set(heights)) != len(heights) or any(h == 0 for h in heights):
            raise ConfigError(f"--heights: expected distinct non-zero heights, found {heights}")
        if self.board is None and self.pixel_mm is None:
            raise ConfigError("calibration needs the pixel size on the plane: a board (--board) or --pixel-mm")
        if self.gamma_levels and self.gamma_levels < 5:
            raise ConfigError(f"--gamma: expected at least 5 levels, found {self.gamma_levels}")

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data["heights_mm"] = list(self.heights_mm)
        data["board"] = None if self.board is None else {**asdict(self.board), "squares": list(self.board.squares)}
        return data

    @classmethod
    def from_json(cls, data: dict[str, Any], where: str) -> CalibrationPlan:
        try:
            board = data.get("board")
            plan = cls(
                heights_mm=tuple(float(h) for h in data.get("heights_mm", ())),
                model=str(data.get("model", REFERENCE_PLANE)),
                degree=int(data.get("degree", 3)),
                board=None if board is None else BoardSpec(**{**board, "squares": tuple(board["squares"])}),
                board_views=int(data.get("board_views", 0)),
                pixel_mm=data.get("pixel_mm"),
                gamma_levels=int(data.get("gamma_levels", 0)),
                flatness_tolerance_mm=float(data.get("flatness_tolerance_mm", 1.0)),
            )
        except (AttributeError, TypeError, ValueError, KeyError) as exc:
            raise CalibrationError(f"{where}: not a calibration session: {exc}") from None
        return plan

    @classmethod
    def load(cls, session: Path) -> CalibrationPlan:
        """The plan stored in a session directory's ``session.json``."""
        data = files.read_json(
            session, CalibrationError, "missing (not a calibration session directory?)", strict=False
        )
        return cls.from_json(data, str(session))


# --------------------------------------------------------------------------- acquisition


class _Acquisition:
    """One session's open rig, the hands that set up each scene, and where progress goes."""

    def __init__(self, devices: RigDevices, directory: Path, hands: list[Operator], progress: Reporter | None) -> None:
        self.devices = devices
        self.directory = directory
        self.hands = hands
        self.progress = progress

    def setup(self, step: str, action: Callable[[Operator], None]) -> None:
        """Tell the front-end which step comes, then have every operator set it up."""
        if self.progress is not None:
            self.progress.message(step, step=step)
        for hand in self.hands:
            action(hand)

    def capture(self, output: Path, patterns: Sequence[dict[str, Any]], scene: str) -> Path:
        from rig.acquisition.scan import scan_with

        return scan_with(self.devices, output, patterns, scene=scene, progress=self.progress).path


def _frames_planned(config: RigConfig, plan: CalibrationPlan) -> int:
    if plan.model == STEREO:
        return plan.board_views * len(stereo_patterns(config)) + len(config.scan.patterns())
    frames = plan.gamma_levels + len(config.scan.patterns()) * (1 + len(plan.heights_mm))
    return frames + (len(BOARD_PATTERNS) * (plan.board_views + 1) if plan.board is not None else 0)


# What `rig calibrate --overwrite` may replace: a calibration, or the session directory of one.
CALIBRATION_KINDS = ("calibration", "calibration-session")


def acquire(
    config: RigConfig,
    plan: CalibrationPlan,
    directory: Path,
    operator: Operator | None = None,
    progress: Reporter | None = None,
    overwrite: bool = False,
) -> None:
    """Capture everything ``plan`` needs as the session directory ``directory`` (see the module docstring).

    The rig is opened once for the session. Before each capture ``operator`` (a person, a stage)
    and, on the simulated rig, the simulated world set up the scene; a session with neither is
    refused. ``progress`` gets one step per frame and a message naming each step. The session is
    captured beside ``directory`` and committed as a whole (:func:`calibrate` also computes before
    the commit); ``overwrite`` replaces only a calibration or a session directory.
    """
    with _staged_session(Path(directory), overwrite) as staging:
        _acquire_into(config, plan, staging, Path(directory), operator, progress)


def calibrate(
    config: RigConfig,
    plan: CalibrationPlan,
    directory: Path,
    operator: Operator | None = None,
    progress: Reporter | None = None,
    overwrite: bool = False,
) -> CalibrationReport:
    """:func:`acquire` and :func:`compute` in a temporary sibling of ``directory``, then commit it.

    Whatever interrupts the session (an error, Stop, a kill), ``directory`` holds the complete
    old calibration or the complete new one: the old one is replaced by an atomic exchange only
    once the new calibration.json is written.
    """
    directory = Path(directory)
    with _staged_session(directory, overwrite) as staging:
        _acquire_into(config, plan, staging, directory, operator, progress)
        report = compute(staging, plan, progress=progress)
    report.calibration.path = directory
    return report


@contextlib.contextmanager
def _staged_session(directory: Path, overwrite: bool) -> Iterator[Path]:
    """A staging directory committed as ``directory`` on success (removed on any error)."""
    if directory.is_dir() and not directory.is_symlink() and not files.is_empty_directory(directory):
        if not overwrite:
            raise CaptureError(f"{directory}: already exists and is not empty; choose another -o or pass --overwrite")
        if files.kind_of(directory) not in CALIBRATION_KINDS:
            raise CaptureError(f"{directory}: not a calibration directory; --overwrite replaces only those")
    with files.staged_directory(directory, CALIBRATION_KINDS, overwrite, CaptureError) as staging:
        yield staging


def _acquire_into(
    config: RigConfig,
    plan: CalibrationPlan,
    staging: Path,
    directory: Path,
    operator: Operator | None,
    progress: Reporter | None,
) -> None:
    """The captures of :func:`acquire`, written into ``staging`` (which becomes ``directory``)."""
    from rig.hardware.assembly import open_rig, world_operator

    plan.check()
    if progress is not None:
        progress.begin(_frames_planned(config, plan), f"calibrate {directory}")
    with open_rig(config, scene="reference") as devices:
        world = world_operator(devices, plan.board)
        hands = [hand for hand in (operator, world) if hand is not None]
        if not hands:
            raise ConfigError("calibration needs an operator: a person at the console or --stage-command")
        (staging / SESSION_FILE).write_text(json.dumps(plan.to_json(), indent=2) + "\n", encoding="utf-8")
        session = _Acquisition(devices, staging, hands, progress)
        if plan.model == STEREO:
            _acquire_stereo(session, plan)
        else:
            _acquire_planes(session, plan)


def _acquire_planes(session: _Acquisition, plan: CalibrationPlan) -> None:
    directory, patterns = session.directory, session.devices.config.scan.patterns()
    if plan.gamma_levels:
        session.setup("gamma ramp on the bare reference plane", methodcaller("clear"))
        session.capture(directory / GAMMA_DIR, ramp_patterns(plan.gamma_levels), "gamma-ramp")
        lut = _gamma_from(directory / GAMMA_DIR)[1]
        np.save(directory / GAMMA_LUT_FILE, lut)
        session.devices.projector.set_gamma_lut(lut)  # every later capture goes through the new LUT
    if plan.board is not None:
        (directory / BOARD_DIR).mkdir(exist_ok=True)
        for index in range(plan.board_views + 1):
            on_plane = index == 0
            step = "board flat on the reference plane" if on_plane else f"board view {index} of {plan.board_views}"
            session.setup(step, methodcaller("board", index, on_plane))
            name, scene = ("plane", "board-on-reference") if on_plane else (f"view-{index:02d}", f"board-view-{index}")
            session.capture(directory / BOARD_DIR / name, BOARD_PATTERNS, scene)
    session.setup("reference plane", methodcaller("plane", 0.0))
    session.capture(directory / REFERENCE_DIR, patterns, "reference")
    (directory / PLANES_DIR).mkdir(exist_ok=True)
    for height in plan.heights_mm:
        label = plane_label(float(height))
        session.setup(f"plane at {float(height):g} mm", methodcaller("plane", float(height)))
        session.capture(directory / PLANES_DIR / label, patterns, label)


def stereo_patterns(config: RigConfig) -> list[dict[str, Any]]:
    """A stereo pose's patterns: white (the board image), then the scan's sinusoids along x and y."""
    along = [replace(config.scan, axis=axis, gray_bits=0).patterns() for axis in ("x", "y")]
    return [{"kind": "flat", "level": 1.0}, *along[0], *along[1]]


def _acquire_stereo(session: _Acquisition, plan: CalibrationPlan) -> None:
    config, directory = session.devices.config, session.directory
    if min(config.scan.frequencies) != 1:
        raise ConfigError("--model stereo: the scan frequencies must start at 1 (hierarchical unwrapping on the board)")
    (directory / STEREO_DIR).mkdir(exist_ok=True)
    for index in range(1, plan.board_views + 1):
        session.setup(f"board pose {index} of {plan.board_views}", methodcaller("pose", index))
        session.capture(directory / STEREO_DIR / f"pose-{index:02d}", stereo_patterns(config), f"board-pose-{index}")
    session.setup("reference plane", methodcaller("plane", 0.0))
    session.capture(directory / REFERENCE_DIR, config.scan.patterns(), "reference")


# --------------------------------------------------------------------------- computation


@dataclass
class CalibrationReport:
    """What :func:`compute` found, for the summary printed by the command."""

    calibration: Calibration
    lines: list[str]


def _absolute_phase(path: Path, axis: str | None = None) -> tuple[np.ndarray, float, str, list[dict[str, Any]]]:
    """Absolute phase (NaN invalid), its frequency, fringe axis (``axis``; default the first captured)
    and the patterns of a capture."""
    from rig.api import ProcessOptions, process

    result = process(path, options=ProcessOptions(correction="none", axis=axis))  # the fits see the measured phase
    unwrapped = result.object.unwrapped
    if unwrapped is None or not unwrapped.absolute:
        raise CalibrationError(
            f"{path}: the pattern set gives no absolute phase (spatial unwrapping); calibrate with temporal unwrapping patterns"
        )
    phase = np.where(result.mask, unwrapped.phase, np.nan)
    return phase, float(unwrapped.frequency), result.object.axis, result.object.capture.patterns


def _gamma_from(directory: Path) -> tuple[Any, np.ndarray]:
    capture = read_capture(directory)
    levels = [float(p.get("level", np.nan)) for p in capture.patterns]
    if any(p.get("kind") != "flat" for p in capture.patterns):
        raise CalibrationError(f"{capture.manifest_path}: the gamma ramp must hold flat patterns only")
    frames = capture.load_frames()
    fit = fit_gamma(levels, mean_response(frames), saturation=float((1 << capture.bit_depth) - 1))
    return fit, inverse_lut(fit)


@dataclass
class BoardView:
    """One stored board view: the image under the projector's white, and under its black (None
    in sessions stored without it: the white frame alone then shows where the projector lights)."""

    white: np.ndarray
    dark: np.ndarray | None


def _board_view(path: Path) -> BoardView:
    capture = read_capture(path)
    levels = [float(p.get("level", np.nan)) if p.get("kind") == "flat" else np.nan for p in capture.patterns]
    if 1.0 not in levels:
        raise CalibrationError(f"{capture.manifest_path}: a board view needs a white frame (flat level 1.0)")
    dark = capture.load_frame(levels.index(0.0)) if 0.0 in levels else None
    return BoardView(capture.load_frame(levels.index(1.0)), dark)


def _board_images(directory: Path) -> tuple[BoardView | None, list[BoardView]]:
    """The board lying on the plane (or None) and the tilted views, from ``directory``'s captures."""
    on_plane = None
    views = []
    if not directory.is_dir():
        return None, []
    for sub in sorted(p for p in directory.iterdir() if (p / "capture.json").is_file()):
        view = _board_view(sub)
        if sub.name == "plane":
            on_plane = view
        else:
            views.append(view)
    return on_plane, views


def _board_note(note: str, first: int) -> str:
    """A camera calibration note with its view index replaced by the stored view's name."""
    match = re.match(r"view (\d+): ", note)
    if not match:
        return note
    index = int(match.group(1)) + first
    name = "board on the plane" if index == 0 else f"board view {index}"
    return name + note[match.end() - 2 :]


def _planes(directory: Path) -> list[tuple[float, Path]]:
    planes_dir = directory / PLANES_DIR
    if not planes_dir.is_dir():
        raise CalibrationError(f"{planes_dir}: missing (the plane captures at known heights)")
    found = []
    for sub in sorted(p for p in planes_dir.iterdir() if p.is_dir()):
        scene = read_capture(sub, verify=False).scene
        match = PLANE_LABEL.fullmatch(scene)
        if not match:
            raise CalibrationError(f"{sub / 'capture.json'}: scene {scene!r}: expected 'plane-at-<height>mm'")
        found.append((float(match.group(1)), sub))
    return sorted(found)


def _copy_capture(source: Path, target: Path) -> None:
    """Copy a capture directory, verified when the calibration was computed, atomically (an earlier
    capture at ``target`` is replaced)."""
    import shutil

    with files.staged_directory(target, ("capture",), True, CaptureError) as staging:
        shutil.copytree(source, staging, dirs_exist_ok=True)


@dataclass
class ComputedCalibration:
    """A calibration computed from a session's captures and not yet written: calibration.json's
    content, the summary lines, the arrays saved beside it and the reference capture it carries."""

    calibration: Calibration
    lines: list[str]
    source: Path  # the session directory
    arrays: dict[str, np.ndarray] = field(default_factory=dict)  # file name -> array, saved beside calibration.json
    reference: Path | None = (
        None  # verified; copied into an output other than ``source`` (references are relative, inside)
    )

    def write(self, output: Path) -> CalibrationReport:
        """Write it all into ``output`` (calibration.json last) and return the summary."""
        if self.arrays:
            output.mkdir(parents=True, exist_ok=True)
        for name, array in self.arrays.items():
            np.save(output / name, array)
        if self.reference is not None and not files.same_path(output, self.source):
            _copy_capture(self.reference, output / REFERENCE_DIR)
        write_calibration(output, self.calibration)
        return CalibrationReport(self.calibration, self.lines)


def compute(
    directory: Path,
    plan: CalibrationPlan | None = None,
    output: Path | None = None,
    progress: Reporter | None = None,
) -> CalibrationReport:
    """Compute and write ``calibration.json`` from the captures in ``directory``.

    ``plan`` overrides the stored session (e.g. another model); ``output`` writes the calibration
    elsewhere (the reference capture is then copied into it: references are relative and inside).
    """
    return compute_calibration(directory, plan, progress).write(output or directory)


def compute_calibration(
    directory: Path, plan: CalibrationPlan | None = None, progress: Reporter | None = None
) -> ComputedCalibration:
    """The calibration the captures in ``directory`` give, computed without writing anything (so
    that a command writing it elsewhere creates its output only once there is something to write)."""

    def note(message: str) -> None:
        if progress is not None:
            progress.message(message)

    if plan is None:
        plan = CalibrationPlan.load(directory / SESSION_FILE)
    computed = ComputedCalibration(Calibration(model=plan.model), [], directory)
    if (directory / GAMMA_DIR).is_dir():
        _projector_gamma(directory, computed)
    if plan.model == STEREO:
        _compute_stereo(directory, plan, computed, note)
        return computed
    camera, pixel_mm = _camera_and_pixel_size(directory, plan, computed)
    fit, f0, frequency, axis, heights, deltas = _fit_planes(directory, plan, camera, pixel_mm, computed, note)
    extra = computed.calibration.extra
    computed.lines.append(
        f"l0 = {fit.l0_mm:.3f} +- {fit.l0_std_mm:.3f} mm, d0 = {fit.d0_mm:.3f} +- {fit.d0_std_mm:.3f} mm"
    )
    computed.lines.append(
        "residuals " + ", ".join(f"{h:g}: {r:+.4f}" for h, r in zip(fit.heights_mm, fit.residuals_mm)) + " mm"
    )
    extra.update({k: v for k, v in fit.as_fields().items() if k not in ("l0_mm", "d0_mm", "f0_per_mm")})
    extra["uncertainty"]["f0_per_mm"] = f0.f0_std_per_mm
    extra["fringe_axis"] = axis
    if plan.model == REFERENCE_PLANE:
        first = {"l0_mm": fit.l0_mm, "d0_mm": fit.d0_mm, "f0_per_mm": f0.f0_per_mm, "f0_frequency": frequency}
        _fit_other_axis(directory, plan, camera, pixel_mm, computed, note, axis, first)
    if plan.model == POLYNOMIAL:
        poly = fit_polynomial(heights, deltas, frequency, degree=plan.degree)
        computed.arrays[COEFFICIENTS_FILE] = poly.coefficients
        extra.update({k: v for k, v in poly.fields(COEFFICIENTS_FILE).items() if k != "model"})
        computed.lines.append(f"polynomial degree {plan.degree}: residual RMS {poly.residual_rms_mm:.4f} mm")
    read_capture(directory / REFERENCE_DIR)  # only a complete, verified capture is copied into another output
    computed.reference = directory / REFERENCE_DIR
    computed.calibration = Calibration(
        model=plan.model,
        l0_mm=fit.l0_mm,
        d0_mm=fit.d0_mm,
        f0_per_mm=f0.f0_per_mm,
        f0_frequency=frequency,
        pixel_mm=pixel_mm,
        reference=REFERENCE_DIR,
        extra=extra,
    )
    return computed


def _projector_gamma(directory: Path, computed: ComputedCalibration) -> None:
    """The projector's gamma from the session's gray levels: its fields, and the LUT saved beside."""
    gamma, lut = _gamma_from(directory / GAMMA_DIR)
    computed.arrays[GAMMA_LUT_FILE] = lut
    computed.calibration.extra["gamma"] = gamma.as_fields()
    computed.calibration.extra["gamma_lut"] = GAMMA_LUT_FILE
    computed.lines.append(
        f"projector gamma {gamma.gamma:.3f} (fit RMS {gamma.residual_rms:.2f} DN); LUT {GAMMA_LUT_FILE}"
    )


def _camera_and_pixel_size(
    directory: Path, plan: CalibrationPlan, computed: ComputedCalibration
) -> tuple[CameraCalibration | None, float]:
    """The camera (from the board views, when there are at least two) and the pixel size on the plane."""
    camera: CameraCalibration | None = None
    pixel_mm = plan.pixel_mm
    if plan.board is not None:
        on_plane, views = _board_images(directory / BOARD_DIR)
        if len(views) >= 2:
            camera = _camera_from_board(plan.board, on_plane, views, computed)
        if pixel_mm is None:
            pixel_mm = _pixel_mm_on_plane(directory, plan.board, on_plane, camera, computed)
    if pixel_mm is None:
        raise CalibrationError("pixel size: no board on the plane and no --pixel-mm")
    return camera, pixel_mm


def _camera_from_board(
    board: BoardSpec, on_plane: Any, views: list[Any], computed: ComputedCalibration
) -> CameraCalibration:
    """The camera's intrinsics from the board on the plane (if any) and the board views."""
    all_views = ([on_plane] if on_plane is not None else []) + views
    # k3 stays 0: a few views of a narrow-angle lens cannot tell it from k1, k2
    camera = calibrate_camera(
        [v.white for v in all_views], board, flags=cv2.CALIB_FIX_K3, darks=[v.dark for v in all_views]
    )
    computed.calibration.extra.update(camera.as_fields())
    computed.lines.append(
        f"camera: {len(camera.views_used)} views, reprojection RMS {camera.rms_px:.3f} px"
        + ("" if camera.distortion_significant else ", no significant lens distortion")
    )
    first = 0 if on_plane is not None else 1  # calibrate_camera's view 0 is the board on the plane
    computed.lines.extend("  " + _board_note(note, first) for note in camera.notes)
    return camera


def _pixel_mm_on_plane(
    directory: Path, board: BoardSpec, on_plane: Any, camera: CameraCalibration | None, computed: ComputedCalibration
) -> float:
    """The pixel size on the reference plane, from the chessboard lying on it (its lit corners)."""
    where = directory / BOARD_DIR / "plane"
    if on_plane is None:
        raise CalibrationError(f"{where}: missing (the board lying on the reference plane)")
    if board.kind != "chessboard":
        raise CalibrationError("pixel size: measure it with a chessboard (or give --pixel-mm)")
    found = detect_board(on_plane.white, board, name="board on the reference plane")
    if found is None:
        raise CalibrationError(f"{where}: the {board.kind} was not found")
    lit = lit_corners(found, on_plane.white, on_plane.dark)
    if lit.sum() < MIN_CORNERS:
        raise CalibrationError(
            f"{where}: {int(lit.sum())} of {lit.size} board corners lit by the projector, "
            f"need {MIN_CORNERS}; lay the board inside the projected area"
        )
    corners = found.image_points
    if camera is not None and camera.distortion_significant:
        corners = undistort_pixels(corners, camera.camera_matrix, camera.distortion)
    pixel_mm = pixel_mm_from_corners(corners, board.inner_corners, board.square_mm, keep=lit)
    used = "" if lit.all() else f", {int(lit.sum())} of {lit.size} corners lit by the projector"
    computed.lines.append(f"pixel size on the plane {pixel_mm:.5f} mm (from the {board.kind}{used})")
    return pixel_mm


def _fit_other_axis(
    directory: Path,
    plan: CalibrationPlan,
    camera: CameraCalibration | None,
    pixel_mm: float,
    computed: ComputedCalibration,
    note: Callable[[str], None],
    axis: str,
    numbers: dict[str, float],
) -> None:
    """With fringes on both axes in the captures, the other axis's own l0, d0, f0 (``axes``, see
    calibration.plane_axes): each axis sees its own share of the baseline, and `rig process` takes the
    more sensitive one. A fit that fails (a baseline with no share along that axis) leaves one axis."""
    other = "y" if axis == "x" else "x"
    patterns = read_capture(directory / REFERENCE_DIR, verify=False).patterns
    if not any(p.get("kind") == "sinusoid" and p.get("axis", "x") == other for p in patterns):
        return
    scratch = ComputedCalibration(Calibration(model=plan.model), [], directory)  # its ripple table is not kept
    try:
        fit, f0, frequency, _, _, _ = _fit_planes(directory, plan, camera, pixel_mm, scratch, note, axis=other)
    except CalibrationError as exc:
        computed.lines.append(f"fringes along {other}: not fitted ({exc}); processing converts {axis} only")
        return
    theirs = {"l0_mm": fit.l0_mm, "d0_mm": fit.d0_mm, "f0_per_mm": f0.f0_per_mm, "f0_frequency": frequency}
    computed.calibration.extra["axes"] = {axis: numbers, other: theirs}
    per_mm = {name: sensitivity_rad_per_mm(n, n["f0_frequency"]) for name, n in ((axis, numbers), (other, theirs))}
    computed.lines.append(
        f"fringes along {other}: l0 = {fit.l0_mm:.3f} mm, d0 = {fit.d0_mm:.3f} mm; sensitivity 2 pi f0 |d0| / l0 "
        f"{per_mm[axis]:.3g} rad/mm along {axis}, {per_mm[other]:.3g} along {other} (at each axis's fitted "
        "frequency): rig process takes the larger by default"
    )


def _fit_planes(
    directory: Path,
    plan: CalibrationPlan,
    camera: CameraCalibration | None,
    pixel_mm: float,
    computed: ComputedCalibration,
    note: Callable[[str], None],
    axis: str | None = None,
) -> tuple[Any, Any, float, str, list[float], list[np.ndarray]]:
    """f0 on the reference plane, then l0 and d0 from the planes' phase differences to it, along ``axis``
    (default the first axis captured).

    Returns the l0/d0 fit, the f0 fit, the fringe frequency and axis, the heights and the phase differences.
    """
    # `rig process` undistorts the frames of scans and reference alike: fit on the same geometry
    undistort = camera is not None and camera.distortion_significant

    def phase_of(path: Path) -> tuple[np.ndarray, float, str, list[dict[str, Any]]]:
        phase, frequency, fitted_axis, patterns = _absolute_phase(path, axis)
        phase = lit_interior(phase)  # fits use lit, modulated pixels only: not the footprint's partly lit edge
        if undistort:
            assert camera is not None
            phase = undistort_map(phase, camera.camera_matrix, camera.distortion)
        return phase, frequency, fitted_axis, patterns

    note("calibrate: reference plane" + (f" (fringes along {axis})" if axis else ""))
    reference, frequency, fitted_axis, patterns = phase_of(directory / REFERENCE_DIR)
    planes = _planes(directory)
    if len(planes) < MIN_HEIGHTS:
        raise CalibrationError(
            f"{directory / PLANES_DIR}: {len(planes)} plane captures, need at least {MIN_HEIGHTS} heights"
        )
    f0 = fit_f0(reference, pixel_mm)
    table, compensate = _ripple(reference, frequency, computed)
    if compensate:
        reference = compensate_phase(reference, table)
    heights, deltas = [], []
    for height, path in planes:
        note(f"calibrate: plane at {height:g} mm")
        phase, _, _, plane_patterns = phase_of(path)  # same patterns, so the same frequency and axis
        check_same_patterns(patterns, plane_patterns, f"{directory / REFERENCE_DIR}", f"{path}")
        heights.append(height)
        deltas.append((compensate_phase(phase, table) if compensate else phase) - reference)
    fit = fit_l0_d0(
        heights,
        deltas,
        f0.f0_per_mm,
        f0_std_per_mm=f0.f0_std_per_mm,
        flatness_tolerance_mm=plan.flatness_tolerance_mm if plan.model == REFERENCE_PLANE else None,
    )
    return fit, f0, frequency, fitted_axis, heights, deltas


def _ripple(reference: np.ndarray, frequency: float, computed: ComputedCalibration) -> tuple[Any, bool]:
    """The reference plane's phase ripple (projector gamma), for `rig process --correction gamma-table`,
    and whether it is strong enough to be taken out of the calibration planes too (or it would read
    as planes not flat)."""
    table, ripple_rms = ripple_table_from_plane(reference)
    extra = computed.calibration.extra
    extra["phase_error"] = {**table.as_fields(), "frequency": frequency, "ripple_rms_rad": ripple_rms}
    computed.lines.append(
        f"phase ripple on the reference plane {ripple_rms:.4f} rad RMS (table for --correction gamma-table)"
    )
    compensate = ripple_rms > RIPPLE_COMPENSATION_RAD
    if compensate:
        extra["planes_ripple_compensated"] = True
        computed.lines.append(
            "  strong ripple: the planes were fitted with it compensated; pre-correct the projector (--gamma) or process with --correction gamma-table"
        )
    return table, compensate


def _pose_view(path: Path, board: BoardSpec) -> Any:
    """Board corners and projector phases of one stored stereo pose."""
    capture = read_capture(path)
    patterns = capture.patterns
    white = [i for i, p in enumerate(patterns) if p.get("kind") == "flat" and float(p.get("level", 0)) == 1.0]
    groups = {
        axis: [i for i, p in enumerate(patterns) if p.get("kind") == "sinusoid" and p.get("axis", "x") == axis]
        for axis in ("x", "y")
    }
    if not white or not groups["x"] or not groups["y"]:
        raise CalibrationError(
            f"{capture.manifest_path}: a stereo pose needs a white frame and sinusoids along x and y"
        )
    frames = capture.load_frames()
    frequencies = sorted({int(patterns[i]["frequency"]) for i in groups["x"]})
    steps = int(patterns[groups["x"][0]]["steps"])
    if frequencies[0] != 1 or len(groups["x"]) != steps * len(frequencies) or len(groups["y"]) != len(groups["x"]):
        raise CalibrationError(
            f"{capture.manifest_path}: stereo poses need the same {steps}-step sinusoids along x and y at frequencies starting at 1"
        )
    view = board_phase_view(frames[white[0]], board, frames[groups["x"]], frames[groups["y"]], frequencies, steps)
    if view is None:
        raise CalibrationError(f"{capture.manifest_path}: the {board.kind} was not found in the white frame")
    return view, capture


def _compute_stereo(
    directory: Path, plan: CalibrationPlan, computed: ComputedCalibration, note: Callable[[str], None]
) -> None:
    """A camera-projector model from the stored board poses, and the reference plane's pose when stored."""
    poses = sorted(p for p in (directory / STEREO_DIR).glob("pose-*") if (p / "capture.json").is_file())
    if len(poses) < 3:
        raise CalibrationError(f"{directory / STEREO_DIR}: {len(poses)} board poses, need at least 3")
    assert plan.board is not None
    views = []
    for path in poses:
        note(f"calibrate: {path.name}")
        view, capture = _pose_view(path, plan.board)
        views.append(view)
    camera_size = (capture.width, capture.height)
    projector_size = tuple(int(v) for v in capture.projector_size)
    result = calibrate_stereo(views, camera_size, projector_size, flags=cv2.CALIB_FIX_K3)  # type: ignore[arg-type]
    fields = result.model.as_fields()
    lines, extra = computed.lines, computed.calibration.extra
    lines.append(
        f"stereo: {result.views_used} poses, reprojection RMS {result.rms_px:.3f} px (camera {result.camera_rms_px:.3f}, "
        f"projector {result.projector_rms_px:.3f}), baseline {result.model.baseline_mm:.2f} mm"
    )
    extra.update(fields)
    extra["reprojection_rms_px"] = result.rms_px
    if (directory / REFERENCE_DIR / "capture.json").is_file():
        note("calibrate: reference plane")
        phase, frequency, axis, _ = _absolute_phase(directory / REFERENCE_DIR)
        points = triangulate(result.model, phase, frequency, axis=axis)
        plane = fit_plane(points)
        extra["plane"] = plane.tolist()
        heights = points @ plane[:3] + plane[3]
        lines.append(
            f"reference plane {plane[3]:.2f} mm from the camera, flat to {np.nanstd(heights):.3f} mm RMS: heights are above it"
        )
    computed.calibration = Calibration(model=STEREO, extra=extra)
