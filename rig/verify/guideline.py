"""The rules of VDI/VDE 2634 Part 2 this product applies: artefact sizes, positions, the volume.

Our reading of the guideline (docs/verification.md says where each rule comes from and where the
reading is uncertain):

- the measuring volume is a box; L0 is the length of its space diagonal;
- probing errors PF and PS: a sphere of diameter 0.1 L0 .. 0.2 L0, at >= 10 positions spread
  through the volume (:data:`SPHERE_POSITIONS`);
- sphere-spacing error SD: a ball bar (or dumbbell) whose centre distance is >= 0.3 L0, at 7
  positions and orientations, the four space diagonals among them (:data:`BALL_BAR_POSITIONS`);
- flatness measurement error F: a plane >= 0.5 L0 long, at 6 positions (:data:`PLANE_POSITIONS`);
- up to 0.3 % of a fit's points, those of largest residual, may be left out
  (:data:`rig.verify.fits.EXCLUDED_FRACTION`).

Positions are :class:`Placement` objects: what the operator is told, and the geometry the
simulated world builds. Coordinates are those of the point cloud (mm; x, y from the centre of the
camera's view on the reference plane, z the height above it).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

SPHERE_DIAMETER_L0 = (0.1, 0.2)
BALL_BAR_MIN_L0 = 0.3
PLANE_MIN_L0 = 0.5
SPHERE_POSITIONS = 10
BALL_BAR_POSITIONS = 7
PLANE_POSITIONS = 6
QUANTITIES = ("PF", "PS", "SD", "F")
KINDS = ("sphere", "ball-bar", "plane")
# Artefacts stand clear of the reference plane (the background of every scan) by at least this.
CLEARANCE_MM = 10.0

Vector = tuple[float, float, float]


@dataclass(frozen=True)
class Volume:
    """The measuring volume: a box ``width`` x ``length`` (x, y) centred on the view, ``depth`` high."""

    width_mm: float
    length_mm: float
    depth_mm: float

    @property
    def l0_mm(self) -> float:
        """L0: the length of the volume's space diagonal."""
        return math.sqrt(self.width_mm**2 + self.length_mm**2 + self.depth_mm**2)

    def as_dict(self) -> dict[str, float]:
        return {"width_mm": self.width_mm, "length_mm": self.length_mm, "depth_mm": self.depth_mm, "l0_mm": self.l0_mm}


def volume_of_view(columns: int, rows: int, pixel_mm: float, l0_mm: float | None, depth_mm: float) -> Volume:
    """The box a camera of ``columns`` x ``rows`` pixels sees whole from the reference plane up to ``depth_mm``.

    A pinhole at ``l0_mm`` sees less at the top of the volume: the box takes the view's width there.
    """
    shrink = 1.0 if not l0_mm else (l0_mm - depth_mm) / l0_mm
    if not 0 < shrink <= 1 or depth_mm <= 0:
        raise ValueError(f"depth_mm: expected between 0 and l0 ({l0_mm} mm), found {depth_mm}")
    return Volume(columns * pixel_mm * shrink, rows * pixel_mm * shrink, depth_mm)


@dataclass(frozen=True)
class Placement:
    """One artefact position: the words for the operator and the geometry (mm) it stands for.

    ``centres``: one sphere centre (sphere), two (ball bar), the plate's centre (plane);
    ``along``/``across``: the plate's unit axes (plane), the bar's direction in ``along`` (ball bar).
    """

    kind: str
    index: int  # 1-based
    total: int
    where: str
    centres: tuple[Vector, ...]
    along: Vector = (1.0, 0.0, 0.0)
    across: Vector = (0.0, 1.0, 0.0)

    @property
    def name(self) -> str:
        """Directory and table name, e.g. ``ball-bar-03``."""
        return f"{self.kind}-{self.index:02d}"

    def prompt(self) -> str:
        label = self.kind.replace("-", " ")
        return f"{label}, position {self.index} of {self.total}: {self.where}, press Enter "

    def as_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "index": self.index,
            "total": self.total,
            "where": self.where,
            "centres": [list(c) for c in self.centres],
            "along": list(self.along),
            "across": list(self.across),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Placement:
        """The placement :meth:`as_dict` wrote; KeyError, TypeError or ValueError when it is not one."""

        def vec(value: Any) -> Vector:
            x, y, z = (float(v) for v in value)
            return (x, y, z)

        return cls(
            kind=str(data["kind"]),
            index=int(data["index"]),
            total=int(data["total"]),
            where=str(data["where"]),
            centres=tuple(vec(c) for c in data["centres"]),
            along=vec(data.get("along", (1.0, 0.0, 0.0))),
            across=vec(data.get("across", (0.0, 1.0, 0.0))),
        )


def _unit(v: Vector) -> Vector:
    n = math.sqrt(sum(c * c for c in v))
    return (v[0] / n, v[1] / n, v[2] / n)


