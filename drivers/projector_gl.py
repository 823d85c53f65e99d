"""Pattern rendering with moderngl, and a projector that renders off-screen (headless EGL).

:class:`PatternRenderer` draws any capture-format pattern with the gamma LUT applied in a
fragment shader (``pattern.frag.glsl``) into whatever framebuffer is bound.
:class:`RenderedProjector` is the projector side of it (draw, read back, upload the LUT) for both
the off-screen :class:`GLProjector` here and the on-screen ``WindowProjector``.
"""

from __future__ import annotations

import abc
import contextlib
import ctypes
import json
import logging
import math
from collections import OrderedDict
from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from drivers.errors import DeviceNotFoundError
from drivers.projector import Projector
from processing.projection.patterns import Binary, Flat, Gray, Grid, Pattern, Sinusoid, SpeckleSinusoid
from processing.projection.speckle import speckle_field

log = logging.getLogger(__name__)

SHADER_DIR = Path(__file__).resolve().parent
KIND_CODES = {"sinusoid": 0, "speckle-sinusoid": 1, "gray": 2, "binary": 2, "flat": 3, "grid": 4}
FRAMEBUFFER_DTYPES = {8: "f1", 32: "f4"}  # bits per pixel -> moderngl dtype (f1: normalised 8-bit)


def _shader_source(name: str) -> str:
    return (SHADER_DIR / name).read_text(encoding="utf-8")


class PatternRenderer:
    """Draws patterns of one projector size with a moderngl context into the bound framebuffer.

    Parameters
    ----------
    ctx : moderngl.Context
        An OpenGL >= 3.3 core context (headless EGL or a window's).
    size : (width, height)
        Projector resolution in pixels.
    """

    SPECKLE_CACHE = 4  # speckle textures kept (one per seed / dot size)

    def __init__(self, ctx: Any, size: tuple[int, int]) -> None:
        self.ctx = ctx
        self.size = (int(size[0]), int(size[1]))
        self.program = ctx.program(
            vertex_shader=_shader_source("fullscreen.vert.glsl"),
            fragment_shader=_shader_source("pattern.frag.glsl"),
        )
        self.vao = ctx.vertex_array(self.program, [])
        self._speckle: dict[tuple[int, int], Any] = {}
        self._lut_texture: Any | None = None
        self._blank = self._texture(np.zeros((1, 1), dtype=np.float32))
        self._set("size", self.size)
        self._set("speckle", 0)
        self._set("lut", 1)
        self.set_lut(None)

    def _set(self, name: str, value: Any) -> None:
        if name in self.program:  # the GLSL compiler drops uniforms a shader does not use
            self.program[name].value = value

    def _texture(self, data: np.ndarray) -> Any:
        rows, cols = data.shape
        tex = self.ctx.texture((cols, rows), 1, np.ascontiguousarray(data, dtype=np.float32).tobytes(), dtype="f4")
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        tex.repeat_x = tex.repeat_y = False
        return tex

    def set_lut(self, lut: np.ndarray | None) -> None:
        """Upload a validated gamma LUT (float32 (N,), N >= 2) or None for the identity."""
        if self._lut_texture is not None:
            self._lut_texture.release()
            self._lut_texture = None
        if lut is not None:
            self._lut_texture = self._texture(np.asarray(lut, dtype=np.float32)[None, :])
        self._set("use_lut", lut is not None)
        self._set("lut_size", 2 if lut is None else int(lut.size))

    def _speckle_texture(self, seed: int, dot_px: int) -> Any:
        key = (seed, dot_px)
        if key not in self._speckle:
            if len(self._speckle) >= self.SPECKLE_CACHE:
                self._speckle.pop(next(iter(self._speckle))).release()
            self._speckle[key] = self._texture(speckle_field(self.size[0], self.size[1], seed, dot_px))
        return self._speckle[key]

    def render(self, pattern: Pattern) -> None:
        """Draw ``pattern`` (typed, so valid) over the whole bound framebuffer."""
        self._set("kind", KIND_CODES[pattern.kind])
        self._set("axis", 0 if getattr(pattern, "axis", "x") == "x" else 1)
        speckle = self._blank
        if isinstance(pattern, Sinusoid):
            self._set("frequency", float(pattern.frequency))
            self._set("offset", float(pattern.offset))
            self._set("amplitude", float(pattern.amplitude))
            self._set("phase", math.fmod(pattern.phase_delay, 2.0 * math.pi) % (2.0 * math.pi))
        if isinstance(pattern, SpeckleSinusoid):
            self._set("speckle_gain", float(pattern.speckle_gain))
            speckle = self._speckle_texture(int(pattern.seed), int(pattern.dot_px))
        elif isinstance(pattern, Gray):
            self._set("bits", int(pattern.bits))
            self._set("bit", int(pattern.bit))
            self._set("inverted", bool(pattern.inverted))
            self._set("binary", isinstance(pattern, Binary))
            self._set("period_px", 0.0 if pattern.period_px is None else float(pattern.period_px))
        elif isinstance(pattern, Flat):
            self._set("level", float(pattern.level))
        elif isinstance(pattern, Grid):
            self._set("pitch_px", int(pattern.pitch_px))
            self._set("line_px", int(pattern.line_px))
            self._set("crosshair_px", int(pattern.crosshair_px))
            self._set("level", float(pattern.level))
            self._set("background", float(pattern.background))
        speckle.use(location=0)
        (self._lut_texture or self._blank).use(location=1)
        self.ctx.viewport = (0, 0, *self.size)
        self.vao.render(vertices=3)

    def release(self) -> None:
        """Free the program and textures (with the context current)."""
        for tex in self._speckle.values():
            tex.release()
        self._speckle.clear()
        for obj in (self._lut_texture, self._blank, self.vao, self.program):
            if obj is not None:
                obj.release()
        self._lut_texture = None


