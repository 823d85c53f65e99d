"""A drawn family of correction cases, each with its oracle: how ``auto`` generalises.

The study's experiments (:mod:`rig.study.experiments`) fix one rig and a few scenes; a method
tuned on them can fail on the next scan. This module draws cases from ranges instead - scene
kind, image size, frequency set and temporal method, phase steps, SNR, bit depth, rig geometry
(l0, signed d0, field of view) and noise seed - renders each with the product's simulated rig
(:mod:`rig.hardware.synthesis`, as the study does), unwraps it temporally, corrects the object
and its reference plane with every shipped method and scores heights against the truth. The
oracle takes the measured wrapped phase with the true fringe orders.

Two disjoint sets of cases are drawn from the same ranges with different seeds
(:data:`DEVELOP_SEED`, :data:`HELD_OUT_SEED`): methods are developed on the first; figures are
reported on the second, which nothing is tuned on.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from processing.geometry.height import nmse
from processing.phase.shifting import phase_shift
from processing.unwrap.temporal import unwrap_heterodyne, unwrap_hierarchical, unwrap_two_frequency
from rig.hardware import synthesis
from rig.hardware.synthesis import Appearance, RigGeometry
from rig.study.experiments import PhaseCapture, correct, heights

TWO_PI = 2.0 * np.pi
DEVELOP_SEED = 20_000  # cases develop i are drawn from seed DEVELOP_SEED + i
HELD_OUT_SEED = 90_000  # held-out cases: never tune on them
FAMILY_SIZE = 64

SCENE_KINDS = ("isolated", "steps", "caps", "ramps", "mixture", "border", "shadows")
# Frequency sets: (temporal method, frequencies); the last frequency is the one corrected.
FREQUENCY_SETS: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("pair", (5, 8)),
    ("pair", (7, 11)),
    ("pair", (13, 17)),
    ("pair", (18, 25)),
    ("pair", (29, 32)),
    ("hierarchical", (1, 6, 36)),
    ("hierarchical", (1, 8, 64)),
    ("heterodyne", (64, 58, 53)),
    ("heterodyne", (32, 29, 27)),
)
METHODS = ("none", "vote", "rpca-orders", "rpca-phase", "auto")
SINGLE_METHODS = ("vote", "rpca-orders", "rpca-phase")
MARGIN = 1.25  # projector footprint over the camera's view, as the study's rig
GAIN_8BIT = 200.0


@dataclass(frozen=True)
class FamilyCase:
    """One drawn case: everything needed to render it again."""

    name: str
    seed: int
    scene: str
    width: int
    height: int
    unwrap: str
    frequencies: tuple[int, ...]
    steps: int
    snr_db: float
    bits: int
    l0_mm: float
    d0_mm: float
    view_mm: float

    def geometry(self) -> RigGeometry:
        """The case's rig: the top frequency puts ``top / MARGIN`` fringes across the view."""
        top = self.frequencies[-1]
        return RigGeometry(
            l0_mm=self.l0_mm,
            d0_mm=self.d0_mm,
            f0_per_mm=top / (MARGIN * self.view_mm),
            f0_frequency=float(top),
            pixel_mm=self.view_mm / self.width,
            camera_width=self.width,
            camera_height=self.height,
        )

    def describe(self) -> str:
        freqs = "/".join(str(f) for f in self.frequencies)
        return (
            f"{self.name}: {self.scene} {self.width}x{self.height} {self.unwrap} {freqs} {self.steps}-step "
            f"{self.snr_db:.1f} dB {self.bits}-bit l0 {self.l0_mm:.0f} d0 {self.d0_mm:+.0f} view {self.view_mm:.0f} mm"
        )


def draw_case(index: int, held_out: bool = False) -> FamilyCase:
    """Case ``index`` of the develop (or held-out) set, drawn from the ranges with its own seed."""
    seed = (HELD_OUT_SEED if held_out else DEVELOP_SEED) + int(index)
    rng = np.random.default_rng(seed)
    unwrap, frequencies = FREQUENCY_SETS[int(rng.integers(len(FREQUENCY_SETS)))]
    width = int(rng.integers(400, 1201))
    height = int(np.clip(width * rng.uniform(0.6, 1.4), 400, 1200))
    return FamilyCase(
        name=f"{'held-out' if held_out else 'develop'}-{index:02d}",
        seed=seed,
        scene=SCENE_KINDS[int(rng.integers(len(SCENE_KINDS)))],
        width=width,
        height=height,
        unwrap=unwrap,
        frequencies=frequencies,
        steps=int(rng.integers(3, 13)),
        snr_db=float(rng.uniform(12.0, 30.0)),
        bits=int(rng.choice([8, 12, 16])),
        l0_mm=float(rng.uniform(700.0, 1500.0)),
        d0_mm=float(rng.uniform(600.0, 1500.0) * rng.choice([-1.0, 1.0])),
        view_mm=float(rng.uniform(300.0, 700.0)),
    )


