"""Pinhole projector-camera simulation: what absolute phase each camera pixel sees on a known object.

Unlike :mod:`mock_devices.synth` (the thesis' ideal reference-plane geometry), camera and projector
here are full pinhole models with intrinsics, OpenCV lens distortion and a pose (R, T: camera ->
projector, mm), looking at a scene of analytic surfaces (a plane and spheres) in the camera frame.
Every camera ray is cast into the scene (nearest hit), the hit point projected into the projector
(``cv2.projectPoints``), and points the projector cannot see (behind a sphere, outside its image)
marked unlit. The result is a :class:`mock_devices.synth.ProjectorMap`, so the synthesiser's
rendering (gamma, noise, quantisation) produces the fringe images.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from mock_devices.synth import Appearance, ProjectorMap, expose
from processing.projection.patterns import pattern_intensity


@dataclass(frozen=True)
class Pinhole:
    matrix: np.ndarray
    distortion: np.ndarray
    width: int
    height: int


@dataclass(frozen=True)
class StereoRig:
    camera: Pinhole
    projector: Pinhole
    rotation: np.ndarray  # camera -> projector
    translation_mm: np.ndarray

    @property
    def projector_centre(self) -> np.ndarray:
        """Projector's optical centre in the camera frame."""
        return -self.rotation.T @ self.translation_mm


@dataclass(frozen=True)
class Scene:
    """A plane n . X = d (camera frame, mm) and spheres (centre, radius) in front of it."""

    plane_normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    plane_distance: float = 600.0
    spheres: tuple[tuple[tuple[float, float, float], float], ...] = field(default=())


def demo_rig(
    camera_width: int = 160, camera_height: int = 128, projector_width: int = 912, projector_height: int = 684
) -> StereoRig:
    """A small rig: camera at the origin, projector 150 mm to its right and toed in by 14 degrees,
    both with mild distortion, focused around 600 mm."""
    fc = 1.25 * camera_width
    camera = Pinhole(
        np.array([[fc, 0, (camera_width - 1) / 2 + 1.5], [0, fc * 1.001, (camera_height - 1) / 2 - 1.0], [0, 0, 1]]),
        np.array([-0.08, 0.05, 0.0005, -0.0003, 0.0]),
        camera_width,
        camera_height,
    )
    fp = 1.1 * projector_width
    projector = Pinhole(
        np.array([[fp, 0, (projector_width - 1) / 2], [0, fp, (projector_height - 1) / 2], [0, 0, 1]]),
        np.array([-0.05, 0.08, 0.0, 0.0, 0.0]),
        projector_width,
        projector_height,
    )
    rotation, _ = cv2.Rodrigues(np.array([0.02, np.radians(14.0), 0.01]))
    centre = np.array([150.0, -5.0, 10.0])  # projector centre in the camera frame
    translation = -rotation @ centre
    return StereoRig(camera, projector, rotation, translation)


def aimed_rig(
    projector_centre_mm: tuple[float, float, float],
    camera_width: int = 160,
    camera_height: int = 128,
    projector_width: int = 912,
    projector_height: int = 684,
    target_mm: tuple[float, float, float] = (0.0, 0.0, 600.0),
) -> StereoRig:
    """:func:`demo_rig`'s camera and projector with the projector at ``projector_centre_mm`` (camera
    frame), aimed at ``target_mm``: e.g. a diagonal baseline, along which both fringe axes carry depth."""
    base = demo_rig(camera_width, camera_height, projector_width, projector_height)
    centre = np.asarray(projector_centre_mm, dtype=np.float64)
    forward = np.asarray(target_mm, dtype=np.float64) - centre
    forward /= np.linalg.norm(forward)
    right = np.cross((0.0, 1.0, 0.0), forward)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.stack([right, down, forward])  # rows: the projector's axes in the camera frame
    return StereoRig(base.camera, base.projector, rotation, -rotation @ centre)


def render_frames(
    rig: StereoRig,
    mapping: ProjectorMap,
    patterns: Sequence[Mapping[str, Any]],
    appearance: Appearance,
    rng: np.random.Generator,
) -> np.ndarray:
    """Camera images (N, H, W) of capture-format patterns (either axis) projected by the rig on a traced scene."""
    size = (rig.projector.width, rig.projector.height)
    return np.stack(
        [expose(pattern_intensity(p, mapping.u, mapping.v, size), mapping, appearance, rng) for p in patterns]
    )


def demo_scene() -> Scene:
    """A plane at 600 mm with a 60 mm-radius sphere standing 40 mm out of it, and a small one."""
    return Scene(spheres=(((0.0, 0.0, 620.0), 60.0), ((-90.0, 60.0, 590.0), 20.0)))


def camera_rays(camera: Pinhole) -> np.ndarray:
    """Unit-z ray directions (H, W, 3) of every camera pixel (lens distortion removed)."""
    xs, ys = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    pts = np.stack([xs.ravel(), ys.ravel()], axis=1).reshape(-1, 1, 2)
    n = cv2.undistortPoints(
        pts, camera.matrix, camera.distortion, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    )
    n = n.reshape(camera.height, camera.width, 2)
    return np.concatenate([n, np.ones((camera.height, camera.width, 1))], axis=2)