def release_egl_thread() -> None:
    """Drop the EGL context glcontext leaves current on this thread after ``release()``.

    Left bound, it makes a later GLX context on the same thread (a glfw window) fail with an X
    BadAccess error, which Xlib answers by exiting the process.
    """
    try:
        egl = ctypes.CDLL("libEGL.so.1")
    except OSError:
        return
    egl.eglReleaseThread()


def read_framebuffer(fbo: Any, size: tuple[int, int], bits: int = 8) -> np.ndarray:
    """Red channel of a framebuffer (8-bit normalised or 32-bit float) as (H, W) float32, row 0 at the top."""
    width, height = size
    if bits == 32:
        data = np.frombuffer(fbo.read(viewport=(0, 0, width, height), components=1, dtype="f4"), dtype=np.float32)
        image = data.reshape(height, width)
    else:
        data = np.frombuffer(fbo.read(viewport=(0, 0, width, height), components=1, alignment=1), dtype=np.uint8)
        image = data.reshape(height, width).astype(np.float32) / 255.0
    return np.ascontiguousarray(image[::-1])


class RenderedProjector(Projector):
    """A projector whose frames a :class:`PatternRenderer` draws in an OpenGL context it owns.

    A backend creates ``_ctx`` and ``_renderer`` in ``_open``, says how its context becomes
    current (:meth:`_current`) and calls :meth:`_draw` from ``_show``; the LUT upload and
    :meth:`last_frame` are shared.
    """

    def __init__(self, size: tuple[int, int], name: str | None = None) -> None:
        super().__init__(size, name)
        self._ctx: Any = None
        self._renderer: PatternRenderer | None = None
        self._frame: np.ndarray | None = None

    @abc.abstractmethod
    def _current(self) -> contextlib.AbstractContextManager[Any]:
        """A context manager that makes the OpenGL context current for the calls inside it."""

    def _draw(self, pattern: Pattern, fbo: Any, bits: int, readback: bool = True) -> None:
        """Render ``pattern`` into ``fbo`` (context current) and, if ``readback``, keep it for last_frame."""
        assert self._renderer is not None
        self._frame = None
        fbo.use()
        self._renderer.render(pattern)
        if readback:
            self._frame = read_framebuffer(fbo, self.size, bits)  # waits for the GPU

    def _set_gamma_lut(self, lut: np.ndarray | None) -> None:
        assert self._renderer is not None
        with self._current():
            self._renderer.set_lut(lut)

    def _last_frame(self) -> np.ndarray | None:
        frame = self._frame
        return None if frame is None else frame.copy()