def draw_family(count: int = FAMILY_SIZE, held_out: bool = False) -> list[FamilyCase]:
    """The first ``count`` cases of the develop or held-out set."""
    return [draw_case(i, held_out) for i in range(count)]


# --------------------------------------------------------------------------- scenes


def _shape(
    kind: str, x: np.ndarray, y: np.ndarray, cx: float, cy: float, size: float, top: float, rng: np.random.Generator
) -> np.ndarray:
    """Heights (mm) of one object of ``kind`` centred at (cx, cy), ``size`` mm across, ``top`` mm high."""
    r = size / 2.0
    if kind == "block":
        aspect = rng.uniform(0.5, 2.0)
        inside = (np.abs(x - cx) < r * aspect) & (np.abs(y - cy) < r / aspect)
        return np.where(inside, top, 0.0)
    if kind == "cylinder":
        return np.where((x - cx) ** 2 + (y - cy) ** 2 < r * r, top, 0.0)
    if kind == "cap":
        radius = (r * r + top * top) / (2.0 * top)  # sphere through the rim, ``top`` high
        inside = (x - cx) ** 2 + (y - cy) ** 2 < r * r
        cap = np.sqrt(np.maximum(radius**2 - (x - cx) ** 2 - (y - cy) ** 2, 0.0)) - (radius - top)
        return np.where(inside, np.maximum(cap, 0.0), 0.0)
    if kind == "ramp":
        angle = rng.uniform(0.0, np.pi)
        along = (x - cx) * np.cos(angle) + (y - cy) * np.sin(angle)
        inside = (np.abs(x - cx) < r) & (np.abs(y - cy) < r)
        return np.where(inside, top * np.clip((along + r) / (2.0 * r), 0.0, 1.0), 0.0)
    # steps: a staircase of 2 - 5 treads along a random axis
    count = int(rng.integers(2, 6))
    along = x - cx if rng.random() < 0.5 else y - cy
    inside = (np.abs(x - cx) < r) & (np.abs(y - cy) < r)
    level = np.floor((along + r) / (2.0 * r) * count) + 1
    return np.where(inside, level * top / count, 0.0)


SCENE_OBJECTS = {
    "isolated": ("block", "cylinder", "cap"),
    "steps": ("steps",),
    "caps": ("cap",),
    "ramps": ("ramp",),
    "mixture": ("block", "cylinder", "cap", "ramp", "steps"),
    "border": ("block", "cylinder", "cap", "ramp", "steps"),
    "shadows": ("block", "cylinder"),
}


def scene_heights(case: FamilyCase) -> np.ndarray:
    """The case's height map (mm): 1 - 5 objects of its kind, drawn from its seed.

    Heights stay below 6 % of l0 (the height of one fringe period at the top frequency is
    l0 / (f0 d0), well above that for every drawn rig) and up to 12 % for ``shadows`` (tall
    objects that throw large projector shadows); ``border`` objects are centred near the edge of
    the view so that they leave it.
    """
    rng = np.random.default_rng(case.seed + 7)
    g = case.geometry()
    w_mm, h_mm = case.width * g.pixel_mm, case.height * g.pixel_mm
    x = (np.arange(case.width) + 0.5) * g.pixel_mm - w_mm / 2.0
    y = (np.arange(case.height) + 0.5)[:, None] * g.pixel_mm - h_mm / 2.0
    x = np.broadcast_to(x[None, :], (case.height, case.width))
    y = np.broadcast_to(y, (case.height, case.width))
    out = np.zeros((case.height, case.width))
    kinds = SCENE_OBJECTS[case.scene]
    highest = (0.12 if case.scene == "shadows" else 0.06) * case.l0_mm
    for _ in range(int(rng.integers(1, 6))):
        size = rng.uniform(0.12, 0.4) * min(w_mm, h_mm)
        if case.scene == "border":
            side = rng.integers(4)
            cx = (rng.choice([-0.5, 0.5]) * w_mm) if side < 2 else rng.uniform(-0.4, 0.4) * w_mm
            cy = (rng.choice([-0.5, 0.5]) * h_mm) if side >= 2 else rng.uniform(-0.4, 0.4) * h_mm
        else:
            cx, cy = rng.uniform(-0.35, 0.35) * w_mm, rng.uniform(-0.35, 0.35) * h_mm
        top = rng.uniform(0.3, 1.0) * highest
        kind = kinds[int(rng.integers(len(kinds)))]
        out = np.maximum(out, _shape(kind, x, y, cx, cy, size, top, rng))
    return out


