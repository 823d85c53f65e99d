"""The validity rules compared: how much of dim surfaces each keeps, and how good what it keeps is.

Real captures (``../shared/real-data``, skipped when absent): SLMaster's eye (12-step f = 32 and
Gray code, its stereo calibration), SLMaster's heterodyne David (4-step 64/58/53) and fpp-tools'
lens (4-step, spatial unwrapping). Per capture and rule: the share of the pixels whose fringe
modulation B (highest frequency) lies in 10-20, 20-30 and >= 30 grey levels that end valid, and
the share of all pixels valid. Rules: ``ratio`` (``--min-modulation 0.2``, the former default) and
``noise`` (the default, ``--max-phase-sigma 0.1``).

Simulated dark flat target: a plane, half of it at reflectivity 1 (B ~ 100), half at 0.12 (B ~ 12),
six-step fringes at 1, 8, 64, 8 bit, ``--correction none``: measured share and plane RMS error of
each half against the truth and against the predicted sigma.

    PYTHONPATH=. python benchmarks/validate_validity.py [--seeds 61 62]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mock_devices import synth  # noqa: E402
from processing.phase.shifting import phase_shift  # noqa: E402
from rig.cli import main as rig_main  # noqa: E402
from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan  # noqa: E402
from rig.pipeline.plan import ProcessOptions, group_patterns  # noqa: E402
from rig.pipeline.run import process  # noqa: E402
from rig.store.capture import read_capture  # noqa: E402

REAL_DATA = Path(__file__).resolve().parents[2] / "shared" / "real-data"
RULES = {"ratio": ProcessOptions(min_modulation_ratio=0.2), "noise": ProcessOptions()}
BANDS = ((10.0, 20.0), (20.0, 30.0), (30.0, np.inf))


def import_real(root: Path) -> dict[str, tuple[Path, Path | None]]:
    """The real captures imported into ``root``: name -> (capture, calibration or None)."""
    eye = REAL_DATA / "slmaster-eye"
    steps = [
        ["calibrate", "--import-opencv", str(eye / "caliInfo.yml"), "--projector-size", "1920x1024"]
        + ["--pixel-centre", "0", "-o", str(root / "eye-cal")],
        ["import", str(eye / "L"), "--patterns", "sin:f=32,steps=12,phase=pi; gray:bits=6"]
        + ["--projector-width", "1920", "-o", str(root / "eye")],
        ["import", str(REAL_DATA / "slmaster-david-heterodyne"), "--patterns", "sin:f=64/58/53,steps=4,phase=pi"]
        + ["--projector-width", "1920", "-o", str(root / "david")],
        ["import", str(REAL_DATA / "fpp-tools-lens"), "--patterns", "sin:f=36,shifts=0/90/180/270deg"]
        + ["--glob", "lens_crop_*.jpg", "-o", str(root / "lens")],
    ]
    with contextlib.redirect_stderr(io.StringIO()):
        for argv in steps:
            assert rig_main(argv) == 0, argv
    return {
        "slmaster-eye": (root / "eye", root / "eye-cal"),
        "david": (root / "david", None),
        "lens": (root / "lens", None),
    }


def highest_modulation(capture_path: Path) -> np.ndarray:
    """Fringe modulation B of the capture's highest-frequency phase-shifted set (grey levels)."""
    capture = read_capture(capture_path)
    groups = group_patterns(capture.pattern_models, str(capture.manifest_path))
    top = groups.along(groups.sinusoids[0].axis)[-1]
    frames = capture.load_frames()[top.indices].astype(np.float64)
    return phase_shift(frames, shifts=np.asarray(top.shifts)).modulation


def real_rows(root: Path) -> list[str]:
    lines = []
    for name, (capture, calibration) in import_real(root).items():
        modulation = highest_modulation(capture)
        for rule, options in RULES.items():
            mask = process(capture, calibration, options).mask
            shares = []
            for low, high in BANDS:
                band = (modulation >= low) & (modulation < high)
                shares.append(f"{np.count_nonzero(mask & band) / max(1, np.count_nonzero(band)):.1%}")
            lines.append(
                f"{name:<13} {rule:<6} B 10-20: {shares[0]:>6}  20-30: {shares[1]:>6}  >=30: {shares[2]:>6}  valid {mask.mean():.2%}"
            )
    return lines


def dark_target(seed: int, root: Path) -> list[str]:
    reflectivity = np.ones((240, 320))
    reflectivity[:, 160:] = 0.12
    appearance = synth.Appearance(reflectivity=reflectivity, ambient=0.1, gain=200.0, snr_db=35.0)
    scan = simulate_scan(
        "flat",
        geometry=demo_geometry(320, 240),
        patterns=synth.sinusoid_patterns((1, 8, 64), 6),
        appearance=appearance,
        seed=seed,
    )
    paths = write_simulated_scan(scan, root / f"dark-{seed}")
    modulation = phase_shift(scan.object_frames[12:18].astype(np.float64)).modulation
    lines = []
    for rule, options in RULES.items():
        result = process(paths.capture, paths.calibration, ProcessOptions(**{**options.__dict__, "correction": "none"}))
        for half, cols in (("bright", slice(0, 160)), ("dark", slice(160, 320))):
            lit = scan.lit[:, cols]
            kept = result.mask[:, cols] & lit
            measured = np.count_nonzero(kept) / np.count_nonzero(lit)
            text = f"seed {seed} {rule:<6} {half:<6} B {np.median(modulation[:, cols]):5.1f}  measured {measured:6.1%}"
            if kept.any():
                assert result.height is not None and result.uncertainty is not None
                error = (result.height - scan.height_mm)[:, cols][kept]
                predicted = float(np.median(result.uncertainty[:, cols][kept]))
                text += f"  plane RMS {np.sqrt(np.mean(error**2)):.3f} mm (predicted sigma {predicted:.3f} mm)"
            lines.append(text)
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[61, 62])
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="validate-validity-") as workdir:
        root = Path(workdir)
        print("simulated dark flat target (320x240, 1/8/64 x 6 steps, 8 bit, 35 dB):")
        for seed in args.seeds:
            for line in dark_target(seed, root):
                print(line)
        if not REAL_DATA.is_dir():
            print(f"real captures: not present at {REAL_DATA}; skipped")
            return 0
        print("real captures: share of pixels valid by modulation band of the highest frequency")
        for line in real_rows(root):
            print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