# Sphere positions as fractions of the room a sphere's centre has (x, y in -1..1, z in 0..1).
_SPHERE_LAYOUT = (
    ((-1, -1, 0), "low, near corner -x -y"),
    ((1, -1, 0), "low, corner +x -y"),
    ((1, 1, 0), "low, corner +x +y"),
    ((-1, 1, 0), "low, corner -x +y"),
    ((0, 0, 0.5), "mid height, centre"),
    ((-0.5, 0.5, 0.5), "mid height, towards -x +y"),
    ((0, -1, 1), "high, edge -y"),
    ((1, 0, 1), "high, edge +x"),
    ((0, 1, 1), "high, edge +y"),
    ((-1, 0, 1), "high, edge -x"),
)


def sphere_placements(volume: Volume, diameter_mm: float, count: int = SPHERE_POSITIONS) -> list[Placement]:
    """``count`` sphere positions spread through the volume (layout cycles when count > 10)."""
    r = diameter_mm / 2
    half_x, half_y = volume.width_mm / 2 - r, volume.length_mm / 2 - r
    z_low, z_high = r + CLEARANCE_MM, volume.depth_mm - r
    if half_x <= 0 or half_y <= 0 or z_high < z_low:
        raise ValueError(f"sphere diameter {diameter_mm:g} mm: does not fit the measuring volume {volume.as_dict()}")
    out = []
    for i in range(count):
        (fx, fy, fz), where = _SPHERE_LAYOUT[i % len(_SPHERE_LAYOUT)]
        centre = (fx * half_x, fy * half_y, z_low + fz * (z_high - z_low))
        out.append(Placement("sphere", i + 1, count, where, (centre,)))
    return out


def ball_bar_placements(volume: Volume, length_mm: float, sphere_diameter_mm: float) -> list[Placement]:
    """Seven ball-bar positions through the volume's centre: four space diagonals, then along x, y and a face diagonal."""
    w, le, d = volume.width_mm, volume.length_mm, volume.depth_mm
    directions = [
        ((w, le, d), "space diagonal -x -y low to +x +y high"),
        ((-w, le, d), "space diagonal +x -y low to -x +y high"),
        ((w, -le, d), "space diagonal -x +y low to +x -y high"),
        ((-w, -le, d), "space diagonal +x +y low to -x -y high"),
        ((1.0, 0.0, 0.0), "level, along x at mid height"),
        ((0.0, 1.0, 0.0), "level, along y at mid height"),
        ((w, le, 0.0), "level, along the diagonal of the top face at mid height"),
    ]
    centre = (0.0, 0.0, d / 2)
    out = []
    for i, (direction, where) in enumerate(directions):
        u = _unit(direction)
        ends = tuple(_along(centre, u, side * length_mm / 2) for side in (-1.0, 1.0))
        _check_inside(volume, ends, sphere_diameter_mm / 2, f"ball bar position {i + 1}")
        out.append(Placement("ball-bar", i + 1, len(directions), where, ends, along=u))
    return out


def plane_placements(volume: Volume, length_mm: float, width_mm: float, tilt_deg: float = 15.0) -> list[Placement]:
    """Six plane positions: level low and high, level on both face diagonals, tilted both ways along x."""
    d = volume.depth_mm
    t = math.radians(tilt_deg)
    diag = _unit((volume.width_mm, volume.length_mm, 0.0))
    anti = _unit((volume.width_mm, -volume.length_mm, 0.0))
    layouts = [
        ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 0.2, "level, along x, low"),
        ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 0.8, "level, along x, high"),
        (diag, (-diag[1], diag[0], 0.0), 0.5, "level, along the diagonal -x -y to +x +y, mid height"),
        (anti, (-anti[1], anti[0], 0.0), 0.5, "level, along the diagonal -x +y to +x -y, mid height"),
        ((math.cos(t), 0.0, math.sin(t)), (0.0, 1.0, 0.0), 0.5, f"along x, rising {tilt_deg:g} deg towards +x"),
        ((math.cos(t), 0.0, -math.sin(t)), (0.0, 1.0, 0.0), 0.5, f"along x, falling {tilt_deg:g} deg towards +x"),
    ]
    out = []
    for i, (along, across, fz, where) in enumerate(layouts):
        rise = abs(along[2]) * length_mm / 2
        z = CLEARANCE_MM + rise + fz * (d - 2 * rise - CLEARANCE_MM)
        corners = [
            (sa * length_mm / 2 * along[0] + sb * width_mm / 2 * across[0],
             sa * length_mm / 2 * along[1] + sb * width_mm / 2 * across[1],
             z + sa * length_mm / 2 * along[2])
            for sa in (-1, 1) for sb in (-1, 1)
        ]  # fmt: skip
        _check_inside(volume, corners, 0.0, f"plane position {i + 1}")
        out.append(Placement("plane", i + 1, len(layouts), where, ((0.0, 0.0, z),), along, across))
    return out


def _along(start: Vector, direction: Vector, distance: float) -> Vector:
    x, y, z = (s + distance * d for s, d in zip(start, direction))
    return (x, y, z)


def _check_inside(volume: Volume, points: Iterable[Vector], margin: float, what: str) -> None:
    for x, y, z in points:
        inside = abs(x) + margin <= volume.width_mm / 2 + 1e-6 and abs(y) + margin <= volume.length_mm / 2 + 1e-6
        if not inside or z - margin < -1e-6 or z + margin > volume.depth_mm + 1e-6:
            raise ValueError(f"{what}: the artefact does not fit the measuring volume {volume.as_dict()}")
