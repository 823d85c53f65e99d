"""Rig calibration: camera intrinsics, projector gamma, reference plane, l0 / d0 / f0, models."""
