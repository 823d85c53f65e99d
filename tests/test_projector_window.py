"""WindowProjector on an Xvfb display: the contract, and what really is on the X screen.

Xvfb keeps its screen in an XWD file (``-fbdir``), so the test reads the pixels the X server
shows, independently of OpenGL. Skips with a reason when Xvfb or glfw is missing.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from contracts import PATTERNS, SIZE, ProjectorContract, expected_drive, pattern_id

from drivers.errors import DeviceNotFoundError, UnsupportedFeatureError

glfw = pytest.importorskip("glfw", reason="glfw is not installed (optional extra 'display')")
if shutil.which("Xvfb") is None:
    pytest.skip("Xvfb is not installed (apt-get install xvfb)", allow_module_level=True)

from drivers.projector_window import WindowProjector  # noqa: E402


def read_xwd(path: Path) -> np.ndarray:
    """The screen of an Xvfb ``-fbdir`` XWD file as (H, W, 3) uint8 RGB (32-bit TrueColor)."""
    data = path.read_bytes()
    header = np.frombuffer(data[:100], dtype=">u4")
    header_size, width, height = int(header[0]), int(header[4]), int(header[5])
    byte_order, bits_per_pixel, bytes_per_line, ncolors = (
        int(header[7]),
        int(header[11]),
        int(header[12]),
        int(header[19]),
    )
    assert bits_per_pixel == 32, f"expected a 32-bit screen, found {bits_per_pixel}"
    start = header_size + 12 * ncolors
    pixels = np.frombuffer(data[start : start + bytes_per_line * height], dtype=np.uint8).reshape(
        height, bytes_per_line
    )
    pixels = pixels[:, : 4 * width].reshape(height, width, 4)
    return pixels[..., [2, 1, 0]] if byte_order == 0 else pixels[..., [1, 2, 3]]  # LSBFirst: B G R x


def _die_with_parent() -> None:
    """In the Xvfb child: get SIGTERM when the test process dies, even if it never tears down."""
    try:
        ctypes.CDLL("libc.so.6").prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


@pytest.fixture(scope="module")
def xvfb(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """An Xvfb server with one SIZE screen; yields the file holding its screen pixels."""
    fbdir = tmp_path_factory.mktemp("xvfb")
    read_fd, write_fd = os.pipe()
    # -displayfd: a free display number, written once the server accepts clients;
    # -noreset: otherwise the server resets when a projector closes and refuses the next one.
    server = subprocess.Popen(
        [
            "Xvfb",
            "-displayfd",
            str(write_fd),
            "-screen",
            "0",
            f"{SIZE[0]}x{SIZE[1]}x24",
            "-fbdir",
            str(fbdir),
            "-nolisten",
            "tcp",
            "-noreset",
        ],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        preexec_fn=_die_with_parent,
    )
    os.close(write_fd)
    try:
        with os.fdopen(read_fd) as pipe:
            display = pipe.readline().strip()
        if not display:
            pytest.skip("Xvfb did not start")
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv("DISPLAY", f":{display}")
            patch.delenv("WAYLAND_DISPLAY", raising=False)
            yield fbdir / "Xvfb_screen0"
    finally:
        server.terminate()
        server.wait(timeout=10)


class TestWindowProjector(ProjectorContract):
    @pytest.fixture(autouse=True)
    def _display(self, xvfb: Path) -> None:
        self.screen = xvfb

    def make_projector(self, size):
        return WindowProjector(size)


@pytest.mark.parametrize("pattern", [PATTERNS[0], PATTERNS[1], PATTERNS[4], PATTERNS[-1]], ids=pattern_id)
def test_the_x_screen_shows_the_pattern(xvfb: Path, pattern: dict) -> None:
    lut = np.linspace(0.0, 1.0, 256) ** (1.0 / 2.2)
    expected = expected_drive(pattern, SIZE, lut)
    with WindowProjector(SIZE) as projector:
        projector.set_gamma_lut(lut)
        projector.show(pattern)
        projector.wait_shown()
        screen = read_xwd(xvfb).astype(np.float32) / 255.0
        assert np.array_equal(projector.last_frame(), screen[..., 0])
    assert screen.shape == (SIZE[1], SIZE[0], 3)
    np.testing.assert_array_equal(screen[..., 0], screen[..., 1])  # grey: all channels alike
    np.testing.assert_allclose(screen[..., 0], expected, atol=1.0 / 255.0, rtol=0)


def test_size_must_match_the_monitor_mode(xvfb: Path) -> None:
    projector = WindowProjector((SIZE[0] * 2, SIZE[1]))
    with pytest.raises(UnsupportedFeatureError, match=f"{SIZE[0]}x{SIZE[1]}"):
        projector.open()
    assert not projector.is_open


def test_missing_monitor_is_device_not_found(xvfb: Path) -> None:
    with pytest.raises(DeviceNotFoundError, match="monitor 3 not found"):
        WindowProjector(SIZE, monitor=3).open()


def test_opens_after_a_released_standalone_egl_context(xvfb: Path) -> None:
    """Regression: glcontext leaves a released EGL context current; the GLX window then hit an X
    BadAccess and Xlib exited the whole test process."""
    moderngl = pytest.importorskip("moderngl")
    try:
        moderngl.create_standalone_context(backend="egl").release()
    except Exception as exc:  # glcontext reports a missing libEGL as a bare Exception
        pytest.skip(f"no EGL: {exc}")
    with WindowProjector(SIZE) as projector:
        projector.show({"kind": "flat", "level": 1.0})
        projector.wait_shown()
        assert np.all(projector.last_frame() == 1.0)
