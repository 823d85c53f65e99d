"""Offline synthesis of a scan: object capture, reference-plane capture and their calibration.

Builds on :mod:`mock_devices.synth` (rig geometry, camera-to-projector map, rendering) and
:mod:`mock_devices.scenes` (height maps). The result is exactly what a real rig would leave on
disk after ``rig calibrate`` and ``rig scan``, plus the true height map, so that ``rig demo``,
the tests and ``rig simulate`` can check processed heights against the truth. The reproduction study
(:mod:`rig.study.experiments`) renders its scenes with :func:`render_scene` and the names
re-exported below, so that only ``rig/hardware`` reaches into ``mock_devices``.

On disk (:func:`write_simulated_scan`)::

    OUT/object/capture.json ...            the scan of the scene
    OUT/calibration/calibration.json       reference-plane model with the true l0, d0, f0, pixel_mm
    OUT/calibration/reference/...          the flat reference plane, same patterns
    OUT/truth-height.npy                   the scene's heights (mm), float32
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from calibration.store import Calibration, write_calibration
from mock_devices import scenes, synth
from rig.store.capture import write_capture
from rig.store.exposures import with_exposures

DEFAULT_FREQUENCIES = (1, 8, 64)
DEFAULT_STEPS = 4

# The simulation's rig geometry, photometry and truth, for callers outside rig/hardware.
RigGeometry = synth.RigGeometry
Appearance = synth.Appearance
ProjectorMap = synth.ProjectorMap
sinusoid_patterns = synth.sinusoid_patterns
true_absolute_phase = synth.true_absolute_phase


def scene_height(name: str, geometry: synth.RigGeometry, **params: float) -> np.ndarray:
    """Height map (mm) of a named scene of :data:`mock_devices.scenes.SCENES` seen by ``geometry``'s camera."""
    return scenes.make_scene(name, geometry.camera_height, geometry.camera_width, geometry.pixel_mm, **params)


def scene_reflectance(
    name: str, height_mm: np.ndarray, geometry: synth.RigGeometry, variant: int = 0
) -> np.ndarray | None:
    """Reflectance map of a named scene (its ``variant``) under ``geometry`` (None: uniformly matte)."""
    return scenes.scene_reflectance(name, height_mm, geometry.pixel_mm, geometry.l0_mm, geometry.d0_mm, variant)


def render_exposures(
    height_mm: np.ndarray,
    geometry: synth.RigGeometry,
    patterns: Sequence[Mapping[str, Any]],
    appearance: synth.Appearance,
    exposures_us: Sequence[float],
    rng: np.random.Generator,
    reference_exposure_us: float = 10_000.0,
) -> tuple[np.ndarray, synth.ProjectorMap]:
    """Frames (E * N, H, W) of each exposure's full sequence in turn (the capture order of
    :func:`rig.store.exposures.with_exposures`); the signal scales with exposure / ``reference_exposure_us``."""
    mapping = synth.projector_coordinates(np.asarray(height_mm, dtype=np.float64), geometry)
    stacks = [
        synth.render_stack(
            patterns, mapping, geometry, replace(appearance, gain=appearance.gain * e / reference_exposure_us), rng
        )
        for e in exposures_us
    ]
    return np.concatenate(stacks), mapping


def render_scene(
    height_mm: np.ndarray,
    geometry: synth.RigGeometry,
    patterns: Sequence[Mapping[str, Any]],
    appearance: synth.Appearance,
    rng: np.random.Generator,
) -> tuple[np.ndarray, synth.ProjectorMap]:
    """Frames (N, H, W) of one scene under a pattern sequence, noise drawn from ``rng``, and its projector map.

    Scenes rendered one after another from the same ``rng`` (an object, then its reference plane)
    draw their noise in that order, as :func:`simulate_scan` does.
    """
    mapping = synth.projector_coordinates(np.asarray(height_mm, dtype=np.float64), geometry)
    return synth.render_stack(patterns, mapping, geometry, appearance, rng), mapping


def demo_appearance(snr_db: float | None = 35.0) -> synth.Appearance:
    """How the demo's simulated camera sees the scene: ambient 0.1, gain 200, noise at ``snr_db``."""
    return synth.Appearance(ambient=0.1, gain=200.0, snr_db=snr_db)


def demo_geometry(width: int = 640, height: int = 480) -> synth.RigGeometry:
    """The synthesiser's default rig with a ``width`` x ``height`` camera and the same field of view."""
    base = synth.RigGeometry()
    pixel_mm = base.pixel_mm * base.camera_width / width
    return synth.RigGeometry(
        l0_mm=base.l0_mm,
        d0_mm=base.d0_mm,
        f0_per_mm=base.f0_per_mm,
        f0_frequency=base.f0_frequency,
        pixel_mm=pixel_mm,
        camera_width=width,
        camera_height=height,
        projector_width=base.projector_width,
        projector_height=base.projector_height,
    )


