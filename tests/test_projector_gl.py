"""The off-screen moderngl projector against processing.projection.patterns (within 1/255, LUT applied)."""

from __future__ import annotations

import numpy as np
import pytest
from contracts import PATTERNS, SIZE, ProjectorContract, expected_drive, pattern_id

from drivers.errors import DeviceNotFoundError

moderngl = pytest.importorskip("moderngl", reason="moderngl is not installed")

from drivers.projector_gl import GLProjector  # noqa: E402


def _egl_available() -> str | None:
    projector = GLProjector(SIZE)
    try:
        projector.open()
    except DeviceNotFoundError as exc:
        return f"no headless EGL OpenGL 3.3 context: {exc}"
    projector.close()
    return None


EGL_PROBLEM = _egl_available()
pytestmark = pytest.mark.skipif(EGL_PROBLEM is not None, reason=str(EGL_PROBLEM))


class TestGLProjector8Bit(ProjectorContract):
    def make_projector(self, size):
        return GLProjector(size)


class TestGLProjectorFloat(ProjectorContract):
    tolerance = 1e-4  # float32 framebuffer: only float32 cosine error remains

    def make_projector(self, size):
        return GLProjector(size, bits=32)


@pytest.mark.parametrize("pattern", PATTERNS, ids=pattern_id)
def test_8bit_output_is_the_rounded_drive_level(pattern: dict) -> None:
    """An 8-bit framebuffer holds round(255 x) exactly, up to float32 cosine error at .5 ties."""
    expected = expected_drive(pattern, SIZE)
    with GLProjector(SIZE) as projector:
        projector.show(pattern)
        projector.wait_shown()
        levels = projector.last_frame() * 255.0
    assert np.allclose(levels, np.rint(levels), atol=1e-3)  # really 8-bit
    mismatched = np.abs(levels - np.rint(expected * 255.0)) > 0.5
    assert mismatched.mean() < 0.01


def test_full_projector_resolution() -> None:
    """The framebuffer is the projector's resolution (a tall DLP-like 912 x 1140), not the window's."""
    size = (912, 1140)
    pattern = {"kind": "gray", "axis": "y", "bit": 9, "bits": 10}
    with GLProjector(size) as projector:
        projector.show(pattern)
        projector.wait_shown()
        frame = projector.last_frame()
    np.testing.assert_array_equal(frame, expected_drive(pattern, size))


def test_last_frame_follows_the_latest_pattern() -> None:
    with GLProjector(SIZE) as projector:
        projector.show({"kind": "flat", "level": 1.0})
        assert projector.last_frame().min() == 1.0
        projector.show({"kind": "flat", "level": 0.0})
        assert projector.last_frame().max() == 0.0


def test_a_pattern_shown_again_is_the_same_frame_until_the_gamma_lut_changes() -> None:
    """Re-shown patterns come from the frames already read back (issue 24: live 3-D), never stale ones."""
    pattern = {"kind": "sinusoid", "axis": "x", "frequency": 3.0, "steps": 4, "step": 1}
    with GLProjector(SIZE) as projector:
        projector.show(pattern)
        first = projector.last_frame()
        projector.show({"kind": "flat", "level": 1.0})
        projector.show(pattern)
        np.testing.assert_array_equal(projector.last_frame(), first)
        projector.last_frame()[:] = 0.0  # a caller's copy: the kept frame is not touched
        np.testing.assert_array_equal(projector.last_frame(), first)
        lut = np.linspace(0.0, 1.0, 256) ** 2.2
        projector.set_gamma_lut(lut)
        projector.show(pattern)
        expected = expected_drive(pattern, SIZE) ** 2.2
        assert np.abs(projector.last_frame() - expected).max() < 2 / 255


def test_missing_backend_is_device_not_found() -> None:
    projector = GLProjector(SIZE, backend="no-such-backend")
    with pytest.raises(DeviceNotFoundError, match="no-such-backend"):
        projector.open()
    assert not projector.is_open


def test_bad_bit_depth_is_refused() -> None:
    with pytest.raises(ValueError, match="bits"):
        GLProjector(SIZE, bits=16)


def test_open_projectors_do_not_draw_into_each_other() -> None:
    """Each projector makes its own context current: opening a second one must not divert the first."""
    first, second = GLProjector(SIZE), GLProjector((32, 24))
    with first, second:
        first.show({"kind": "flat", "level": 0.5})
        second.show({"kind": "flat", "level": 0.25})
        first.show({"kind": "flat", "level": 1.0})
        assert first.last_frame().shape == (SIZE[1], SIZE[0]) and np.all(first.last_frame() == 1.0)
        assert np.all(second.last_frame() == 64 / 255)
    with first:
        first.show({"kind": "flat", "level": 0.0})
        assert np.all(first.last_frame() == 0.0)


def test_last_frame_is_readable_from_another_thread() -> None:
    """The simulated camera reads frames from the trigger box's thread, where no GL context is current."""
    import threading

    pattern = {"kind": "sinusoid", "axis": "x", "frequency": 3, "steps": 4, "step": 1}
    seen: list[np.ndarray | None] = []
    with GLProjector(SIZE) as projector:
        projector.show(pattern)
        reader = threading.Thread(target=lambda: seen.append(projector.last_frame()))
        reader.start()
        reader.join()
    np.testing.assert_allclose(seen[0], expected_drive(pattern, SIZE), atol=1 / 255)
