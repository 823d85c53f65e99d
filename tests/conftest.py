"""Shared fixtures: a small synthesised scan written as a capture with its calibration."""

from __future__ import annotations

from pathlib import Path

import pytest

from rig.simulation import SimulatedPaths, SimulatedScan, demo_geometry, simulate_scan, write_simulated_scan

pytest_plugins = ["conftest_devices"]  # the --device option for hardware contract tests

# Small enough to keep every test quick, large enough for three-frequency unwrapping to be meaningful.
SMALL_WIDTH, SMALL_HEIGHT = 160, 120


@pytest.fixture(scope="session")
def small_scan() -> SimulatedScan:
    """A hemisphere scanned with 4-step sinusoids at frequencies 1, 8 and 64 (seeded, 35 dB SNR)."""
    return simulate_scan("hemisphere", geometry=demo_geometry(SMALL_WIDTH, SMALL_HEIGHT), seed=1)


@pytest.fixture
def small_capture(tmp_path: Path, small_scan: SimulatedScan) -> SimulatedPaths:
    """``small_scan`` written to ``tmp_path``: object capture, calibration + reference, truth heights."""
    return write_simulated_scan(small_scan, tmp_path / "scan")