def exact_calibration(
    geometry: synth.RigGeometry,
    reference: str = "reference",
    extra: dict[str, Any] | None = None,
    axes: Sequence[str] = (),
) -> Calibration:
    """The reference-plane calibration that ``geometry`` is exactly (what `rig calibrate` estimates).

    ``axes``: the fringe axes it was fitted on, each with its own share of the baseline and its
    fringe frequency on the plane (calibration.plane_axes), the first one's at the top level and
    as ``fringe_axis``; none (the default): the x axis's numbers, naming no axis.
    """
    numbers = {
        axis: {
            "l0_mm": geometry.l0_mm,
            "d0_mm": geometry.baseline_share(axis),
            "f0_per_mm": geometry.per_mm_along(axis, geometry.f0_frequency),
            "f0_frequency": float(geometry.f0_frequency),
        }
        for axis in axes
    }
    fields = dict(extra or {})
    if numbers:
        fields.update({"fringe_axis": axes[0], "axes": numbers})
    top = numbers[axes[0]] if numbers else {"d0_mm": geometry.d0_mm, "f0_per_mm": geometry.f0_per_mm}
    return Calibration(
        l0_mm=geometry.l0_mm,
        d0_mm=top["d0_mm"],
        f0_per_mm=top["f0_per_mm"],
        f0_frequency=float(geometry.f0_frequency),
        pixel_mm=geometry.pixel_mm,
        reference=reference,
        extra=fields,
    )


@dataclass
class SimulatedScan:
    """Frames of an object and of the reference plane under the same patterns, with the truth."""

    geometry: synth.RigGeometry
    patterns: list[dict[str, Any]]  # the base sequence (the reference plane's)
    height_mm: np.ndarray  # (H, W) true scene heights
    object_frames: np.ndarray  # (N, H, W)
    reference_frames: np.ndarray  # (N, H, W)
    object_map: synth.ProjectorMap
    reference_map: synth.ProjectorMap
    description: dict[str, Any] = field(default_factory=dict)
    object_patterns: list[dict[str, Any]] | None = None  # the object's, when taken at several exposures
    calibrated_axes: tuple[str, ...] = ()  # exact_calibration's axes (none: the x axis, naming none)

    @property
    def lit(self) -> np.ndarray:
        """Pixels the projector reaches in both the object and the reference scene."""
        return self.object_map.lit & self.reference_map.lit

    def calibration(self, reference: str = "reference") -> Calibration:
        """The exact calibration of the simulated rig (reference-plane model)."""
        return exact_calibration(
            self.geometry, reference, extra={"simulation": dict(self.description)}, axes=self.calibrated_axes
        )


def simulate_scan(
    scene: str | np.ndarray = "hemisphere",
    geometry: synth.RigGeometry | None = None,
    patterns: Sequence[Mapping[str, Any]] | None = None,
    appearance: synth.Appearance | None = None,
    seed: int | None = 0,
    scene_params: Mapping[str, float] | None = None,
    exposures_us: Sequence[float] | None = None,
    reference_exposure_us: float = 10_000.0,
) -> SimulatedScan:
    """Render a scene and the flat reference plane under a pattern sequence.

    Parameters
    ----------
    scene : str or (H, W) array
        A name from :data:`mock_devices.scenes.SCENES` or a height map in mm.
    geometry : RigGeometry, optional
        Default :func:`demo_geometry` (640 x 480 camera).
    patterns : list of capture-format pattern dicts, optional
        Default 4-step sinusoids at frequencies 1, 8, 64 along x.
    appearance : Appearance, optional
        Photometry and noise; default a little ambient light and 35 dB SNR, 8-bit.
    seed : int or None
        Seed of the noise generator (reproducible by default).
    scene_params : mapping, optional
        Extra parameters of the named scene.
    exposures_us : sequence of float, optional
        Several exposures: the object is captured at each (each exposure's full sequence in turn,
        patterns tagged with their exposure), the reference plane once at ``reference_exposure_us``,
        the exposure at which ``appearance.gain`` holds. A named scene with a reflectance map
        (``shiny-and-dark``) is rendered with it.
    """
    geometry = demo_geometry() if geometry is None else geometry
    pattern_list: list[dict[str, Any]] = [
        dict(p) for p in (patterns or synth.sinusoid_patterns(DEFAULT_FREQUENCIES, DEFAULT_STEPS))
    ]
    appearance = demo_appearance() if appearance is None else appearance
    if isinstance(scene, str):
        name = scene
        height = scene_height(scene, geometry, **(scene_params or {}))
    else:
        name = "custom"
        height = np.asarray(scene, dtype=np.float64)
    variant = int((scene_params or {}).get("variant", 0))
    reflectance = scene_reflectance(name, height, geometry, variant) if isinstance(scene, str) else None
    seen = appearance if reflectance is None else replace(appearance, reflectivity=reflectance)
    rng = np.random.default_rng(seed)
    if exposures_us is not None and len(exposures_us) > 1:
        object_frames, object_map = render_exposures(
            height, geometry, pattern_list, seen, exposures_us, rng, reference_exposure_us
        )
        object_patterns = with_exposures(pattern_list, exposures_us)
    else:
        exposure = reference_exposure_us if not exposures_us else float(exposures_us[0])
        seen = replace(seen, gain=seen.gain * exposure / reference_exposure_us)
        object_frames, object_map = render_scene(height, geometry, pattern_list, seen, rng)
        object_patterns = pattern_list
    reference_frames, reference_map = render_scene(np.zeros_like(height), geometry, pattern_list, appearance, rng)
    description: dict[str, Any] = {
        "scene": name,
        "scene_params": dict(scene_params or {}),
        "seed": seed,
        "snr_db": appearance.snr_db,
        "max_height_mm": float(np.max(height)),
    }
    if exposures_us is not None:
        description["exposures_us"] = [float(e) for e in exposures_us]
    return SimulatedScan(
        geometry=geometry,
        patterns=pattern_list,
        object_patterns=object_patterns,
        height_mm=height,
        object_frames=object_frames,
        reference_frames=reference_frames,
        object_map=object_map,
        reference_map=reference_map,
        description=description,
    )


