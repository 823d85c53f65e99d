"""The exposure assistant: a quick pre-capture, a reflectance estimate per pixel, the fewest exposures that do.

At two probe exposures (the configured exposure over 8 and times 2) the rig projects white, black
and three phase shifts of the scan's highest frequency; while more than ``SATURATED_ALLOWANCE`` of
the pixels still clip at the shortest probe, up to two more probes, each 8 times shorter (not
below the camera's shortest exposure). Per pixel, from the longest probe where it is not
saturated:

- white rate r_W = white / t and black rate r_K = black / t (grey levels per microsecond);
- fringe contrast c = 2 B / (white - black) from the three shifts (defocus, subsurface scattering),
  clipped to [0, 1];
- lit: white - black of at least ``LIT_GREY`` grey levels at the longest probe, or saturated there;
  a pixel saturated at every probe is counted lit and never usable (the plan then says so).

A pixel is usable at exposure t when its brightest frame stays under the saturation margin and its
fringe is strong enough to trust its phase::

    r_W t <= SATURATION_MARGIN * top     and     c (r_W - r_K) t / 2 >= MIN_MODULATION * top

(top: the camera's largest grey level). The candidate exposures are a ladder of factors of
sqrt(2) from the configured one (two significant digits), inside the camera's exposure limits and
under half the frame deadline, and those limits themselves. The plan is the fewest candidates (at
most :data:`MAX_EXPOSURES`) whose union of usable pixels covers ``TARGET_COVERAGE`` of the lit
pixels and whose shortest exposure leaves at most ``SATURATED_ALLOWANCE`` more of them saturated
than the shortest candidate does (a saturated pixel has no phase; a dark one a noisier phase);
between plans of as many exposures, the one covering most, then the one nearest the configured
exposure; if no plan reaches the target, the best of the largest size, and the plan says so.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from processing.phase.shifting import sample_stride
from rig.acquisition.loop import AcquisitionSettings, acquire_in_memory
from rig.errors import CaptureError

if TYPE_CHECKING:
    from rig.events import ProgressSink
    from rig.hardware.assembly import RigDevices

TARGET_COVERAGE = 0.98
MAX_EXPOSURES = 3
SATURATION_MARGIN = 0.9  # the brightest frame under 90 % of the top grey level: noise does not clip it
MIN_MODULATION = 0.1  # fringe amplitude B of at least a tenth of the range: well above the modulation mask
SATURATED_ALLOWANCE = 0.001  # lit pixels the shortest exposure may leave saturated (hot pixels, glints)
LIT_GREY = 3.0  # white - black at the longer probe: below this a pixel is not lit by the projector
PROBE_FACTORS = (0.125, 2.0)  # the probe exposures, times the configured exposure
EXTRA_PROBES = 2  # shorter probes (each 1/8 of the last) while highlights still clip
LADDER_STEP = math.sqrt(2.0)
LADDER_SPAN = 12  # candidates from 1/64 to 64 times the configured exposure
SAMPLES = 20_000  # pixels the choice is made on (a regular subsample)


@dataclass
class ExposurePlan:
    """What the assistant chose and why."""

    exposures_us: tuple[float, ...]
    coverage: float  # predicted share of the lit pixels usable at one of the exposures at least
    lit_fraction: float  # share of the camera's pixels the projector lights
    each: list[dict[str, float]] = field(default_factory=list)  # per exposure: usable share, share only it gives
    single: dict[str, float] = field(default_factory=dict)  # the configured exposure alone: its coverage
    limits_us: tuple[float, float] = (0.0, math.inf)
    probes_us: tuple[float, ...] = ()
    reached: bool = True

    def lines(self) -> list[str]:
        """The plan in a few lines for a person: the exposures, the coverage, why each one."""
        chosen = ", ".join(f"{e:g}" for e in self.exposures_us)
        head = (
            f"exposures {chosen} us: {100 * self.coverage:.1f} % of the lit pixels predicted usable "
            f"(target {100 * TARGET_COVERAGE:g} %; {self.single['exposure_us']:g} us alone: "
            f"{100 * self.single['coverage']:.1f} %)"
        )
        out = [head]
        for entry in self.each:
            out.append(
                f"  {entry['exposure_us']:g} us: usable on {100 * entry['usable']:.1f} %, "
                f"the only usable one for {100 * entry['only']:.1f} %"
            )
        if not self.reached:
            out.append(
                f"  target not reached with {MAX_EXPOSURES} exposures inside the camera's limits "
                f"{self.limits_us[0]:g} .. {self.limits_us[1]:g} us: the rest is too dark at the longest "
                "or saturated at the shortest"
            )
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (capture.json's ``exposure_plan``, the console)."""
        return {
            "exposures_us": list(self.exposures_us),
            "coverage": round(self.coverage, 4),
            "lit_fraction": round(self.lit_fraction, 4),
            "each": self.each,
            "single": self.single,
            "limits_us": [self.limits_us[0], self.limits_us[1] if math.isfinite(self.limits_us[1]) else None],
            "probes_us": list(self.probes_us),
            "target": TARGET_COVERAGE,
            "reached": self.reached,
            "lines": self.lines(),
        }