class GLProjector(RenderedProjector):
    """Renders patterns off-screen at the projector resolution with a headless EGL context.

    What it renders is what a display of the given bit depth would show; :meth:`last_frame` hands
    it back (the simulated camera looks at it). The frame is read back when shown, in the thread
    that owns the OpenGL context, so :meth:`last_frame` never touches OpenGL and may be called
    from any thread (the simulated camera exposes from the trigger box's thread).

    A pattern shown again (with the same gamma LUT) is not drawn again: the frame read back the
    first time is handed back (the last :data:`DRAWN_KEPT` patterns are kept).

    Parameters
    ----------
    size : (width, height)
        Projector resolution.
    bits : {8, 32}
        Framebuffer format: 8-bit like a display (default) or 32-bit float.
    backend : str or None
        moderngl standalone backend, ``"egl"`` (headless, default) or None for the platform default.
    """

    DRAWN_KEPT = 16  # frames read back kept for patterns shown again

    def __init__(
        self, size: tuple[int, int], *, bits: int = 8, backend: str | None = "egl", name: str | None = None
    ) -> None:
        super().__init__(size, name)
        if bits not in FRAMEBUFFER_DTYPES:
            raise ValueError(f"bits: expected one of {tuple(FRAMEBUFFER_DTYPES)}, found {bits!r}")
        self.bits = bits
        self.backend = backend
        self._fbo: Any = None
        # frames already read back, by pattern: reading a framebuffer back costs ~70 ms at 1280x800
        # in software OpenGL, and a live 3-D view shows the same few patterns over and over
        self._drawn: OrderedDict[str, np.ndarray] = OrderedDict()

    def _open(self) -> None:
        kwargs = {"backend": self.backend} if self.backend else {}
        try:
            self._ctx = moderngl.create_standalone_context(require=330, **kwargs)
        except Exception as exc:  # glcontext raises bare Exceptions for missing libraries / displays
            raise DeviceNotFoundError(
                f"{self.name}: no OpenGL 3.3 context (backend {self.backend or 'default'}): {exc}"
            ) from exc
        try:
            with self._ctx:
                colour = self._ctx.renderbuffer(self.size, components=1, dtype=FRAMEBUFFER_DTYPES[self.bits])
                self._fbo = self._ctx.framebuffer(color_attachments=[colour])
                self._renderer = PatternRenderer(self._ctx, self.size)
        except Exception:
            self._release()
            raise

    def _current(self) -> contextlib.AbstractContextManager[Any]:
        # Every GL call runs inside ``with self._ctx``: several projectors (or a window) may be
        # open in one thread, and a standalone context is not made current by moderngl on its own.
        return self._ctx

    def _show(self, pattern: Pattern) -> None:
        assert self._fbo is not None
        key = json.dumps(pattern.to_dict(), sort_keys=True)
        cached = self._drawn.get(key)
        if cached is not None:  # drawn before with the same LUT: the same pixels, without the read-back
            self._drawn.move_to_end(key)
            self._frame = cached
            return
        self._frame = None
        with self._current():
            self._draw(pattern, self._fbo, self.bits)
        if self._frame is not None:
            self._drawn[key] = self._frame
            while len(self._drawn) > self.DRAWN_KEPT:
                self._drawn.popitem(last=False)

    def _set_gamma_lut(self, lut: np.ndarray | None) -> None:
        self._drawn.clear()  # every pattern looks different through another LUT
        super()._set_gamma_lut(lut)

    def _wait(self, timeout_s: float) -> bool:
        return self._frame is not None  # off-screen: shown once drawn and read back

    def _close(self) -> None:
        self._release()

    def _release(self) -> None:
        self._frame = None
        self._drawn.clear()
        if self._ctx is None:
            return
        try:
            with self._ctx:
                if self._renderer is not None:
                    self._renderer.release()
                if self._fbo is not None:
                    for attachment in self._fbo.color_attachments:
                        attachment.release()
                    self._fbo.release()
        finally:
            self._ctx.release()
            self._ctx = self._fbo = self._renderer = None
            if self.backend == "egl":
                release_egl_thread()


__all__ = ["GLProjector", "PatternRenderer", "RenderedProjector", "read_framebuffer", "release_egl_thread"]
