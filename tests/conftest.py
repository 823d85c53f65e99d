"""Shared fixtures: a small synthesised scan written as a capture with its calibration; the
simulated rig's config text and its exact calibration for `rig scan` tests."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from console_client import console, console_rig_toml  # noqa: F401 - fixtures of the console tests

from rig.hardware.synthesis import SimulatedPaths, SimulatedScan, demo_geometry, simulate_scan, write_simulated_scan

pytest_plugins = ["conftest_devices"]  # the --device option for hardware contract tests

# Small enough to keep every test quick, large enough for three-frequency unwrapping to be meaningful.
SMALL_WIDTH, SMALL_HEIGHT = 160, 120


@pytest.fixture(autouse=True, scope="session")
def _private_processing_cache(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The processing cache of this test session lives in its own folder, not the user's."""
    import os

    os.environ["RIG_CACHE_DIR"] = str(tmp_path_factory.mktemp("rig-cache"))


@pytest.fixture(scope="session")
def small_scan() -> SimulatedScan:
    """A hemisphere scanned with 4-step sinusoids at frequencies 1, 8 and 64 (seeded, 35 dB SNR)."""
    return simulate_scan("hemisphere", geometry=demo_geometry(SMALL_WIDTH, SMALL_HEIGHT), seed=1)


@pytest.fixture
def small_capture(tmp_path: Path, small_scan: SimulatedScan) -> SimulatedPaths:
    """``small_scan`` written to ``tmp_path``: object capture, calibration + reference, truth heights."""
    return write_simulated_scan(small_scan, tmp_path / "scan")


def _simulated_rig_toml(
    projector: tuple[int, int], camera: tuple[int, int], snr_db: float, gamma: float | None = None
) -> str:
    text = (
        f"\n[projector]\nsize = [{projector[0]}, {projector[1]}]\n[camera]\nsize = [{camera[0]}, {camera[1]}]\n"
        '[scan]\nfrequencies = [1, 8, 32]\nsteps = 4\n[simulation]\nscene = "hemisphere"\n'
        f"snr_db = {snr_db:g}\n"
    )
    return text if gamma is None else text + f"gamma = {gamma:g}\n"


@pytest.fixture(scope="session")
def simulated_rig_toml() -> Callable[..., str]:
    """Rig config text of the simulated rig: ``(projector WxH, camera WxH, snr_db, gamma=None)``.

    Frequencies 1, 8, 32 with 4 steps, the hemisphere scene; ``[simulation]`` is the last table,
    so keys appended to the text land there.
    """
    return _simulated_rig_toml


@pytest.fixture(scope="session")
def exact_calibration() -> Callable[[Path, Path], Path]:
    """``(config_path, directory)``: `rig scan` the reference plane into ``directory/reference`` and
    write the simulated rig's exact geometry as the calibration there (what `rig calibrate` estimates)."""
    from calibration.store import write_calibration
    from rig.cli import main
    from rig.config import load_config
    from rig.hardware.simulated import geometry_from_config
    from rig.hardware.synthesis import exact_calibration as exact

    def calibrate(config_path: Path, directory: Path) -> Path:
        geometry = geometry_from_config(load_config(config_path))
        assert (
            main(["scan", "--config", str(config_path), "--scene", "reference", "-o", str(directory / "reference")])
            == 0
        )
        write_calibration(directory, exact(geometry))
        return directory

    return calibrate