@dataclass
class Reflectance:
    """Per sampled pixel: white and black rates (grey per microsecond), fringe contrast, lit."""

    white_rate: np.ndarray
    black_rate: np.ndarray
    contrast: np.ndarray
    lit: np.ndarray


def estimate_reflectance(probes: Sequence[tuple[float, np.ndarray]], top: float, steps: int = 3) -> Reflectance:
    """Reflectance of each pixel from the probe captures ``(exposure_us, frames)``, shortest exposure first.

    ``frames`` (2 + ``steps``, P): white, black, then ``steps`` uniform phase shifts. The longest
    probe whose frames stay under the saturation margin speaks for each pixel; a pixel saturated at
    every probe gets an infinite white rate (usable at no exposure).
    """
    limit = SATURATION_MARGIN * top
    frames = np.asarray(probes[0][1], dtype=np.float64)
    times = np.full(frames.shape[1], probes[0][0])
    clear = np.all(frames < limit, axis=0)
    for exposure, data in probes[1:]:  # longer probes replace shorter ones where they do not clip
        data = np.asarray(data, dtype=np.float64)
        ok = np.all(data < limit, axis=0)
        frames = np.where(ok, data, frames)
        times = np.where(ok, exposure, times)
        clear |= ok
    white, black, fringe = frames[0], frames[1], frames[2:]
    delta = 2.0 * np.pi * np.arange(steps) / steps
    amplitude = (
        2.0 / steps * np.hypot(np.tensordot(np.sin(delta), fringe, axes=1), np.tensordot(np.cos(delta), fringe, axes=1))
    )
    span = white - black
    with np.errstate(divide="ignore", invalid="ignore"):
        contrast = np.clip(np.where(span > 0, 2.0 * amplitude / span, 0.0), 0.0, 1.0)
    longest = np.asarray(probes[-1][1], dtype=np.float64)
    lit = (longest[0] - longest[1] >= LIT_GREY) | ~np.all(longest < limit, axis=0)
    white_rate = np.where(clear, white / times, np.inf)
    return Reflectance(white_rate, black / times, contrast, lit)


def saturated_share(probe: np.ndarray, top: float) -> float:
    """Share of a probe's pixels whose white frame reaches the saturation margin."""
    return float(np.mean(np.asarray(probe)[0] >= SATURATION_MARGIN * top))


def usable(reflectance: Reflectance, exposure_us: float, top: float) -> np.ndarray:
    """Pixels whose frames at ``exposure_us`` stay unsaturated with a fringe strong enough (module docstring)."""
    r = reflectance
    bright_ok = r.white_rate * exposure_us <= SATURATION_MARGIN * top
    strong = r.contrast * (r.white_rate - r.black_rate) * exposure_us / 2.0 >= MIN_MODULATION * top
    return bright_ok & strong & r.lit


