"""Fringe image denoising by RPCA (thesis ch. 2.4).

A captured fringe image is I = I_f + W + Q: the clean fringe pattern (low rank: a few singular
values carry it, thesis Fig. 2.1), sparse strong impulsive noise W (speckle, saturated or dead
pixels) and small dense noise Q. RPCA keeps the low-rank part I_f; phase shifting then runs on the
denoised frames. Each frame is processed on its own, as in the thesis.

The solver is the inexact ALM of :func:`processing.denoise.rpca.rpca_ialm`, by default in its stable form
(stop when the residual reaches the noise level), which leaves the dense noise Q out of I_f.
"""

from __future__ import annotations

import logging

import numpy as np

from processing import _validate
from processing.denoise.rpca import RPCAResult, rpca_ialm

log = logging.getLogger(__name__)


def rpca_denoise_frame(
    image: np.ndarray,
    tau: float | None = None,
    stable: bool = True,
    svd: str = "auto",
    tol: float = 1e-7,
    noise_sigma: float | None = None,
    dtype: np.dtype | type | None = np.float32,
) -> tuple[np.ndarray, RPCAResult]:
    """Low-rank part of one fringe image.

    Parameters
    ----------
    image : (H, W) array, any real dtype, finite
    tau : float, optional
        Weight of ||W||_1; default 1 / sqrt(max(H, W)).
    stable : bool
        Stop at the noise level (default) instead of exact decomposition.
    svd : {"auto", "partial", "full"}
    tol : float
        Relative residual for the exact rule (``stable=False``).
    noise_sigma : float, optional
        Standard deviation of the dense noise in image units; default estimated robustly.
    dtype : float32 or float64
        Working precision (float32 suffices for camera images).

    Returns
    -------
    denoised : (H, W) float64
    result : RPCAResult
    """
    arr = _validate.finite_array(image, "image", ndim=2)
    result = rpca_ialm(arr, tau=tau, tol=tol, svd=svd, dtype=dtype, stable=stable, noise_sigma=noise_sigma)
    return result.low_rank.astype(np.float64), result


def rpca_denoise_stack(
    stack: np.ndarray,
    tau: float | None = None,
    stable: bool = True,
    svd: str = "auto",
    tol: float = 1e-7,
    dtype: np.dtype | type | None = np.float32,
) -> tuple[np.ndarray, list[RPCAResult]]:
    """:func:`rpca_denoise_frame` on every frame of an (N, H, W) stack.

    Returns
    -------
    denoised : (N, H, W) float64
    results : list of N RPCAResult
    """
    arr = _validate.finite_array(stack, "stack", ndim=3)
    out = np.empty(arr.shape, dtype=np.float64)
    results: list[RPCAResult] = []
    for index, frame in enumerate(arr):
        out[index], result = rpca_denoise_frame(frame, tau=tau, stable=stable, svd=svd, tol=tol, dtype=dtype)
        results.append(result)
        log.info(
            "denoised frame %d/%d: rank %d, %d iterations, %.2f s",
            index + 1,
            len(arr),
            result.rank,
            result.iterations,
            result.seconds,
        )
    return out, results
