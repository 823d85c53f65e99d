"""A projector that is a display: a borderless full-screen window on a chosen monitor (optional
extra ``display``: glfw).

Patterns are drawn by the same shader as the off-screen projector (:class:`PatternRenderer`) into
the window's back buffer, read back (glReadPixels) so :meth:`last_frame` is exactly what goes on
screen, then swapped in with vsync. The window uses the monitor's current video mode ("windowed
full screen"): the projector's resolution must be the monitor's mode.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from typing import Any

import moderngl

from drivers.errors import DeviceError, DeviceNotFoundError, UnsupportedFeatureError
from drivers.projector_gl import PatternRenderer, RenderedProjector, release_egl_thread
from processing.projection.patterns import Pattern

log = logging.getLogger(__name__)


def _glfw() -> Any:
    try:
        import glfw
    except ImportError as exc:
        raise DeviceNotFoundError("glfw is not installed (pip install 'fpp-rig[display]')") from exc
    return glfw


class WindowProjector(RenderedProjector):
    """Full-screen window on monitor ``monitor`` (glfw's order; 0 is the primary).

    Parameters
    ----------
    size : (width, height)
        Projector resolution; must equal the monitor's current video mode.
    monitor : int
        Index into the connected monitors.
    vsync : bool
        Swap on vertical blank (swap interval 1).
    readback : bool
        Read each frame back before swapping, for :meth:`last_frame` (costs one glReadPixels).
    """

    def __init__(
        self,
        size: tuple[int, int],
        *,
        monitor: int = 0,
        vsync: bool = True,
        readback: bool = True,
        name: str | None = None,
    ) -> None:
        super().__init__(size, name or f"display projector (monitor {monitor})")
        self.monitor = int(monitor)
        self.vsync = vsync
        self.readback = readback
        self._window: Any = None

    def _open(self) -> None:
        glfw = _glfw()
        # An EGL context left current on this thread (a released standalone moderngl context)
        # makes the GLX MakeCurrent below fail with BadAccess, and Xlib then exits the process.
        release_egl_thread()
        if not glfw.init():
            raise DeviceNotFoundError(f"{self.name}: glfw cannot start (no display? check $DISPLAY)")
        try:
            self._create_window(glfw)
        except BaseException:
            self._release(glfw)
            raise

    def _create_window(self, glfw: Any) -> None:
        monitors = glfw.get_monitors() or []
        if not 0 <= self.monitor < len(monitors):
            raise DeviceNotFoundError(f"{self.name}: monitor {self.monitor} not found ({len(monitors)} connected)")
        monitor = monitors[self.monitor]
        mode = glfw.get_video_mode(monitor)
        if (mode.size.width, mode.size.height) != self.size:
            raise UnsupportedFeatureError(
                f"{self.name}: monitor {self.monitor} runs at {mode.size.width}x{mode.size.height}, "
                f"projector size is {self.size[0]}x{self.size[1]}; set the display mode or the projector size"
            )
        hints = {
            glfw.CONTEXT_VERSION_MAJOR: 3,
            glfw.CONTEXT_VERSION_MINOR: 3,
            glfw.OPENGL_PROFILE: glfw.OPENGL_CORE_PROFILE,
            glfw.OPENGL_FORWARD_COMPAT: True,
            glfw.RED_BITS: mode.bits.red,  # the current mode's depth and rate: no mode switch
            glfw.GREEN_BITS: mode.bits.green,
            glfw.BLUE_BITS: mode.bits.blue,
            glfw.REFRESH_RATE: mode.refresh_rate,
            glfw.DECORATED: False,
            glfw.AUTO_ICONIFY: False,
        }
        glfw.default_window_hints()
        for hint, value in hints.items():
            glfw.window_hint(hint, value)
        self._window = glfw.create_window(*self.size, self.name, monitor, None)
        if not self._window:
            raise DeviceNotFoundError(f"{self.name}: no OpenGL 3.3 window on monitor {self.monitor}")
        glfw.make_context_current(self._window)
        glfw.swap_interval(1 if self.vsync else 0)
        glfw.set_input_mode(self._window, glfw.CURSOR, glfw.CURSOR_HIDDEN)
        self._ctx = moderngl.create_context(require=330)
        found = tuple(glfw.get_framebuffer_size(self._window))
        if found != self.size:
            raise UnsupportedFeatureError(f"{self.name}: window framebuffer is {found}, expected {self.size}")
        self._renderer = PatternRenderer(self._ctx, self.size)
        log.info("%s: %s on %s", self.name, self._ctx.info["GL_RENDERER"], glfw.get_monitor_name(monitor))

    @contextlib.contextmanager
    def _current(self) -> Iterator[None]:
        _glfw().make_context_current(self._window)
        yield

    def _show(self, pattern: Pattern) -> None:
        glfw = _glfw()
        with self._current():
            self._draw(pattern, self._ctx.screen, 8, readback=self.readback)
        glfw.swap_buffers(self._window)
        glfw.poll_events()
        if glfw.window_should_close(self._window):
            raise DeviceError(f"{self.name}: the window was closed")

    def _wait(self, timeout_s: float) -> bool:
        self._ctx.finish()  # after the swap: returns once the frame was handed to the display
        return True

    def _close(self) -> None:
        self._release(_glfw())

    def _release(self, glfw: Any) -> None:
        self._frame = None
        try:
            if self._window:
                glfw.make_context_current(self._window)
            if self._renderer is not None:
                self._renderer.release()
            if self._ctx is not None:
                self._ctx.release()
        finally:
            if self._window:
                glfw.make_context_current(None)
                glfw.destroy_window(self._window)
            self._window = self._ctx = self._renderer = None
            glfw.terminate()