def ladder(base_us: float, limits_us: tuple[float, float], longest_us: float) -> list[float]:
    """Candidate exposures: ``base_us`` times powers of sqrt(2), inside the limits and under ``longest_us``."""
    low, high = limits_us[0], min(limits_us[1], longest_us)
    if high < low:
        raise CaptureError(f"exposure limits {low:g} .. {high:g} us: no exposure fits under the frame deadline")
    out = [base_us * LADDER_STEP**k for k in range(-LADDER_SPAN, LADDER_SPAN + 1)]
    return sorted(
        {_two_digits(float(np.clip(e, low, high))) for e in out if low <= _two_digits(e) <= high} | {low, high}
    )


def _two_digits(value: float) -> float:
    """``value`` rounded to two significant digits (7071.07 -> 7100): exposures a person can read and type."""
    return float(round(value, 1 - int(math.floor(math.log10(value)))))


def choose_exposures(
    reflectance: Reflectance, candidates: Sequence[float], top: float, default_us: float
) -> tuple[tuple[float, ...], float, bool]:
    """The fewest candidates (ascending) covering the target share of the lit pixels: (exposures, coverage, reached).

    A plan must also keep all but :data:`SATURATED_ALLOWANCE` of the lit pixels that some candidate
    keeps unsaturated unsaturated at its shortest exposure: a saturated pixel has no phase at all,
    a dark one only a noisier phase.
    """
    lit = reflectance.lit
    total = max(int(np.count_nonzero(lit)), 1)
    table = np.stack([usable(reflectance, e, top) for e in candidates])[:, lit]  # (C, lit pixels)
    unsaturated = [
        np.count_nonzero(reflectance.white_rate[lit] * e <= SATURATION_MARGIN * top) / total for e in candidates
    ]
    reachable = max(unsaturated)  # pixels saturated even at the shortest candidate cannot be helped
    distance = [abs(math.log(e / default_us)) for e in candidates]
    best: tuple[float, float, tuple[int, ...]] = (-1.0, 0.0, ())
    for size in range(1, MAX_EXPOSURES + 1):
        best = (-1.0, 0.0, ())
        for combo in itertools.combinations(range(len(candidates)), size):
            if unsaturated[combo[0]] < reachable - SATURATED_ALLOWANCE:
                continue
            covered = np.count_nonzero(np.any(table[list(combo)], axis=0)) / total
            closeness = -sum(distance[i] for i in combo)  # ties: exposures nearest the configured one
            if (covered, closeness) > best[:2]:
                best = (covered, closeness, combo)
        if best[0] >= TARGET_COVERAGE:
            break
    chosen = tuple(candidates[i] for i in best[2])
    return chosen, float(best[0]), bool(best[0] >= TARGET_COVERAGE)


def probe_patterns(frequency: float, axis: str, steps: int = 3) -> list[dict[str, Any]]:
    """The pre-capture: white, black and ``steps`` shifts of the fringe at ``frequency``."""
    return [
        {"kind": "flat", "level": 1.0},
        {"kind": "flat", "level": 0.0},
        *({"kind": "sinusoid", "axis": axis, "frequency": frequency, "steps": steps, "step": j} for j in range(steps)),
    ]


def capture_probe(
    devices: RigDevices, patterns: Sequence[Mapping[str, Any]], exposure_us: float, settings: AcquisitionSettings
) -> np.ndarray:
    """Frames (N, H, W) of ``patterns`` at ``exposure_us``, in memory (nothing is written)."""
    frames = acquire_in_memory(
        patterns, devices.projector, devices.camera, devices.trigger, settings, exposure_us=exposure_us
    )
    return np.stack([np.asarray(frame.image) for frame in frames])


