"""Reproduction study: the thesis' simulations regenerated with this package's methods.

Every experiment simulates captures with the product's simulated rig
(:mod:`rig.hardware.synthesis`: the scenes and renderer ``rig demo`` and ``rig simulate`` use),
runs the thesis' processing chain with the numeric kernels the pipeline's stages call
(:mod:`processing`), corrects the phase with the methods of the one correction registry
(:data:`rig.pipeline.corrections.REGISTRY`, what ``rig process --correction`` offers) and compares
heights (NMSE_h, thesis eq. 2.18) or phases (MSE, eq. 3.5) with the simulation's truth:

- Table 4.1: sphere cap, f = (5, 8), 6-step, 15 dB; no correction, ch. 4, ch. 3 with and
  without post-processing, Ding's voting [119], ``auto`` and an oracle (true fringe orders);
- ch. 2.4 denoising: 3-step PSP of a hemisphere, and (5, 8) 6-step of two hemispheres;
- ch. 3.3.2 sweep of t (Figs. 3.6-3.8): phase MSE and residual order errors at 15, 12, 10 dB;
- Fig. 4.5: NMSE_h against SNR;
- ch. 4.3.1: isolated objects at f = (18, 25), 18 dB;
- ch. 2.3: single-shot speckle-embedded unwrapping of a hemisphere and two hemispheres.

The rig is fixed for all of them (:data:`RIG`; the thesis does not state its l0, d0, f0).
:func:`run_study` writes a Markdown report, a CSV of every number and PNG figures.
"""

from __future__ import annotations

import csv
import logging
import math
import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from processing.correction.orders import postprocess_orders
from processing.correction.registry import DECIMATE_FROM, DECIMATION
from processing.correction.sampling import fringe_step_rad, undersampled_for_spatial_methods
from processing.correction.voting import vote_row_orders
from processing.denoise.frames import rpca_denoise_stack
from processing.geometry.height import nmse, phase_mse, phase_to_height
from processing.phase.shifting import phase_shift
from processing.unwrap.single_shot import prepare_reference, single_shot_unwrap
from processing.unwrap.temporal import unwrap_two_frequency
from rig.blas import rpca_blas
from rig.errors import ConfigError
from rig.hardware import synthesis
from rig.hardware.synthesis import Appearance, ProjectorMap, RigGeometry
from rig.pipeline.corrections import REGISTRY as CORRECTIONS
from rig.study import figures as fig

log = logging.getLogger(__name__)

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class StudyRig:
    """The simulated rig of every experiment (lengths in mm).

    The camera always sees ``view_mm`` x ``view_mm`` of the reference plane, whatever its pixel
    count, so a smaller ``size`` is the same physical experiment at a lower resolution. The
    projector's footprint is ``margin`` times the view (RigGeometry's default), so the
    frequency-8 pattern has f0 = 8 / (1.25 * 500) = 0.0128 cycles/mm on the plane.
    """

    l0_mm: float = 1000.0
    d0_mm: float = 1250.0
    view_mm: float = 500.0
    margin: float = 1.25
    f0_frequency: int = 8

    @property
    def f0_per_mm(self) -> float:
        return self.f0_frequency / (self.margin * self.view_mm)

    def geometry(self, size: int) -> RigGeometry:
        """RigGeometry of a ``size`` x ``size`` camera over the fixed view."""
        return RigGeometry(
            l0_mm=self.l0_mm,
            d0_mm=self.d0_mm,
            f0_per_mm=self.f0_per_mm,
            f0_frequency=self.f0_frequency,
            pixel_mm=self.view_mm / size,
            camera_width=size,
            camera_height=size,
        )


RIG = StudyRig()

# Thesis figures quoted beside ours.
THESIS_TABLE_4_1 = {
    "none": 0.3893,
    "rpca-phase": 0.0003,
    "rpca-orders-nopost": 0.2959,
    "rpca-orders": 0.0057,
    "vote": 0.0081,
}
THESIS_DENOISE = {"psp3-hemisphere": (0.0199, 0.000866), "two-freq-two-hemispheres": (0.6786, 0.0025)}

ORDER_T = 0.034
# Methods compared on two-frequency captures: key -> (label, CORRECTIONS entry or None, parameters).
METHODS: dict[str, tuple[str, str | None, dict[str, Any]]] = {
    "none": ("no correction", "none", {}),
    "rpca-phase": ("ch. 4: RPCA on the absolute phase", "rpca-phase", {}),
    "rpca-orders-nopost": (
        "ch. 3: RPCA on orders, no post-processing",
        "rpca-orders",
        {"t": ORDER_T, "postprocess": False},
    ),
    "rpca-orders": ("ch. 3: RPCA on orders + post-processing", "rpca-orders", {"t": ORDER_T}),
    "vote": ("Ding's row voting [119]", "vote", {}),
    "auto": ("auto (region-pooled orders + ch. 4)", "auto", {}),
    "oracle": ("oracle: true fringe orders", None, {}),
}

SINGLE_SHOT_FREQUENCY = 16
SINGLE_SHOT_SNR_DB = 25.0
SINGLE_SHOT_HEMISPHERE_MM = 100.0
SPECKLE_PATTERN = {
    "kind": "speckle-sinusoid",
    "axis": "x",
    "frequency": SINGLE_SHOT_FREQUENCY,
    "steps": 1,
    "step": 0,
    "seed": 2026,
    "dot_px": 3,
    "speckle_gain": 0.3,
}


@dataclass(frozen=True)
class StudyConfig:
    """Sizes, seeds and sweeps of one study run (the defaults are the full study)."""

    size: int = 1000  # Table 4.1, denoising, isolated objects, single shot
    sweep_size: int = 1000  # t sweep (many RPCA runs)
    snr_size: int = 1000  # NMSE vs SNR
    seeds: int = 3
    t_values: tuple[float, ...] = (0.02, 0.03, 0.034, 0.04, 0.05, 0.06, 0.09, 0.3)
    sweep_snrs: tuple[float, ...] = (15.0, 12.0, 10.0)
    snr_values: tuple[float, ...] = (10.0, 12.0, 15.0, 18.0, 20.0, 25.0)
    quick: bool = False

    @classmethod
    def quick_config(cls, seeds: int = 2) -> StudyConfig:
        """A small, fast configuration that runs every experiment (for tests)."""
        return cls(
            size=128,
            sweep_size=96,
            snr_size=96,
            seeds=seeds,
            t_values=(0.02, 0.034, 0.09),
            sweep_snrs=(15.0, 10.0),
            snr_values=(10.0, 15.0, 25.0),
            quick=True,
        )

    def __post_init__(self) -> None:
        for name in ("size", "sweep_size", "snr_size"):
            if int(getattr(self, name)) < 64:
                raise ConfigError(f"{name}: expected at least 64 pixels, found {getattr(self, name)}")
        if int(self.seeds) < 1:
            raise ConfigError(f"seeds: expected at least 1, found {self.seeds}")


@dataclass
class Rows:
    """The study's numbers in long form, one CSV row each."""

    rows: list[dict[str, Any]] = field(default_factory=list)

    def add(self, experiment: str, metric: str, value: float, **keys: Any) -> None:
        self.rows.append({"experiment": experiment, "metric": metric, "value": float(value), **keys})

    def select(self, experiment: str, metric: str, **keys: Any) -> list[float]:
        return [
            r["value"]
            for r in self.rows
            if r["experiment"] == experiment and r["metric"] == metric and all(r.get(k) == v for k, v in keys.items())
        ]