@dataclass
class SimulatedPaths:
    """Where :func:`write_simulated_scan` put things."""

    root: Path
    capture: Path
    calibration: Path
    reference: Path
    truth: Path


def simulated_paths(out: str | os.PathLike[str]) -> SimulatedPaths:
    """Where :func:`write_simulated_scan` puts things under ``out``."""
    root = Path(out)
    return SimulatedPaths(
        root=root,
        capture=root / "object",
        calibration=root / "calibration",
        reference=root / "calibration" / "reference",
        truth=root / "truth-height.npy",
    )


def write_simulated_scan(scan: SimulatedScan, out: str | os.PathLike[str]) -> SimulatedPaths:
    """Write the object capture, the calibration with its reference capture, and the true heights."""
    paths = simulated_paths(out)
    root = paths.root
    g = scan.geometry
    projector = {"width": g.projector_width, "height": g.projector_height}
    extra = {"simulation": dict(scan.description)}
    object_patterns = scan.object_patterns or scan.patterns
    write_capture(paths.capture, scan.object_frames, object_patterns, projector, scene="object", extra=extra)
    write_capture(paths.reference, scan.reference_frames, scan.patterns, projector, scene="reference", extra=extra)
    write_calibration(paths.calibration, scan.calibration(reference="reference"))
    root.mkdir(parents=True, exist_ok=True)
    np.save(paths.truth, scan.height_mm.astype(np.float32))
    return paths


ARCHIVE_SCENES = ("hemisphere", "sphere-cap", "two-hemispheres", "steps")


def write_simulated_archive(
    out: str | os.PathLike[str],
    count: int,
    width: int = 64,
    height: int = 48,
    seed: int = 0,
    scene_names: Sequence[str] = ARCHIVE_SCENES,
) -> tuple[Path, Path]:
    """An archive of ``count`` simulated scans sharing one calibration (for batch tests and benchmarks).

    Writes ``OUT/calibration/`` (with its reference capture) and ``OUT/archive/scan-NNN/object``
    with ``truth-height.npy`` beside each capture, scenes cycling through ``scene_names``, noise
    seeded by ``seed + i``. Returns (archive directory, calibration directory).
    """
    root = Path(out)
    geometry = demo_geometry(width, height)
    projector = {"width": geometry.projector_width, "height": geometry.projector_height}
    archive = root / "archive"
    first: SimulatedScan | None = None
    for i in range(count):
        scan = simulate_scan(scene_names[i % len(scene_names)], geometry=geometry, seed=seed + i)
        # each scan keeps only its object capture and truth: one calibration for the whole archive, written below
        paths = simulated_paths(archive / f"scan-{i:03d}")
        extra = {"simulation": dict(scan.description)}
        write_capture(paths.capture, scan.object_frames, scan.patterns, projector, scene="object", extra=extra)
        np.save(paths.truth, scan.height_mm.astype(np.float32))
        first = first or scan
    calibration = root / "calibration"
    scan = first if first is not None else simulate_scan(scene_names[0], geometry=geometry, seed=seed)
    write_capture(calibration / "reference", scan.reference_frames, scan.patterns, projector, scene="reference")
    write_calibration(calibration, scan.calibration(reference="reference"))
    return archive, calibration