# --------------------------------------------------------------------------- capture and scoring


def _appearance(case: FamilyCase) -> Appearance:
    gain = GAIN_8BIT * 2 ** (case.bits - 8)
    return Appearance(ambient=0.05, gain=gain, snr_db=case.snr_db, bit_depth=case.bits)


def capture(case: FamilyCase, height_mm: np.ndarray, rng: np.random.Generator) -> PhaseCapture:
    """Render one scene of the case, phase-shift every frequency and unwrap with the case's method."""
    geometry = case.geometry()
    patterns = synthesis.sinusoid_patterns(list(case.frequencies), case.steps)
    stack, mapping = synthesis.render_scene(height_mm, geometry, patterns, _appearance(case), rng)
    frames = stack.astype(np.float64)
    phis = [phase_shift(frames[i * case.steps : (i + 1) * case.steps]).phase for i in range(len(case.frequencies))]
    if case.unwrap == "pair":
        result = unwrap_two_frequency(phis[0], phis[1], *case.frequencies)
    elif case.unwrap == "hierarchical":
        result = unwrap_hierarchical(phis, case.frequencies)
    else:
        result = unwrap_heterodyne(phis, case.frequencies)
    top = max(case.frequencies)
    assert result.orders is not None  # temporal methods always give orders
    wrapped = result.phase - TWO_PI * result.orders
    truth = synthesis.true_absolute_phase(mapping, geometry, top)
    lit = mapping.lit & np.isfinite(result.phase)
    lower = tuple((float(f), phi) for f, phi in zip(case.frequencies, phis) if f != top)
    return PhaseCapture(result.phase, wrapped, result.orders, truth, lit, lower=lower, frequency=float(top))


def corrected(method: str, capture_: PhaseCapture) -> np.ndarray:
    """Absolute phase after ``method`` as ``rig process`` applies it (:func:`rig.study.experiments.correct`)."""
    return correct(method, capture_)


def evaluate(case: FamilyCase, methods: Sequence[str] = METHODS) -> dict[str, Any]:
    """NMSE_h of every method (and the oracle) on one case, with wrong-order fractions and seconds."""
    start = time.perf_counter()
    height_mm = scene_heights(case)
    rng = np.random.default_rng(case.seed)
    obj = capture(case, height_mm, rng)
    ref = capture(case, np.zeros_like(height_mm), rng)
    mask = obj.lit & ref.lit
    geometry = case.geometry()
    top = max(case.frequencies)
    scores: dict[str, float] = {}
    seconds: dict[str, float] = {}
    for method in (*methods, "oracle"):
        tick = time.perf_counter()
        h = heights(corrected(method, obj), corrected(method, ref), geometry, top)
        seconds[method] = time.perf_counter() - tick
        finite = mask & np.isfinite(h)
        value = nmse(h, height_mm, finite)
        lost = np.count_nonzero(mask & ~np.isfinite(h))
        scores[method] = math.inf if lost > 0.01 * np.count_nonzero(mask) else float(value)
    with np.errstate(invalid="ignore"):
        wrong = np.count_nonzero(mask & (np.abs(obj.phase - obj.truth) > np.pi))
    return {
        "case": asdict(case),
        "description": case.describe(),
        "nmse": scores,
        "seconds": seconds,
        "wrong_fraction": wrong / max(int(np.count_nonzero(mask)), 1),
        "shadow_fraction": 1.0 - np.count_nonzero(mask) / mask.size,
        "total_seconds": time.perf_counter() - start,
    }


def ratios(result: dict[str, Any]) -> dict[str, float]:
    """NMSE_h of each method over the oracle's, and ``auto`` over the best single method (``best``)."""
    scores = result["nmse"]
    oracle = scores["oracle"]
    out = {m: (scores[m] / oracle if oracle > 0 else math.inf) for m in scores if m != "oracle"}
    best = min(scores[m] for m in SINGLE_METHODS + ("none",) if m in scores)
    out["auto/best"] = scores["auto"] / best if best > 0 else math.inf
    out["auto/none"] = scores["auto"] / scores["none"] if scores["none"] > 0 else math.inf
    return out


def distribution(values: Sequence[float]) -> tuple[float, float, float]:
    """(median, 90th percentile, worst) of ``values`` (inf counts as worst)."""
    arr = np.asarray(values, dtype=np.float64)
    arr = np.where(np.isnan(arr), np.inf, arr)
    return float(np.median(arr)), float(np.percentile(arr, 90, method="higher")), float(np.max(arr))
