"""Both fringe axes against either alone: depth error on the simulated camera-projector rig.

The scene (mock_devices.stereo_synth's plane with two spheres) is traced through a stereo rig and
rendered with six-step fringes on both axes, (1, 8, 32) across the 912 projector columns and
(1, 6, 24) across the 684 rows (28.5 projector pixels per period on either), 8 bit, seeded noise;
then processed with ``--correction none`` along x, along y and (the default for this capture and
calibration) both. Depth RMS error against the traced truth over the pixels every run measures
without an order slip (more than 5 mm off; slips are counted apart), per seed, and the ratio
both / best single axis (the target: <= 0.75).

Rigs: ``diagonal`` (projector at (107, 113, 10) mm, both axes equally sensitive: the best case,
1/sqrt(2) expected) and ``horizontal`` (the demo rig: 150 mm to the right; the row fringes carry
~30x the depth per projector pixel, so both should equal x alone).

    PYTHONPATH=. python benchmarks/validate_axes.py [--seeds 51 52 53 54 55] [--rig diagonal]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calibration.store import Calibration, write_calibration  # noqa: E402
from mock_devices import synth  # noqa: E402
from mock_devices.stereo_synth import (  # noqa: E402
    aimed_rig,
    calibration_fields,
    demo_rig,
    demo_scene,
    render_frames,
    trace,
)
from rig.pipeline.plan import ProcessOptions  # noqa: E402
from rig.pipeline.run import process  # noqa: E402
from rig.store.capture import write_capture  # noqa: E402

FREQUENCIES = {"x": (1, 8, 32), "y": (1, 6, 24)}
SLIP_MM = 5.0
RIGS = {
    "diagonal": lambda: aimed_rig((107.0, 113.0, 10.0), 320, 256),
    "horizontal": lambda: demo_rig(320, 256),
}


def run_seed(rig_name: str, seed: int, snr_db: float, root: Path) -> dict[str, float]:
    """Depth RMS of x, y and both, and the slips of each, for one seeded capture."""
    rig = RIGS[rig_name]()
    points, mapping = trace(rig, demo_scene())
    patterns = [p for axis, f in FREQUENCIES.items() for p in synth.sinusoid_patterns(f, 6, axis)]
    frames = render_frames(
        rig, mapping, patterns, synth.Appearance(ambient=0.05, snr_db=snr_db), np.random.default_rng(seed)
    )
    projector = {"width": rig.projector.width, "height": rig.projector.height}
    capture = write_capture(root / f"capture-{seed}", frames, patterns, projector).path
    fields = calibration_fields(rig)
    fields.pop("model")
    write_calibration(root / f"calibration-{seed}", Calibration(model="stereo", extra=fields))
    errors = {}
    for axis in ("x", "y", None):
        result = process(capture, root / f"calibration-{seed}", ProcessOptions(correction="none", axis=axis))
        assert result.height is not None
        errors[axis or "both"] = np.where(result.mask & mapping.lit, result.height - points[..., 2], np.nan)
    slip = SLIP_MM if rig_name == "diagonal" else 100.0  # the horizontal rig's y noise is millimetres
    keep = np.logical_and.reduce([np.abs(e) < slip for e in errors.values()])
    out = {name: float(np.sqrt(np.mean(e[keep] ** 2))) for name, e in errors.items()}
    out.update({f"{name} slips": float(np.count_nonzero(np.abs(e) >= slip)) for name, e in errors.items()})
    out["compared"] = float(keep.mean())
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[51, 52, 53, 54, 55])
    parser.add_argument("--rig", choices=sorted(RIGS), default="diagonal")
    parser.add_argument("--snr-db", type=float, default=30.0)
    args = parser.parse_args(argv)
    print(f"rig {args.rig}, 320x256 camera, {args.snr_db} dB, 6 steps, x {FREQUENCIES['x']}, y {FREQUENCIES['y']}")
    print("seed  x RMS mm  y RMS mm  both RMS mm  both/best  slips x/y/both  compared")
    ratios = []
    with tempfile.TemporaryDirectory(prefix="validate-axes-") as workdir:
        for seed in args.seeds:
            r = run_seed(args.rig, seed, args.snr_db, Path(workdir))
            ratio = r["both"] / min(r["x"], r["y"])
            ratios.append(ratio)
            print(
                f"{seed:>4}  {r['x']:>8.4f}  {r['y']:>8.4f}  {r['both']:>11.4f}  {ratio:>9.3f}  "
                f"{r['x slips']:.0f}/{r['y slips']:.0f}/{r['both slips']:.0f}  {r['compared']:.1%}"
            )
    print(f"both / best single axis: median {np.median(ratios):.3f}, max {max(ratios):.3f} over {len(ratios)} seeds")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
