"""Fourier-transform profilometry (Takeda): wrapped phase from a single fringe image.

Along the fringe axis a row ``I = A + B cos(phi)``, ``phi = 2 pi f0 x + phi_obj``, has spectrum
lobes at 0 and +-f0. Keeping only the lobe at +f0 with a band-pass window and transforming back
gives ``(B / 2) exp(i phi)``: its angle is the wrapped phase (carrier included, the same
quantity phase shifting returns) and twice its magnitude the fringe amplitude. All rows are
transformed at once (``scipy.fft.rfft`` along the axis).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import fft as sfft

from processing import _validate

WINDOWS = ("hann", "rect", "tukey")


def _band(frequencies: np.ndarray, carrier: float, half_width: float, window: str) -> np.ndarray:
    """Band-pass weights over ``frequencies`` (cycles/pixel), centred on ``carrier``."""
    offset = np.abs(frequencies - carrier) / half_width  # 0 at the carrier, 1 at the band's edge
    inside = offset < 1.0
    if window == "rect":
        return inside.astype(np.float64)
    if window == "hann":
        return np.where(inside, 0.5 * (1.0 + np.cos(np.pi * offset)), 0.0)
    # tukey (alpha 0.5): flat over the inner half, cosine taper over the outer half
    taper = 0.5 * (1.0 + np.cos(np.pi * (offset - 0.5) / 0.5))
    return np.where(offset <= 0.5, 1.0, np.where(inside, taper, 0.0))


def detect_carrier(image: np.ndarray, axis: int = 1) -> float:
    """Strongest non-DC spatial frequency along ``axis`` in cycles per pixel.

    The magnitude spectra of all lines along ``axis`` (each minus its mean) are summed; the peak
    bin is refined by parabolic interpolation of the log magnitude. Frequencies below two cycles
    per line are ignored (the background's slow variations live there).
    """
    img = _validate.finite_array(image, "image", ndim=2).astype(np.float64, copy=False)
    axis = _check_axis(axis)
    n = img.shape[axis]
    if n < 8:
        raise ValueError(f"image: expected at least 8 pixels along axis {axis}, found {n}")
    lines = img - img.mean(axis=axis, keepdims=True)
    power = np.abs(sfft.rfft(lines, axis=axis)).sum(axis=1 - axis)
    lowest = 2
    peak = lowest + int(np.argmax(power[lowest:]))
    shift = 0.0
    if lowest < peak < power.size - 1:
        left, mid, right = np.log(power[peak - 1 : peak + 2] + 1e-300)
        denominator = left - 2.0 * mid + right
        if denominator < 0:
            shift = 0.5 * (left - right) / denominator
    return (peak + shift) / n


def _check_axis(axis: int) -> int:
    if isinstance(axis, (bool, np.bool_)) or axis not in (0, 1, -1, -2):
        raise ValueError(f"axis: expected 0 (columns) or 1 (rows), found {axis!r}")
    return int(axis) % 2


def ftp_phase(
    image: np.ndarray,
    carrier: float | None = None,
    axis: int = 1,
    bandwidth: float = 0.5,
    window: str = "hann",
) -> tuple[np.ndarray, np.ndarray]:
    """Wrapped phase and fringe amplitude of one fringe image by Fourier-transform profilometry.

    Parameters
    ----------
    image : (H, W) array
        A fringe image I = A + B cos(phi), the phase increasing along ``axis``.
    carrier : float, optional
        Carrier frequency f0 in cycles per pixel along ``axis`` (e.g. fringes / width for a
        fronto-parallel view); a negative value selects the lobe of a phase decreasing along
        the axis. Default: :func:`detect_carrier` (assumes increasing phase).
    axis : int
        1: fringes vary along x (vertical fringes, each row transformed); 0: along y.
    bandwidth : float
        Band half-width as a fraction of |carrier|: the window passes |f - f0| < bandwidth |f0|
        (0.5 keeps f0 / 2 .. 3 f0 / 2, Takeda's classic band). In (0, 1].
    window : str
        Band shape: ``"hann"`` (default; smooth, fewest ringing artefacts), ``"tukey"``
        (flat inner half) or ``"rect"``.

    Returns
    -------
    phase : (H, W) float64 array in [-pi, pi)
        Wrapped phase phi (carrier included).
    amplitude : (H, W) float64 array
        Estimated fringe amplitude B (twice the band-passed magnitude).
    """
    img = _validate.image(image, "image").astype(np.float64, copy=False)
    analytic = _analytic_signal(img, carrier, axis, bandwidth, window)
    phase = np.angle(analytic)
    phase[phase >= np.pi] -= 2.0 * np.pi
    return phase, 2.0 * np.abs(analytic)


def ftp_amplitude(
    image: np.ndarray,
    carrier: float | None = None,
    axis: int = 1,
    bandwidth: float = 0.5,
    window: str = "hann",
) -> np.ndarray:
    """Fringe amplitude B of one fringe image by FTP, in float32, without the phase: a live view's
    modulation map at a fraction of :func:`ftp_phase`'s cost.

    The same band-pass as :func:`ftp_phase` (same parameters), computed in single precision; the
    carrier, when not given, is detected on every fourth line (:func:`detect_carrier`).

    Returns
    -------
    amplitude : (H, W) float32 array
    """
    img = _validate.image(image, "image").astype(np.float32, copy=False)
    if carrier is None:
        axis = _check_axis(axis)
        carrier = detect_carrier(img[::4] if axis == 1 else img[:, ::4], axis)
    analytic = _analytic_signal(img, carrier, axis, bandwidth, window)
    amplitude = np.abs(analytic)
    amplitude *= np.float32(2.0)
    return amplitude


def _analytic_signal(img: np.ndarray, carrier: float | None, axis: int, bandwidth: float, window: str) -> np.ndarray:
    """The band-passed lobe at +carrier transformed back, (B / 2) exp(i phi), in the image's precision."""
    axis = _check_axis(axis)
    if not np.isfinite(img).all():
        raise ValueError("image: contains NaN or infinity; fill invalid pixels first")
    if window not in WINDOWS:
        raise ValueError(f"window: expected one of {', '.join(WINDOWS)}, found {window!r}")
    width = _validate.finite_float(bandwidth, "bandwidth", minimum=0.0, strict=True)
    if width > 1.0:
        raise ValueError(f"bandwidth: expected a fraction in (0, 1], found {bandwidth!r}")
    n = img.shape[axis]
    if carrier is None:
        f0 = detect_carrier(img, axis)
    else:
        f0 = _validate.finite_float(carrier, "carrier")
        if not 0.0 < abs(f0) <= 0.5:
            raise ValueError(f"carrier: expected 0 < |carrier| <= 0.5 cycles per pixel, found {carrier!r}")
    spectrum = sfft.rfft(img, axis=axis)
    band = _band(sfft.rfftfreq(n), abs(f0), width * abs(f0), window).astype(img.dtype, copy=False)
    spectrum *= band if axis == 1 else band[:, None]
    # Inverse of a one-sided spectrum: pad the negative half with zeros and use the complex ifft.
    full = np.zeros(img.shape, dtype=spectrum.dtype)
    index = [slice(None), slice(None)]
    index[axis] = slice(0, spectrum.shape[axis])
    full[tuple(index)] = spectrum
    analytic = sfft.ifft(full, axis=axis)
    return np.conj(analytic) if f0 < 0 else analytic


def fringe_background(fringe: np.ndarray, carrier: float, axis: int = 1) -> np.ndarray:
    """Background A of a fringe image: its mean over one fringe period (``1 / |carrier|`` pixels,
    rounded) along ``axis``, borders reflected; float64 (H, W).

    Parameters
    ----------
    fringe : (H, W) array
        Fringe image I = A + B cos(phi).
    carrier : float
        Carrier in cycles per pixel along ``axis`` (:func:`ftp_phase`); 0 leaves the image as it is.
    axis : int
        1: fringes vary along x; 0: along y.
    """

    axis = _check_axis(axis)
    period = max(int(round(1.0 / abs(carrier))), 1) if carrier else 1
    kernel = (period, 1) if axis == 1 else (1, period)
    return cv2.blur(np.asarray(fringe, dtype=np.float64), kernel, borderType=cv2.BORDER_REFLECT)


@dataclass
class FringeParts:
    """What the height and correction stages need from one FTP-phased fringe image, all (H, W)."""

    phase: np.ndarray  # wrapped phase in [-pi, pi), float64
    amplitude: np.ndarray  # fringe amplitude B, float64
    background: np.ndarray  # mean intensity over one fringe period along the axis, float64
    valid: np.ndarray  # bool: amplitude above ``min_modulation`` times its median


def ftp_fringe_parts(
    fringe: np.ndarray, carrier: float, axis: int = 1, bandwidth: float = 0.5, min_modulation: float = 0.2
) -> FringeParts:
    """Wrapped phase, amplitude, background and modulation mask of a fringe image at a known carrier.

    Parameters
    ----------
    fringe : (H, W) array
        Fringe image (e.g. the fringe part a single shot separated from its speckle).
    carrier : float
        Carrier in cycles per pixel along ``axis`` (:func:`ftp_phase`).
    axis : int
        1: fringes vary along x; 0: along y.
    bandwidth : float
        FTP band half-width as a fraction of the carrier.
    min_modulation : float
        A pixel is valid where its amplitude exceeds this fraction of the median amplitude.
    """
    axis = _check_axis(axis)
    phase, amplitude = ftp_phase(fringe, carrier=carrier, axis=axis, bandwidth=bandwidth)
    amplitude = np.asarray(amplitude, dtype=np.float64)
    background = fringe_background(fringe, carrier, axis)
    valid = amplitude > min_modulation * float(np.median(amplitude))
    return FringeParts(np.asarray(phase, dtype=np.float64), amplitude, background, valid)