# --------------------------------------------------------------------------- simulation


@dataclass
class PhaseCapture:
    """Absolute phase at the highest frequency of one simulated scene (object or reference)."""

    phase: np.ndarray  # as unwrapped (Ding), NaN nowhere
    wrapped: np.ndarray  # in [0, 2 pi): phase = wrapped + 2 pi orders
    orders: np.ndarray
    truth: np.ndarray  # true absolute phase, NaN where unlit
    lit: np.ndarray
    frames: np.ndarray | None = None
    # (frequency, wrapped phase) of every lower frequency, for auto's temporal evidence
    lower: tuple[tuple[float, np.ndarray], ...] = ()
    frequency: float | None = None  # the frequency ``phase`` is at, as the correction stage passes it


def _render(
    height_mm: np.ndarray,
    geometry: RigGeometry,
    patterns: list[dict[str, Any]],
    snr_db: float | None,
    rng: np.random.Generator,
) -> tuple[np.ndarray, ProjectorMap]:
    stack, mapping = synthesis.render_scene(height_mm, geometry, patterns, Appearance(snr_db=snr_db), rng)
    return stack.astype(np.float64), mapping


def two_frequency_capture(
    height_mm: np.ndarray,
    geometry: RigGeometry,
    frequencies: tuple[int, int],
    steps: int,
    snr_db: float,
    rng: np.random.Generator,
    denoise: bool = False,
    keep_frames: bool = False,
) -> PhaseCapture:
    """Render, phase-shift and unwrap (Ding) one scene; optionally RPCA-denoise every frame first."""
    f1, f2 = frequencies
    stack, mapping = _render(height_mm, geometry, synthesis.sinusoid_patterns([f1, f2], steps), snr_db, rng)
    frames = stack
    if denoise:
        frames, _ = rpca_denoise_stack(stack)
    phi1 = phase_shift(frames[:steps]).phase
    phi2 = phase_shift(frames[steps:]).phase
    result = unwrap_two_frequency(phi1, phi2, f1, f2)
    assert result.orders is not None  # temporal methods always give fringe orders
    wrapped = result.phase - TWO_PI * result.orders
    return PhaseCapture(
        result.phase,
        wrapped,
        result.orders,
        synthesis.true_absolute_phase(mapping, geometry, f2),
        mapping.lit,
        stack if keep_frames else None,
        lower=((float(f1), phi1),),
        frequency=float(f2),
    )


def single_frequency_capture(
    height_mm: np.ndarray,
    geometry: RigGeometry,
    frequency: int,
    steps: int,
    snr_db: float,
    rng: np.random.Generator,
    denoise: bool = False,
) -> PhaseCapture:
    """Phase-shifted capture at one frequency, unwrapped with the true fringe orders (oracle)."""
    stack, mapping = _render(height_mm, geometry, synthesis.sinusoid_patterns([frequency], steps), snr_db, rng)
    frames = rpca_denoise_stack(stack)[0] if denoise else stack
    wrapped = np.mod(phase_shift(frames).phase, TWO_PI)
    truth = synthesis.true_absolute_phase(mapping, geometry, frequency)
    orders = np.rint((np.nan_to_num(truth) - wrapped) / TWO_PI).astype(np.int64)
    return PhaseCapture(wrapped + TWO_PI * orders, wrapped, orders, truth, mapping.lit, stack, frequency=frequency)


def oracle_phase(capture: PhaseCapture) -> np.ndarray:
    """The measured wrapped phase with the true fringe orders (NaN where unlit)."""
    orders = np.rint((capture.truth - capture.wrapped) / TWO_PI)
    return capture.wrapped + TWO_PI * orders


def correct(key: str, capture: PhaseCapture, **params: Any) -> np.ndarray:
    """Absolute phase of ``capture`` after the :data:`METHODS` entry ``key`` (NaN outside the lit pixels).

    ``oracle`` is the study's yardstick (:func:`oracle_phase`); every other key is a method of the
    correction registry, called as ``rig process``'s correction stage calls it (its frequency, and for
    ``auto`` the lower frequencies' wrapped phases; ``auto`` skipped where fringes are too dense for it,
    :func:`auto_too_dense`); ``params`` override the entry's.
    """
    if key == "oracle":
        return oracle_phase(capture)
    _, registry_name, entry_params = METHODS[key]
    assert registry_name is not None
    if registry_name == "auto" and auto_too_dense(capture):
        registry_name, entry_params = "none", {}
    inputs: dict[str, Any] = {}
    if capture.frequency is not None:
        inputs["frequency"] = capture.frequency
    if registry_name == "auto" and capture.frequency is not None:
        inputs["lower_wrapped"] = list(capture.lower)
    phase, _info = CORRECTIONS[registry_name](
        capture.phase, capture.wrapped, mask=capture.lit, **inputs, **{**entry_params, **params}
    )
    return phase


def auto_too_dense(capture: PhaseCapture) -> bool:
    """Whether ``rig process`` would skip ``auto`` on this capture (fringes too dense along x)."""
    return undersampled_for_spatial_methods(fringe_step_rad(capture.phase, capture.lit, axis=1))


def corrected_phases(capture: PhaseCapture, methods: Sequence[str]) -> dict[str, tuple[np.ndarray, float]]:
    """Absolute phase after each method (NaN outside the lit pixels) and its seconds."""
    out: dict[str, tuple[np.ndarray, float]] = {}
    for key in methods:
        start = time.perf_counter()
        if key == "rpca-orders" and "rpca-orders-nopost" in out:
            # Ch. 3's post-processing pass (what rpca-orders runs after its RPCA solve) on the
            # no-post-processing result, so the costly RPCA runs once for both columns.
            nopost, rpca_seconds = out["rpca-orders-nopost"]
            post = postprocess_orders(nopost, np.isfinite(nopost))
            out[key] = (post, rpca_seconds + time.perf_counter() - start)
            continue
        phase = correct(key, capture)
        out[key] = (phase, time.perf_counter() - start)
    return out


def heights(obj_phase: np.ndarray, ref_phase: np.ndarray, geometry: RigGeometry, frequency: float) -> np.ndarray:
    """Eq. 1.15 on object - reference absolute phases of ``frequency``."""
    return phase_to_height(obj_phase - ref_phase, geometry.l0_mm, geometry.d0_mm, geometry.per_mm(frequency))