def _sphere_hits(origin: np.ndarray, directions: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """Smallest positive ray parameter s of origin + s d on the sphere (inf where missed)."""
    oc = origin - centre
    a = np.einsum("...k,...k->...", directions, directions)
    b = 2.0 * np.einsum("...k,k->...", directions, oc)
    c = float(oc @ oc) - radius * radius
    disc = b * b - 4 * a * c
    root = np.sqrt(np.maximum(disc, 0.0))
    near = (-b - root) / (2 * a)
    far = (-b + root) / (2 * a)
    s = np.where(near > 1e-9, near, np.where(far > 1e-9, far, np.inf))
    return np.where(disc >= 0, s, np.inf)


def trace(rig: StereoRig, scene: Scene) -> tuple[np.ndarray, ProjectorMap]:
    """True 3-D points (H, W, 3) the camera sees, and the projector coordinates lighting them.

    Projector coordinates follow the product's convention (pixel k spans k .. k + 1, so u =
    OpenCV's x + 0.5).
    """
    rays = camera_rays(rig.camera)
    normal = np.asarray(scene.plane_normal, dtype=np.float64)
    with np.errstate(divide="ignore"):
        s = scene.plane_distance / np.einsum("hwk,k->hw", rays, normal)
    s = np.where(s > 0, s, np.inf)
    origin = np.zeros(3)
    for centre, radius in scene.spheres:
        s = np.minimum(s, _sphere_hits(origin, rays, np.asarray(centre, float), radius))
    points = rays * s[..., None]
    hit = np.isfinite(s)
    safe = np.where(hit[..., None], points, 0.0)
    # projector visibility: nothing between the projector centre and the point
    centre_p = rig.projector_centre
    towards = safe - centre_p
    lit = hit.copy()
    for centre, radius in scene.spheres:
        blocked = _sphere_hits(centre_p, towards, np.asarray(centre, float), radius)
        lit &= ~(blocked < 1.0 - 1e-6)
    rvec, _ = cv2.Rodrigues(rig.rotation)
    projected, _ = cv2.projectPoints(
        safe.reshape(-1, 1, 3), rvec, rig.translation_mm, rig.projector.matrix, rig.projector.distortion
    )
    projected = projected.reshape(rig.camera.height, rig.camera.width, 2) + 0.5
    u, v = projected[..., 0], projected[..., 1]
    in_front = (np.einsum("ij,hwj->hwi", rig.rotation, safe) + rig.translation_mm)[..., 2] > 0
    lit &= in_front & (u >= 0) & (u < rig.projector.width) & (v >= 0) & (v < rig.projector.height)
    return np.where(hit[..., None], points, np.nan), ProjectorMap(u=u, v=v, lit=lit)


def calibration_fields(rig: StereoRig) -> dict:
    """The rig's exact parameters as calibration.json keys of the ``stereo`` model."""
    return {
        "model": "stereo",
        "camera_matrix": rig.camera.matrix.tolist(),
        "distortion": rig.camera.distortion.tolist(),
        "projector_matrix": rig.projector.matrix.tolist(),
        "projector_distortion": rig.projector.distortion.tolist(),
        "rotation": rig.rotation.tolist(),
        "translation_mm": rig.translation_mm.tolist(),
        "camera_size": [rig.camera.width, rig.camera.height],
        "projector_size": [rig.projector.width, rig.projector.height],
    }


def board_scene(rvec: np.ndarray, tvec: np.ndarray) -> Scene:
    """The (infinite) plane of a board at pose (rvec, tvec), board frame -> camera frame."""
    rotation, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))
    normal = rotation[:, 2]
    distance = float(normal @ np.asarray(tvec, dtype=np.float64).ravel())
    if distance < 0:
        normal, distance = -normal, -distance
    return Scene(plane_normal=tuple(normal), plane_distance=distance)


def board_session(
    rig: StereoRig,
    count: int = 8,
    squares: tuple[int, int] = (9, 7),
    square_mm: float = 30.0,
    distance_mm: float = 600.0,
    seed: int = 0,
) -> list[tuple[np.ndarray, ProjectorMap]]:
    """``count`` poses of a chessboard in front of the rig: per pose the camera's image of the board
    (mock_devices.board_synth) and the projector map of the board's plane (for fringe rendering
    with the board image as reflectivity)."""
    from mock_devices import board_synth

    rng = np.random.default_rng(seed)
    camera = board_synth.PinholeCamera(rig.camera.matrix, rig.camera.distortion, rig.camera.width, rig.camera.height)
    px_per_mm, margin = 2.0, square_mm
    texture = board_synth.chessboard_texture(squares, square_mm, px_per_mm, margin)
    size = (squares[0] * square_mm, squares[1] * square_mm)
    out = []
    for _ in range(count):
        tilt = rng.uniform(-25, 25, 2)
        centre = (rng.uniform(-40, 40), rng.uniform(-30, 30), distance_mm * rng.uniform(0.92, 1.08))
        rvec, tvec = board_synth.board_pose(tilt[0], tilt[1], rng.uniform(-10, 10), centre, size)
        image = board_synth.render_board_view(texture, px_per_mm, margin, camera, rvec, tvec, rng=rng)
        _, mapping = trace(rig, board_scene(rvec, tvec))
        out.append((image, mapping))
    return out