def plan_exposures(
    devices: RigDevices, progress: ProgressSink | None = None, default_us: float | None = None
) -> ExposurePlan:
    """Pre-capture at two exposures, estimate reflectance, choose the exposures (module docstring).

    ``default_us``: the exposure the operator uses now (default the config's ``[camera] exposure_us``).
    """
    config = devices.config
    camera = devices.camera
    default_us = float(config.camera.exposure_us if default_us is None else default_us)
    settings = AcquisitionSettings(config.scan.show_timeout_s, config.scan.fetch_timeout_s, config.scan.retries)
    limits = camera.exposure_limits_us
    longest = 0.5 * settings.fetch_timeout_s * 1e6  # an exposure must end well inside the frame deadline
    probes_us = tuple(float(np.clip(default_us * f, limits[0], min(limits[1], longest))) for f in PROBE_FACTORS)
    patterns = probe_patterns(max(config.scan.frequencies), config.scan.axis)
    if progress is not None:
        progress.begin(len(probes_us), "exposure assistant: pre-capture")
    probes = []
    for exposure in probes_us:
        probes.append((exposure, _probe(devices, patterns, exposure, settings, progress)))
    top = float(np.iinfo(probes[0][1].dtype).max) if np.issubdtype(probes[0][1].dtype, np.integer) else np.inf
    for _ in range(EXTRA_PROBES):  # highlights still clipped at the short probe: probe shorter
        shortest = probes[0][0]
        if saturated_share(probes[0][1], top) <= SATURATED_ALLOWANCE or shortest <= limits[0]:
            break
        exposure = max(shortest * PROBE_FACTORS[0], limits[0])
        probes.insert(0, (exposure, _probe(devices, patterns, exposure, settings, None)))
    probes_us = tuple(e for e, _ in probes)
    reflectance = estimate_reflectance(probes, top)
    candidates = ladder(default_us, limits, longest)
    chosen, coverage, reached = choose_exposures(reflectance, candidates, top, default_us)
    return summarise(reflectance, chosen, coverage, reached, top, default_us, limits, probes_us)


def _probe(
    devices: RigDevices,
    patterns: Sequence[Mapping[str, Any]],
    exposure: float,
    settings: AcquisitionSettings,
    progress: ProgressSink | None,
) -> np.ndarray:
    """One probe's frames on the regular subsample: (frames, pixels)."""
    frames = capture_probe(devices, patterns, exposure, settings)
    stride = sample_stride(frames.shape[1:], SAMPLES)
    if progress is not None:
        progress.step(f"pre-capture at {exposure:g} us")
    return frames.reshape(len(frames), -1)[:, ::stride]


def summarise(
    reflectance: Reflectance,
    chosen: Sequence[float],
    coverage: float,
    reached: bool,
    top: float,
    default_us: float,
    limits: tuple[float, float],
    probes_us: tuple[float, ...],
) -> ExposurePlan:
    """The plan with each exposure's share and the configured exposure's coverage alone."""
    lit = reflectance.lit
    total = max(int(np.count_nonzero(lit)), 1)
    masks = [usable(reflectance, e, top)[lit] for e in chosen]
    each = []
    for k, exposure in enumerate(chosen):
        others = (
            np.any([m for j, m in enumerate(masks) if j != k], axis=0) if len(masks) > 1 else np.zeros_like(masks[k])
        )
        each.append(
            {
                "exposure_us": float(exposure),
                "usable": round(float(np.count_nonzero(masks[k])) / total, 4),
                "only": round(float(np.count_nonzero(masks[k] & ~others)) / total, 4),
            }
        )
    single = np.count_nonzero(usable(reflectance, default_us, top)[lit]) / total
    return ExposurePlan(
        exposures_us=tuple(float(e) for e in chosen),
        coverage=coverage,
        lit_fraction=float(np.mean(lit)),
        each=each,
        single={"exposure_us": default_us, "coverage": round(float(single), 4)},
        limits_us=(float(limits[0]), float(limits[1])),
        probes_us=tuple(float(e) for e in probes_us),
        reached=bool(reached),
    )