def order_errors(phase: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> int:
    """Pixels whose absolute phase is off by more than pi (a wrong fringe order)."""
    with np.errstate(invalid="ignore"):
        return int(np.count_nonzero(mask & (np.abs(phase - truth) > np.pi)))


# --------------------------------------------------------------------------- experiments


Progress = Callable[[str], None]


def _compare_methods(
    experiment: str,
    rows: Rows,
    height_mm: np.ndarray,
    geometry: RigGeometry,
    obj: PhaseCapture,
    ref: PhaseCapture,
    frequency: float,
    methods: Sequence[str],
    **keys: Any,
) -> dict[str, np.ndarray]:
    """NMSE_h, order errors and seconds of every method on one object/reference pair."""
    mask = obj.lit & ref.lit
    obj_out = corrected_phases(obj, methods)
    ref_out = corrected_phases(ref, methods)
    maps: dict[str, np.ndarray] = {}
    for key in methods:
        (po, so), (pr, sr) = obj_out[key], ref_out[key]
        h = heights(po, pr, geometry, frequency)
        rows.add(experiment, "nmse_h", nmse(h, height_mm, mask), method=key, **keys)
        rows.add(experiment, "order_errors", order_errors(po, obj.truth, mask), method=key, **keys)
        rows.add(experiment, "seconds", so + sr, method=key, **keys)
        maps[key] = po
        maps[f"{key}:height"] = h
    rows.add(experiment, "pixels", int(mask.sum()), method="-", **keys)
    return maps


def table_4_1(config: StudyConfig, rows: Rows, progress: Progress) -> dict[str, Any]:
    """Thesis Table 4.1 on ``config.seeds`` noise seeds; returns the first seed's maps for figures."""
    geometry = RIG.geometry(config.size)
    cap = synthesis.scene_height("sphere-cap", geometry, radius_mm=300.0, max_height_mm=100.0)
    first: dict[str, Any] = {}
    for seed in range(config.seeds):
        rng = np.random.default_rng(4100 + seed)
        obj = two_frequency_capture(cap, geometry, (5, 8), 6, 15.0, rng)
        ref = two_frequency_capture(np.zeros_like(cap), geometry, (5, 8), 6, 15.0, rng)
        maps = _compare_methods(
            "table-4.1", rows, cap, geometry, obj, ref, 8, list(METHODS), seed=seed, size=config.size, snr_db=15.0
        )
        progress(f"Table 4.1 seed {seed}: none {rows.select('table-4.1', 'nmse_h', method='none', seed=seed)[0]:.4f}")
        if seed == 0:
            first = {"maps": maps, "truth": obj.truth, "height": cap, "lit": obj.lit & ref.lit}
    return first


def denoising(config: StudyConfig, rows: Rows, progress: Progress) -> dict[str, Any]:
    """Thesis ch. 2.4: the two denoising experiments, without and with RPCA denoising."""
    geometry = RIG.geometry(config.size)
    hemi = synthesis.scene_height("hemisphere", geometry)
    pair = synthesis.scene_height("two-hemispheres", geometry)
    figure: dict[str, Any] = {}
    for seed in range(config.seeds):
        for denoise in (False, True):
            label = "rpca-denoised" if denoise else "raw"
            # (a) 3-step PSP at f = 8, orders from the truth: the phase noise is all that differs.
            rng = np.random.default_rng(2400 + seed)
            obj = single_frequency_capture(hemi, geometry, 8, 3, 15.0, rng, denoise=denoise)
            ref = single_frequency_capture(np.zeros_like(hemi), geometry, 8, 3, 15.0, rng, denoise=denoise)
            mask = obj.lit & ref.lit
            h = heights(obj.phase, ref.phase, geometry, 8)
            rows.add("denoise", "nmse_h", nmse(h, hemi, mask), case="psp3-hemisphere", method=label, seed=seed)
            if seed == 0:
                figure[f"psp3:{label}:height"] = h
                if denoise:
                    assert obj.frames is not None
                    figure["psp3:frame"] = obj.frames[0]
                    figure["psp3:denoised"] = rpca_denoise_stack(obj.frames[:1])[0][0]
                    clean, _ = _render(hemi, geometry, synthesis.sinusoid_patterns([8], 3)[:1], None, rng)
                    figure["psp3:clean"] = clean[0]
            # (b) two frequencies (5, 8), 6-step, Ding unwrapping, on two hemispheres.
            rng = np.random.default_rng(2410 + seed)
            obj = two_frequency_capture(pair, geometry, (5, 8), 6, 15.0, rng, denoise=denoise)
            ref = two_frequency_capture(np.zeros_like(pair), geometry, (5, 8), 6, 15.0, rng, denoise=denoise)
            mask = obj.lit & ref.lit
            h = heights(obj.phase, ref.phase, geometry, 8)
            rows.add("denoise", "nmse_h", nmse(h, pair, mask), case="two-freq-two-hemispheres", method=label, seed=seed)
            rows.add(
                "denoise",
                "order_errors",
                order_errors(obj.phase, obj.truth, mask),
                case="two-freq-two-hemispheres",
                method=label,
                seed=seed,
            )
            if seed == 0:
                figure[f"pair:{label}:height"] = h
        progress(f"denoising seed {seed} done")
    figure["hemisphere"] = hemi
    figure["pair"] = pair
    return figure


def t_sweep(config: StudyConfig, rows: Rows, progress: Progress) -> None:
    """Thesis Figs. 3.6-3.8: ch. 3 RPCA (no post-processing) over t, at several SNRs."""
    geometry = RIG.geometry(config.sweep_size)
    hemi = synthesis.scene_height("hemisphere", geometry)
    for snr in config.sweep_snrs:
        rng = np.random.default_rng(3600 + int(snr))
        obj = two_frequency_capture(hemi, geometry, (5, 8), 6, snr, rng)
        ref = two_frequency_capture(np.zeros_like(hemi), geometry, (5, 8), 6, snr, rng)
        # The thesis sweeps both maps at 15 dB (Figs. 3.6, 3.7) and the hemisphere at other SNRs (Fig. 3.8).
        targets = [("hemisphere", obj), ("reference", ref)] if snr == config.sweep_snrs[0] else [("hemisphere", obj)]
        for scene_name, cap in targets:
            mask = cap.lit
            rows.add(
                "t-sweep",
                "order_errors",
                order_errors(cap.phase, cap.truth, mask),
                scene=scene_name,
                snr_db=snr,
                t="none",
            )
            rows.add("t-sweep", "mse", phase_mse(cap.phase, cap.truth, mask), scene=scene_name, snr_db=snr, t="none")
            for t in config.t_values:
                phase = correct("rpca-orders-nopost", cap, t=t)
                rows.add(
                    "t-sweep", "order_errors", order_errors(phase, cap.truth, mask), scene=scene_name, snr_db=snr, t=t
                )
                rows.add(
                    "t-sweep",
                    "order_errors_post",
                    order_errors(postprocess_orders(phase, np.isfinite(phase)), cap.truth, mask),
                    scene=scene_name,
                    snr_db=snr,
                    t=t,
                )
                rows.add("t-sweep", "mse", phase_mse(phase, cap.truth, mask), scene=scene_name, snr_db=snr, t=t)
        progress(f"t sweep at {snr:g} dB done")


def snr_sweep(config: StudyConfig, rows: Rows, progress: Progress) -> None:
    """Thesis Fig. 4.5: NMSE_h of every method against SNR (sphere cap, (5, 8), 6-step)."""
    geometry = RIG.geometry(config.snr_size)
    cap = synthesis.scene_height("sphere-cap", geometry)
    for snr in config.snr_values:
        for seed in range(config.seeds):
            rng = np.random.default_rng(4500 + int(snr) + 100 * seed)
            obj = two_frequency_capture(cap, geometry, (5, 8), 6, snr, rng)
            ref = two_frequency_capture(np.zeros_like(cap), geometry, (5, 8), 6, snr, rng)
            _compare_methods(
                "snr-sweep",
                rows,
                cap,
                geometry,
                obj,
                ref,
                8,
                list(METHODS),
                snr_db=snr,
                size=config.snr_size,
                seed=seed,
            )
        progress(f"SNR sweep at {snr:g} dB done")


def isolated(config: StudyConfig, rows: Rows, progress: Progress) -> dict[str, Any]:
    """Thesis ch. 4.3.1: isolated objects, f = (18, 25), 6-step, 18 dB; returns seed 0's maps."""
    geometry = RIG.geometry(config.size)
    objects = synthesis.scene_height("isolated", geometry)
    first: dict[str, Any] = {}
    for seed in range(config.seeds):
        rng = np.random.default_rng(4600 + seed)
        obj = two_frequency_capture(objects, geometry, (18, 25), 6, 18.0, rng)
        ref = two_frequency_capture(np.zeros_like(objects), geometry, (18, 25), 6, 18.0, rng)
        maps = _compare_methods(
            "isolated", rows, objects, geometry, obj, ref, 25, list(METHODS), snr_db=18.0, size=config.size, seed=seed
        )
        if seed == 0:
            first = {"maps": maps, "truth": obj.truth, "height": objects, "lit": obj.lit & ref.lit}
    progress("isolated objects done")
    return first


def single_shot(config: StudyConfig, rows: Rows, progress: Progress) -> dict[str, Any]:
    """Thesis ch. 2.3: one speckle-embedded image per scene, 25 dB, perfect calibration."""
    geometry = RIG.geometry(config.size)
    scene_maps = {
        "hemisphere": synthesis.scene_height("hemisphere", geometry, radius_mm=SINGLE_SHOT_HEMISPHERE_MM),
        "two-hemispheres": synthesis.scene_height("two-hemispheres", geometry),
    }
    look = Appearance(snr_db=SINGLE_SHOT_SNR_DB)
    f = SINGLE_SHOT_FREQUENCY
    figure: dict[str, Any] = {}
    for seed in range(config.seeds):
        rng = np.random.default_rng(2300 + seed)
        ref_frames, ref_map = synthesis.render_scene(
            np.zeros((config.size, config.size)), geometry, [SPECKLE_PATTERN], look, rng
        )
        ref_image = ref_frames[0]
        ref_truth = synthesis.true_absolute_phase(ref_map, geometry, f)
        # the reference is prepared once per seed for each variant: with and without RPCA separation
        references = {
            variant: prepare_reference(ref_image, ref_truth, f, separate=variant == "rpca")
            for variant in ("rpca", "no-separation")
        }
        for name, height_mm in scene_maps.items():
            frames, obj_map = synthesis.render_scene(height_mm, geometry, [SPECKLE_PATTERN], look, rng)
            image = frames[0]
            truth = synthesis.true_absolute_phase(obj_map, geometry, f)
            for variant, reference in references.items():
                result = single_shot_unwrap(image, reference, None, f, separate=variant == "rpca")
                lit = np.isfinite(truth)
                valid = result.mask & lit
                k_true = np.rint((truth - result.wrapped_phase) / TWO_PI)
                keys = {"scene": name, "seed": seed, "method": variant}
                rows.add("single-shot", "valid_fraction", valid.sum() / max(lit.sum(), 1), **keys)
                rows.add(
                    "single-shot",
                    "exact_correlation",
                    np.mean(result.correlation_orders[valid] == k_true[valid]),
                    **keys,
                )
                rows.add("single-shot", "exact_voted", np.mean(result.orders[valid] == k_true[valid]), **keys)
                # Ding's row vote alone on the same correlation orders (the thesis' last step), to show
                # what the 2-D segment vote adds
                row_vote = vote_row_orders(
                    np.where(result.mask, result.wrapped_phase + TWO_PI * result.correlation_orders, np.nan),
                    result.wrapped_phase,
                    mask=result.mask,
                )
                row_orders = np.rint((row_vote - result.wrapped_phase) / TWO_PI)
                rows.add("single-shot", "exact_row_vote", np.mean(row_orders[valid] == k_true[valid]), **keys)
                rows.add(
                    "single-shot",
                    "nmse_h_row_vote",
                    nmse(heights(row_vote, ref_truth, geometry, f), height_mm, valid),
                    **keys,
                )
                h = heights(result.absolute_phase, ref_truth, geometry, f)
                rows.add("single-shot", "nmse_h", nmse(h, height_mm, valid), **keys)
                good = valid & (np.abs(result.absolute_phase - truth) < np.pi)
                rows.add("single-shot", "nmse_h_right_orders", nmse(h, height_mm, good), **keys)
                if variant == "rpca":
                    for stage in ("rpca", "ftp", "correlation", "voting", "total"):
                        rows.add("single-shot", f"seconds_{stage}", result.timings[stage], **keys)
                if seed == 0 and variant == "rpca":
                    figure[name] = {
                        "image": image,
                        "fringe": result.fringe,
                        "speckle": result.speckle,
                        "orders": np.where(valid, result.orders, np.nan),
                        "error": np.where(valid, result.orders - k_true, np.nan),
                        "height": np.where(valid, h, np.nan),
                        "truth": height_mm,
                    }
        progress(f"single shot seed {seed} done")
    return figure


# --------------------------------------------------------------------------- report


def _stats(values: Sequence[float]) -> tuple[float, float, float]:
    arr = np.asarray(values, dtype=np.float64)
    return float(np.median(arr)), float(np.min(arr)), float(np.max(arr))


def _fmt(value: float | None, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if value == 0:
        return "0"
    if abs(value) < 10 ** -(digits - 1) or abs(value) >= 1e4:
        return f"{value:.2e}"
    return f"{value:.{digits}f}"


def _spread(values: Sequence[float]) -> str:
    """Median (min - max) of repeated values; counts print as integers."""
    if not values:
        return "-"
    med, lo, hi = _stats(values)
    counts = all(float(v).is_integer() for v in values)
    show = (lambda v: f"{v:.1f}" if not float(v).is_integer() else str(int(v))) if counts else _fmt
    if len(values) == 1:
        return show(med)
    return f"{show(med)} ({show(lo)} - {show(hi)})"


def write_csv(rows: Rows, path: Path) -> None:
    keys: list[str] = []
    for r in rows.rows:
        for k in r:
            if k not in keys:
                keys.append(k)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=keys)
        writer.writeheader()
        for r in rows.rows:
            writer.writerow(r)


def _figures(  # noqa: C901  the study report: one section after another
    out: Path,
    config: StudyConfig,
    rows: Rows,
    t41: dict[str, Any],
    den: dict[str, Any],
    iso: dict[str, Any],
    ss: dict[str, Any],
) -> list[tuple[str, str]]:
    """Draw every PNG; returns (file name, caption) pairs for the report."""
    written: list[tuple[str, str]] = []
    short = {
        "none": "none",
        "rpca-phase": "ch.4",
        "rpca-orders-nopost": "ch.3 no post",
        "rpca-orders": "ch.3 + post",
        "vote": "vote [119]",
        "auto": "auto",
        "oracle": "oracle",
    }

    def save(name: str, image: np.ndarray, caption: str) -> None:
        fig.save_png(out / name, image)
        written.append((name, caption))

    # Fig. 4.3: absolute phase maps and their errors.
    truth = t41["truth"]
    lo, hi = float(np.nanmin(truth)), float(np.nanmax(truth))
    tiles = [("truth", fig.colorize(truth, lo, hi))]
    for key in ("none", "rpca-phase", "rpca-orders-nopost", "rpca-orders", "vote", "auto"):
        tiles.append((short[key], fig.colorize(t41["maps"][key], lo, hi)))
    for key in ("none", "rpca-phase", "rpca-orders-nopost", "rpca-orders", "vote", "auto"):
        err = np.abs(t41["maps"][key] - truth)
        tiles.append((f"|error| {short[key]}", fig.colorize(err, 0.0, 0.5)))
    save(
        "table41_phase_maps.png",
        fig.panel(tiles, 7, "Table 4.1 scene (seed 0): absolute phase at f=8, and |error| (0..0.5 rad)"),
        "Absolute phase of the sphere cap at f2 = 8 after each method (top) and its absolute error, clipped at 0.5 rad (bottom); cf. thesis Fig. 4.3.",
    )
    # Fig. 4.4: cross-section of the heights.
    row = config.size // 2
    x = np.arange(config.size)
    series = [("truth", x, t41["height"][row])]
    for key in ("none", "rpca-phase", "rpca-orders-nopost", "rpca-orders", "vote", "auto"):
        series.append((short[key], x, t41["maps"][f"{key}:height"][row]))
    save(
        "table41_cross_section.png",
        fig.line_plot(
            series, f"Heights on row {row} (seed 0)", "column (px)", "height (mm)", ylim=(-40.0, 140.0), markers=False
        ),
        "Cross-section of the reconstructed heights through the cap's centre, clipped to -40..140 mm; cf. thesis Fig. 4.4.",
    )
    # Figs. 3.6-3.8: t sweep.
    t_vals = list(config.t_values)
    mse_series, err_series = [], []
    for snr in config.sweep_snrs:
        for scene_name in ("hemisphere", "reference"):
            mse = [rows.select("t-sweep", "mse", scene=scene_name, snr_db=snr, t=t) for t in t_vals]
            if not any(mse):
                continue
            errs = [rows.select("t-sweep", "order_errors", scene=scene_name, snr_db=snr, t=t) for t in t_vals]
            label = f"{'hemi' if scene_name == 'hemisphere' else 'ref'} {snr:g} dB"
            mse_series.append((label, t_vals, [m[0] for m in mse]))
            err_series.append((label, t_vals, [max(e[0], 0.5) for e in errs]))
    save(
        "t_sweep_mse.png",
        fig.line_plot(
            mse_series, "Ch. 3 RPCA (no post-processing): phase MSE vs t", "t", "MSE (rad^2)", logx=True, logy=True
        ),
        "Phase MSE (eq. 3.5) after ch. 3 RPCA against t; cf. thesis Fig. 3.6.",
    )
    save(
        "t_sweep_errors.png",
        fig.line_plot(
            err_series, "Residual fringe-order errors vs t (0 drawn at 0.5)", "t", "pixels", logx=True, logy=True
        ),
        "Pixels with a wrong fringe order after ch. 3 RPCA against t; cf. thesis Figs. 3.7 and 3.8.",
    )
    # Fig. 4.5: NMSE vs SNR.
    snr_series = []
    for key in METHODS:
        snr_series.append(
            (
                short[key],
                list(config.snr_values),
                [
                    float(np.median(rows.select("snr-sweep", "nmse_h", method=key, snr_db=s) or [np.nan]))
                    for s in config.snr_values
                ],
            )
        )
    save(
        "nmse_vs_snr.png",
        fig.line_plot(snr_series, "NMSE_h vs SNR (sphere cap, f = 5, 8, 6-step)", "SNR (dB)", "NMSE_h", logy=True),
        "NMSE_h of every method against SNR; cf. thesis Fig. 4.5.",
    )
    # Ch. 2.4 denoising: a fringe row before and after, and the heights.
    if "psp3:frame" in den:
        r = config.size // 2
        cols = np.arange(config.size)
        series = [
            ("noisy", cols, den["psp3:frame"][r]),
            ("RPCA", cols, den["psp3:denoised"][r]),
            ("clean", cols, den["psp3:clean"][r]),
        ]
        save(
            "denoise_cross_section.png",
            fig.line_plot(
                series,
                f"3-step PSP frame 0, row {r}: noisy, RPCA-denoised, noise-free",
                "column (px)",
                "intensity (DN)",
                markers=False,
            ),
            "A row of a noisy fringe image, its RPCA low-rank part and the noise-free image; cf. thesis Fig. 2.5(c).",
        )
    tiles = []
    for case, truth_key in (("psp3", "hemisphere"), ("pair", "pair")):
        top = float(np.max(den[truth_key]))
        for label in ("raw", "rpca-denoised"):
            tiles.append((f"{case} {label}", fig.colorize(den[f"{case}:{label}:height"], -0.1 * top, 1.1 * top)))
    save(
        "denoise_heights.png",
        fig.panel(tiles, 4, "Ch. 2.4: heights without / with RPCA denoising (seed 0)"),
        "Heights of the 3-step hemisphere and the two-frequency double hemisphere, without and with RPCA denoising; cf. thesis Figs. 2.5(e, f) and 2.7(g, h).",
    )
    # Isolated objects.
    truth = iso["truth"]
    lo, hi = float(np.nanmin(truth)), float(np.nanmax(truth))
    tiles = [("truth", fig.colorize(truth, lo, hi))]
    for key in ("none", "rpca-phase", "rpca-orders", "vote", "auto"):
        tiles.append((short[key], fig.colorize(iso["maps"][key], lo, hi)))
    save(
        "isolated_phase_maps.png",
        fig.panel(tiles, 6, "Isolated objects, f = (18, 25), 18 dB: absolute phase at f=25"),
        "Absolute phase of the isolated objects at f2 = 25 after each method; cf. thesis Fig. 4.6.",
    )
    # Single shot.
    tiles = []
    for name, maps in ss.items():
        top = float(np.max(maps["truth"]))
        tiles += [
            (f"{name}: image", fig.grey_image(maps["image"])),
            ("fringe (low rank)", fig.grey_image(maps["fringe"])),
            ("speckle (sparse)", fig.grey_image(maps["speckle"])),
            ("order error", fig.colorize(maps["error"], -2, 2)),
            ("height", fig.colorize(maps["height"], -0.1 * top, 1.1 * top)),
        ]
    save(
        "single_shot.png",
        fig.panel(tiles, 5, "Single shot (seed 0): RPCA separation, order errors (-2..2), heights"),
        "Single-shot speckle-embedded unwrapping: captured image, RPCA fringe and speckle parts, fringe-order error map and heights; cf. thesis Figs. 2.2-2.4.",
    )
    return written


def write_report(out: Path, config: StudyConfig, rows: Rows, figures: list[tuple[str, str]], seconds: float) -> Path:  # noqa: C901  the study report: one section after another
    """The Markdown report with the thesis' numbers beside ours."""
    g = RIG
    lines: list[str] = []
    add = lines.append
    quick = " (quick mode: small images, for tests only)" if config.quick else ""
    add(f"# Reproduction study of the thesis' simulations{quick}")
    add("")
    add(
        "Generated by `rig study" + (" --quick" if config.quick else "") + f" --seeds {config.seeds}` in "
        f"{seconds:.0f} s (Python {platform.python_version()}, numpy {np.__version__}). "
        "Every number is in `study.csv`; figures are the PNG files beside this report."
    )
    add("")
    none_values = rows.select("table-4.1", "nmse_h", method="none")
    none_median = float(np.median(none_values)) if none_values else float("nan")
    add("## The simulated rig (fixed for every experiment)")
    add("")
    add(
        f"- l0 = {g.l0_mm:g} mm, d0 = {g.d0_mm:g} mm, camera view {g.view_mm:g} mm x {g.view_mm:g} mm of the "
        f"reference plane (pixel {g.view_mm / config.size:g} mm at {config.size} px), projector footprint "
        f"{g.margin:g} x the view, so f0 = {g.f0_per_mm:g} cycles/mm for the frequency-{g.f0_frequency} pattern "
        f"(f0 d0 = {g.f0_per_mm * g.d0_mm:g})."
    )
    add(
        "- Noise: additive white Gaussian at the stated SNR (signal power = mean I^2, MATLAB `awgn` 'measured'), "
        "8-bit quantisation, projector intensity 0.5 + 0.5 cos, 200 DN full scale."
    )
    add(
        "- NMSE_h (eq. 2.18) is summed over the pixels lit in both the object and the reference captures "
        "(projector shadows excluded: they have no phase); MSE (eq. 3.5) over the lit pixels."
    )
    add("")
    add(
        "Why these values. The thesis does not state l0, d0 or f0. The errors to correct come from the "
        "noise alone: at 15 dB with 6 steps about 1 % of the pixels of each map get a wrong order from "
        "Ding's (5, 8) look-up, whatever the geometry. How much a wrong order costs in height is "
        "l0 / (f0 d0) per period, so the geometry sets NMSE_h of the uncorrected result. Two constraints "
        "fixed it: (1) eq. 1.15, h = l0 dPhi / (dPhi - 2 pi f0 d0), has a pole at dPhi = 2 pi f0 d0; the "
        "largest phase-difference error two-frequency unwrapping can make is 2 x 2 pi (f2 - 1) = 2 pi x 14 "
        "(object and reference both wrong by 7 orders in opposite directions), so f0 d0 > 14 keeps every "
        "error finite (f0 d0 = 16 here; with d0 = 250 mm one wrong order sends heights to the pole and NMSE_h "
        "to ~500); (2) with the 500 mm view the sphere cap of Table 4.1 (447 mm across) fits, and d0 = 1250 mm "
        f"gives NMSE_h of the uncorrected result {_fmt(none_median)} at 15 dB (Table 4.1 below), the magnitude of the thesis' 0.3893. "
        "The price is a steep triangulation angle (51 degrees): projector shadows beside tall objects."
    )
    add("")

    # Table 4.1
    add("## Table 4.1: sphere cap R = 300 mm, 100 mm high, f = (5, 8), 6-step, 15 dB")
    add("")
    add(
        f"{config.size} x {config.size} pixels, {config.seeds} noise seed(s): median (min - max). "
        "Seconds are for object + reference on this machine (2 shared cores)."
    )
    add("")
    add("| method | thesis NMSE_h | our NMSE_h | wrong orders (object) | seconds |")
    add("| --- | --- | --- | --- | --- |")
    for key, (label, _, _) in METHODS.items():
        thesis = THESIS_TABLE_4_1.get(key)
        add(
            f"| {label} | {_fmt(thesis) if thesis is not None else '-'} | "
            f"{_spread(rows.select('table-4.1', 'nmse_h', method=key))} | "
            f"{_spread(rows.select('table-4.1', 'order_errors', method=key))} | "
            f"{_spread(rows.select('table-4.1', 'seconds', method=key))} |"
        )
    thesis_rank = sorted(THESIS_TABLE_4_1, key=THESIS_TABLE_4_1.__getitem__)
    ours_rank = sorted(THESIS_TABLE_4_1, key=lambda k: np.median(rows.select("table-4.1", "nmse_h", method=k)))
    add("")
    add(
        "Ranking, best first - thesis: "
        + " < ".join(thesis_rank)
        + "; ours: "
        + " < ".join(ours_rank)
        + (" (the same order)." if thesis_rank == ours_rank else ".")
    )
    pixels = rows.select("table-4.1", "pixels", method="-")
    add("")
    add(
        f"Compared pixels per seed: {int(pixels[0]) if pixels else 0}. Ch. 3 uses t = {ORDER_T}; the RPCA runs once "
        "and the post-processing pass is applied to its result for the second column."
    )
    add("")
    add(
        "`auto` (processing.correction.registry.correct_auto): first, with the lower frequencies, measured phase "
        "outside the pattern (below 0 or from 2 pi f on) moves back by the period no lower frequency sees, where the "
        "neighbours do not favour the measured orders (processing.correction.phase_range); then the fringe orders "
        "are pooled over 2-D fringe regions (processing.correction.region_orders): every 4-connected region that no wrapped-phase jump or kink "
        "crosses lies within one fringe and has one order, so it takes the majority of its pixels' orders, voted "
        "per 16 x 16 square and re-voted pixel by pixel over a 9 x 9 window of the region where squares "
        "disagree (a hidden object edge inside the region); then ch. 4's low-rank phase L of that phase (stable "
        "inexact ALM, stopped at a noise level estimated from wrapped second differences; on maps of "
        f"{DECIMATE_FROM} px and more solved on {DECIMATION} x {DECIMATION} block means and interpolated back, "
        "about 40x cheaper, with L's orders not used near blocks where L bends sharply); the pooled orders, "
        "alone and with L's re-derived orders k = round((L - phi) / 2 pi) where L fits the wrapped phase, are "
        "ranked by order breaks (second differences beyond pi; no ground truth), with the earlier guarded "
        "re-derivation as a fallback where pooling leaves more breaks than the measured phase; each blob of "
        "pixels whose order the winner changes keeps the change only if it leaves fewer order breaks on the "
        "blob's edges than the measured orders (as many either way: the measured orders stay and the blob is "
        "reported unresolved); with the lower frequencies' wrapped phases (passed as rig process passes them) "
        "the kept changes are then weighed against them, blob by blob and, in a blob of several order shifts, "
        "shift by shift; after a block solve L is refitted at full resolution "
        "(its factors by least squares on the kept orders' phase, used where they fit it better); each blob of "
        "pixels where L's re-derived orders differ from the kept ones then takes L's orders where they leave at "
        "most half the order breaks on its edges and the lower frequencies do not contradict them, or no more "
        "breaks and the lower frequencies clearly favour them (a blob nothing decides is reported unresolved; "
        "processing.correction.surface_orders), and a pixel a fringe or more off three or four of its "
        "neighbours takes the order more of them support where the lower frequencies fit it no worse "
        "(processing.correction.broken_pixels), and a pixel kept one or two orders off its measured order (or further off, "
        "where the lower frequencies tell the orders apart) goes back to it where it continues the surface of its settled neighbours (better than the kept order continues one, or as well where the phase noise alone tells the two orders apart) and the lower frequencies favour it "
        "(processing.correction.surface_continuation), and an island of pixels whose measured orders do not decide "
        "their kept one, broken off a larger surface all round by a shift of three orders or more the lower "
        "frequencies cannot see, per pixel nor over the island, takes the shift that joins it "
        "(processing.correction.order_islands), and the pixels next to what those two moved are judged again as "
        "broken pixels; finally L, "
        "except "
        "where the result departs from it coherently beyond the noise (3 x 3 mean residual above 4 of its "
        "standard deviations), where one pixel departs beyond 8 standard deviations and breaks with no neighbour "
        "(or, on the edge of a height step, continues more neighbours than it breaks with and keeps the order "
        "temporal unwrapping measured), or where L lies a fringe or more from the kept orders: there the measured "
        "phase with its corrected order is kept. Why: ch. 4 alone "
        "removes order errors and noise on smooth scenes, but a low-rank model fails when errors are dense "
        "(isolated objects); one pixel's temporal order is unreliable there, a region's majority is not. The "
        "oracle column (true orders, measured wrapped phase) is the best any order-only correction (ch. 3, "
        "voting) can do; ch. 4 and auto can beat it because they also smooth the phase noise."
    )
    ch4 = rows.select("table-4.1", "nmse_h", method="rpca-phase")
    auto = rows.select("table-4.1", "nmse_h", method="auto")
    if ch4 and auto:
        add("")
        ratio = float(np.median(auto) / np.median(ch4))
        if ratio > 1.05:
            why = (
                "on this smooth synthetic cap the low-rank phase is nearly exact except along the cap's rim "
                "(the ringing in the ch. 4 error map), where auto falls back to the measured, noisier phase: "
                "it pays a little noise for never replacing measured detail by a low-rank guess."
            )
        elif ratio < 0.95 and config.size >= DECIMATE_FROM:
            why = (
                f"auto solves L on {DECIMATION} x {DECIMATION} block means, which carry 1/{DECIMATION} of the "
                "noise, so stopping at the noise level leaves a cleaner surface, and keeps the measured phase "
                "where the low-rank model departs from it."
            )
        elif ratio < 0.95:
            why = "keeping the measured phase where the low-rank model departs from it pays off here."
        else:
            why = "the two are on par on this smooth scene."
        add(f"Here auto's median NMSE_h is {ratio:.2f} x ch. 4's: {why}")
    add("")

    # Denoising
    add("## Ch. 2.4: RPCA fringe denoising, 15 dB")
    add("")
    add("| experiment | thesis raw | thesis denoised | our raw | our denoised |")
    add("| --- | --- | --- | --- | --- |")
    for case, text in (
        ("psp3-hemisphere", "hemisphere, 3-step PSP, f = 8 (true orders)"),
        ("two-freq-two-hemispheres", "two hemispheres, (5, 8) 6-step, Ding unwrapping"),
    ):
        t_raw, t_den = THESIS_DENOISE[case]
        add(
            f"| {text} | {_fmt(t_raw)} | {_fmt(t_den)} | "
            f"{_spread(rows.select('denoise', 'nmse_h', case=case, method='raw'))} | "
            f"{_spread(rows.select('denoise', 'nmse_h', case=case, method='rpca-denoised'))} |"
        )
    add("")
    errs_raw = rows.select("denoise", "order_errors", case="two-freq-two-hemispheres", method="raw")
    errs_den = rows.select("denoise", "order_errors", case="two-freq-two-hemispheres", method="rpca-denoised")
    add(
        f"Wrong fringe orders of the two-hemisphere object: {_spread(errs_raw)} raw, {_spread(errs_den)} "
        "after denoising. The thesis does not say how it unwrapped the 3-step case; we use the true orders so "
        "that only the phase noise differs. Each frame is denoised on its own (processing.denoise.frames, stable "
        "inexact ALM)."
    )
    add("")

    # t sweep
    add("## Ch. 3.3.2: choice of t (Figs. 3.6-3.8)")
    add("")
    combos = [
        (snr, scene_name)
        for snr in config.sweep_snrs
        for scene_name in (("hemisphere", "reference") if snr == config.sweep_snrs[0] else ("hemisphere",))
    ]
    add(
        f"Hemisphere (and the reference plane at {config.sweep_snrs[0]:g} dB), f = (5, 8), 6-step, "
        f"{config.sweep_size} x {config.sweep_size} pixels, orders at f2 = 8, one seed. Ch. 3 RPCA "
        "(processing.correction.orders, inexact ALM on the objective t ||E||_1 + (1 - t) ||K||_*) without "
        "post-processing, as in the thesis' figures; `errors` counts pixels whose order is wrong, `post` the "
        "same after the monotonicity pass. The thesis finds the best t in 0.032-0.036."
    )
    add("")
    add("| t | " + " | ".join(f"{name[:3]} {snr:g} dB: MSE | errors | post" for snr, name in combos) + " |")
    add("|" + " --- |" * (1 + 3 * len(combos)))
    for t in ["none", *config.t_values]:
        cells = []
        for snr, scene_name in combos:
            mse = rows.select("t-sweep", "mse", scene=scene_name, snr_db=snr, t=t)
            err = rows.select("t-sweep", "order_errors", scene=scene_name, snr_db=snr, t=t)
            post = rows.select("t-sweep", "order_errors_post", scene=scene_name, snr_db=snr, t=t)
            cells += [
                _fmt(mse[0]) if mse else "-",
                str(int(err[0])) if err else "-",
                str(int(post[0])) if post else "-",
            ]
        add(f"| {t} | " + " | ".join(cells) + " |")
    add("")
    best = []
    for snr, scene_name in combos:
        mses = [
            (rows.select("t-sweep", "mse", scene=scene_name, snr_db=snr, t=t) or [np.inf])[0] for t in config.t_values
        ]
        best.append(f"{scene_name} {snr:g} dB: t = {config.t_values[int(np.argmin(mses))]:g}")
    add(
        "Lowest MSE: " + "; ".join(best) + ". The thesis' range 0.032-0.036 is tau = t / (1 - t) = "
        "0.033-0.037 in the usual form, around the standard RPCA weight 1 / sqrt(max(M, N)) = 0.032 of its "
        "1000-pixel maps. Without post-processing the RPCA smooths the fringe boundaries (the misalignments "
        "of the thesis' Fig. 3.5), which the `errors` column counts; the post-processing pass removes them."
    )
    add("")

    # SNR sweep
    add("## Fig. 4.5: NMSE_h against SNR")
    add("")
    add(
        f"Sphere cap, f = (5, 8), 6-step, {config.snr_size} x {config.snr_size} pixels, {config.seeds} seed(s) "
        "per SNR: median (min - max)."
    )
    add("")
    add("| method | " + " | ".join(f"{s:g} dB" for s in config.snr_values) + " |")
    add("|" + " --- |" * (len(config.snr_values) + 1))
    for key, (label, _, _) in METHODS.items():
        cells = [_spread(rows.select("snr-sweep", "nmse_h", method=key, snr_db=s)) for s in config.snr_values]
        add(f"| {label} | " + " | ".join(cells) + " |")
    add("")

    # Isolated
    add("## Ch. 4.3.1: isolated objects, f = (18, 25), 6-step, 18 dB")
    add("")
    add(
        f"mock_devices.scenes.isolated_objects (a block, a cylinder and a cap; the thesis shows two objects), "
        f"{config.size} x {config.size} pixels, heights from f2 = 25 (the thesis shows f1 = 18), "
        f"{config.seeds} seed(s): median (min - max). The thesis gives figures only."
    )
    add("")
    add("| method | NMSE_h | wrong orders (object) | seconds |")
    add("| --- | --- | --- | --- |")
    for key, (label, _, _) in METHODS.items():
        add(
            f"| {label} | {_spread(rows.select('isolated', 'nmse_h', method=key))} | "
            f"{_spread(rows.select('isolated', 'order_errors', method=key))} | "
            f"{_spread(rows.select('isolated', 'seconds', method=key))} |"
        )
    add("")
    wrong = rows.select("isolated", "order_errors", method="none")
    lit = rows.select("isolated", "pixels", method="-")
    if wrong and lit:
        fraction = float(np.median(wrong)) / lit[0]
        scored = {k: np.median(rows.select("isolated", "nmse_h", method=k)) for k in METHODS if k != "oracle"}
        best_key = min(scored, key=scored.__getitem__)
        add(
            f"Before correction {100 * fraction:.0f} % of the compared pixels have a wrong order: Ding's "
            "tolerance at (18, 25) is pi / 43 = 0.073 rad, below the phase noise of 6-step PSP at 18 dB "
            "(about 0.09 rad). "
            + (
                "That is far denser than the sparse errors RPCA is built to separate (its guarantees, for "
                "tau = 1 / sqrt(n), cover a few per cent of randomly placed errors)"
                if fraction > 0.1
                else "RPCA's sparse-error model still holds at this density"
            )
            + f"; the best correction here is {METHODS[best_key][0]} (NMSE_h {_fmt(float(scored[best_key]))})."
        )
        add("")

    # Single shot
    add("## Ch. 2.3: single-shot speckle-embedded unwrapping, 25 dB")
    add("")
    add(
        f"One `speckle-sinusoid` image per scene (frequency {SINGLE_SHOT_FREQUENCY}, 3 x 3-pixel dots, speckle "
        f"gain 0.3), {config.size} x {config.size} pixels, reference phase known (perfect calibration, as in the "
        f"thesis), 27 x 27 NCC windows, {config.seeds} seed(s). The hemisphere has radius "
        f"{SINGLE_SHOT_HEMISPHERE_MM:g} mm: with this rig's 51-degree triangulation a taller one (the scene's "
        "default is a third of the view, 167 mm) shifts its top by 250 mm, beyond the part of the projector "
        "the reference plane shows in the same row, where no reference speckle can match. Exact = the fringe "
        "order equals the truth's; valid = lit and with fringe modulation above half the median."
    )
    add("")
    add(
        "| scene | separation | valid fraction | exact (correlation) | exact (row vote) | exact (+ segment vote) | NMSE_h (row vote) | NMSE_h (+ segment vote) | NMSE_h (right orders) | seconds per shot |"
    )
    add("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name in ("hemisphere", "two-hemispheres"):
        for variant, text in (("rpca", "RPCA"), ("no-separation", "none: composite image, as [104]")):
            sel = {"scene": name, "method": variant}
            secs = rows.select("single-shot", "seconds_total", **sel)
            add(
                f"| {name} | {text} | {_spread(rows.select('single-shot', 'valid_fraction', **sel))} | "
                f"{_spread(rows.select('single-shot', 'exact_correlation', **sel))} | "
                f"{_spread(rows.select('single-shot', 'exact_row_vote', **sel))} | "
                f"{_spread(rows.select('single-shot', 'exact_voted', **sel))} | "
                f"{_spread(rows.select('single-shot', 'nmse_h_row_vote', **sel))} | "
                f"{_spread(rows.select('single-shot', 'nmse_h', **sel))} | "
                f"{_spread(rows.select('single-shot', 'nmse_h_right_orders', **sel))} | "
                f"{_spread(secs) if secs else '-'} |"
            )
    add("")
    effects: list[tuple[str, float]] = []
    for name in ("hemisphere", "two-hemispheres"):
        with_rpca = rows.select("single-shot", "exact_voted", scene=name, method="rpca")
        without = rows.select("single-shot", "exact_voted", scene=name, method="no-separation")
        if with_rpca and without:
            effects.append((name, 100 * float(np.median(with_rpca) - np.median(without))))
    if effects:
        text = ", ".join(f"{name} {gain:+.1f}" for name, gain in effects)
        if all(abs(gain) < 2.0 for _, gain in effects):
            why = (
                "The thesis reports a significant gain; here the composite image correlates almost as well, "
                "because the right candidate also matches the fringe component (the warp aligns the same "
                "projector columns), so the fringes help it as much as they blur the speckle."
            )
        elif all(gain >= 2.0 for _, gain in effects):
            why = "Separation pays, as the thesis reports."
        else:
            why = "The effect depends on the scene."
        add(f"Effect of the RPCA separation on the exact orders after voting, in percentage points: {text}. {why}")
        add("")
    add(
        'The thesis reports this experiment in figures only (reconstructions "with high accuracy"). '
        "Wrong orders concentrate on the steepest slopes and beside shadows, where the fringes leave FTP's band "
        "and the speckle is strongly foreshortened."
    )
    add("")
    add(
        "Beyond the thesis, the segment vote (processing.unwrap.single_shot.vote_fringe_segments): Ding's row vote "
        "pools the correlation orders of one row run, about one 27 x 27 window's worth of evidence, so where "
        "neighbouring windows go wrong together whole runs stay wrong. Every 4-connected region that no "
        "wrapped-phase jump crosses lies within one fringe and has one order (Ding's assumption in 2-D), so it "
        "takes the NCC-weighted majority of its pixels' correlation orders; a region smaller than one window, "
        "or one whose vote would leave more order breaks (neighbours more than pi apart) than the row vote "
        "(a region that leaks into the next fringe where a slope hides a jump), keeps the row vote. "
        "The columns above compare it with the row vote alone on the same images."
    )
    worse = []
    for name in ("hemisphere", "two-hemispheres"):
        for variant, text in (("rpca", "RPCA"), ("no-separation", "no separation")):
            row_vote = rows.select("single-shot", "nmse_h_row_vote", scene=name, method=variant)
            segment = rows.select("single-shot", "nmse_h", scene=name, method=variant)
            if row_vote and segment and np.median(segment) > np.median(row_vote):
                worse.append(
                    f"{name} with {text} ({_fmt(float(np.median(row_vote)))} -> {_fmt(float(np.median(segment)))})"
                )
    if worse:
        add("")
        add(
            "NMSE_h grows with the segment vote on " + ", ".join(worse) + ", although fewer pixels are wrong: where "
            "a whole fringe region's correlation evidence is scattered (no candidate holds even a fifth of its "
            "weight; on the left object of the two hemispheres the true match lies within a fringe of the "
            "reference image's left border, where its windows are cut), the region takes one wrong order throughout instead of a patchwork of "
            "smaller ones, and squared height errors weigh the large offset heavily. No vote over that "
            "evidence can settle such a region."
        )
    add("")

    add("## Beyond these cases: a drawn family")
    add("")
    add(
        "The experiments above fix one rig and a few scenes. How the corrections generalise is measured on "
        "a family of cases drawn from ranges (scene kind, size, frequency set, steps, SNR, bit depth, l0, "
        "signed d0, field of view, seeds), developed on one set of seeds and reported on a held-out set: "
        "[family.md](family.md), from `benchmarks/bench_auto_family.py` (rig.study.family)."
    )
    add("")

    add("## Figures")
    add("")
    for name, caption in figures:
        add(f"![{caption}]({name})")
        add("")
        add(f"*{caption}*")
        add("")
    path = out / "README.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def run_study(config: StudyConfig, out: Path, progress: Progress | None = None) -> Path:
    """Run every experiment and write README.md, study.csv and the PNG figures into ``out``."""
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{out}: cannot create the output directory ({exc.strerror})") from exc
    start = time.perf_counter()

    def report(message: str) -> None:
        text = f"[{time.perf_counter() - start:6.1f} s] {message}"
        log.info(text)
        if progress is not None:
            progress(text)

    rows = Rows()
    with rpca_blas():  # nearly all the study's time is in RPCA solves
        t41 = table_4_1(config, rows, report)
        den = denoising(config, rows, report)
        t_sweep(config, rows, report)
        snr_sweep(config, rows, report)
        iso = isolated(config, rows, report)
        ss = single_shot(config, rows, report)
    figures = _figures(out, config, rows, t41, den, iso, ss)
    write_csv(rows, out / "study.csv")
    path = write_report(out, config, rows, figures, time.perf_counter() - start)
    report(f"report written to {path}")
    return path


def stderr_progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)
