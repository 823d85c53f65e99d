"""Robust principal component analysis: D = L + S with L low rank and S sparse.

Two solvers of principal component pursuit, min ||L||_* + tau ||S||_1 s.t. L + S = D:

- :func:`rpca_ialm`, the inexact augmented Lagrange multiplier method (thesis eqs. 4.3-4.9,
  Lin, Chen & Ma 2010), with an increasing penalty mu: few iterations;
- :func:`rpca_adm`, the alternating direction method with a fixed penalty beta (thesis eq. 2.11,
  Yuan & Yang), optionally in the (t, 1 - t) weighting of thesis ch. 3.

Both spend their time in singular value thresholding; ``svd="full"`` is the plain reference
implementation, ``"auto"``/``"partial"`` the fast partial SVD of :mod:`processing.denoise.svd`.

The many small QR/SVD calls run faster with single-threaded BLAS on a busy machine; this module
leaves the process's BLAS threads alone, the application sets the limit around the solves
(``rig.blas``, through threadpoolctl).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from processing.angles import wrap_to_pi
from processing.denoise.svd import SubspaceState, check_svd_method, singular_value_threshold

log = logging.getLogger(__name__)


@dataclass
class RPCAResult:
    """Outcome of one RPCA run.

    Attributes
    ----------
    low_rank, sparse : (M, N) float arrays
        L and S with D ~ L + S.
    iterations : int
    rank : int
        Rank of ``low_rank`` at the last iteration.
    converged : bool
        The stopping rule was met before ``max_iter``.
    residual : float
        ||D - L - S||_F / ||D||_F at the end (ADM: the last relative change of (L, S)).
    seconds : float
        Wall-clock time of the solver.
    """

    low_rank: np.ndarray
    sparse: np.ndarray
    iterations: int
    rank: int
    converged: bool
    residual: float
    seconds: float

    def info(self) -> dict[str, float | int | bool]:
        """The scalar figures, for reports."""
        return {
            "iterations": self.iterations,
            "rank": self.rank,
            "converged": self.converged,
            "residual": self.residual,
            "seconds": round(self.seconds, 4),
        }


def shrink(x: np.ndarray, threshold: float) -> np.ndarray:
    """Entry-wise soft thresholding H_threshold[x] (thesis eq. 4.4)."""
    return np.sign(x) * np.maximum(np.abs(x) - threshold, 0.0)


def _shrink_into(x: np.ndarray, threshold: float, out: np.ndarray) -> np.ndarray:
    """shrink(x, threshold) written into ``out`` (no temporaries beyond one)."""
    np.abs(x, out=out)
    out -= threshold
    np.maximum(out, 0.0, out=out)
    np.copysign(out, x, out=out)
    return out


def check_matrix(d: np.ndarray, name: str = "D") -> np.ndarray:
    """Validate a data matrix: 2-D, non-empty, finite, real. Returns a float array."""
    arr = np.asarray(d)
    if arr.ndim != 2:
        raise ValueError(f"{name}: expected a 2-D matrix, found shape {arr.shape}")
    if arr.size == 0 or min(arr.shape) < 2:
        raise ValueError(f"{name}: expected at least 2x2, found shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool):
        raise ValueError(f"{name}: expected real numbers, found dtype {arr.dtype}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinity (fill or mask them first)")
    return arr


def _working_dtype(d: np.ndarray, dtype: np.dtype | type | None) -> np.dtype:
    if dtype is None:
        return np.dtype(np.float32) if d.dtype == np.float32 else np.dtype(np.float64)
    dt = np.dtype(dtype)
    if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"dtype: expected float32 or float64, found {dt}")
    return dt


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name}: expected a finite value > 0, found {value}")
    return value


def default_tau(shape: tuple[int, int]) -> float:
    """tau = 1 / sqrt(max(M, N)) (Candes et al.; thesis ch. 4)."""
    return 1.0 / np.sqrt(max(shape))


def second_differences(d: np.ndarray, mask: np.ndarray | None = None) -> Iterator[np.ndarray]:
    """The finite second differences along rows, then along columns (two 1-D arrays).

    With ``mask``, only differences of three valid pixels count. An axis shorter than three
    pixels gives an empty array. The column differences come in row-major order (their
    statistics, not their order, are what callers read).
    """
    for second in masked_second_differences(d, mask):
        yield second[np.isfinite(second)]


def masked_second_differences(d: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Second differences along rows ``(H, W - 2)`` and down columns ``(H - 2, W)``, NaN unless
    all three pixels are valid (``mask``) and finite; float64. An axis shorter than three pixels
    gives an empty array."""
    arr = np.asarray(d, dtype=np.float64)
    if arr.ndim != 2:
        raise ValueError(f"d: expected a 2-D array, found {arr.ndim} dimensions")
    if mask is not None:
        arr = np.where(np.asarray(mask, dtype=bool), arr, np.nan)
    rows, cols = arr.shape
    along = _second_difference(arr[:, 2:], arr[:, 1:-1], arr[:, :-2]) if cols >= 3 else np.empty((rows, 0))
    down = _second_difference(arr[2:, :], arr[1:-1, :], arr[:-2, :]) if rows >= 3 else np.empty((0, cols))
    return along, down


def _second_difference(after: np.ndarray, middle: np.ndarray, before: np.ndarray) -> np.ndarray:
    """``after - 2 middle + before``, evaluated in that order in one buffer (the same rounding, one array)."""
    out = np.multiply(middle, 2.0)
    np.subtract(after, out, out=out)
    out += before
    return out


def robust_noise_sigma(d: np.ndarray, mask: np.ndarray | None = None, wrap: bool = False) -> float:
    """Standard deviation of white noise on a smooth matrix, robust to sparse outliers.

    Median absolute deviation of the second differences (which cancel smooth content; their
    variance is 6 sigma^2), scaled to a Gaussian standard deviation, along rows and along
    columns; the smaller of the two is kept, since content only adds to it (fringes, for
    instance, vary along one axis only). It assumes content smooth along at least one axis
    (phase maps, fringe images); for other data give sigma. With ``mask``, only differences of
    three valid pixels count (filled shadows would bias it low). ``wrap``: wrap the differences
    into [-pi, pi) first, for phase maps whose 2 pi order errors must not count as noise.
    """
    return noise_sigma_from_second_differences(second_differences(d, mask), wrap)


def noise_sigma_from_second_differences(seconds: Iterable[np.ndarray], wrap: bool = False) -> float:
    """:func:`robust_noise_sigma` from the finite second differences of each axis."""
    estimates = []
    for second in seconds:
        if wrap:
            second = wrap_to_pi(second)
        if second.size:
            mad = _median(np.abs(second - _median(second)))
            estimates.append(1.4826 * mad / np.sqrt(6.0))
    return min(estimates) if estimates else 0.0


def _median(values: np.ndarray) -> float:
    """``np.median`` of a 1-D array without NaN, by one partition (np.median partitions twice)."""
    middle = values.size // 2
    part = np.partition(values, middle)
    if values.size % 2:
        return float(part[middle])
    return float((part[:middle].max() + part[middle]) / 2.0)


def rpca_ialm(
    D: np.ndarray,
    tau: float | None = None,
    tol: float = 1e-7,
    max_iter: int = 500,
    rho: float = 1.5,
    svd: str = "auto",
    dtype: np.dtype | type | None = None,
    stable: bool = False,
    noise_sigma: float | None = None,
) -> RPCAResult:
    """RPCA by the inexact augmented Lagrange multiplier method (thesis eqs. 4.3-4.9).

    Y0 = D / max(||D||_2, ||D||_inf / tau), S0 = 0, mu0 = 1.25 / ||D||_2; each iteration
    L = SVT_{1/mu}(D - S + Y/mu), S = shrink_{tau/mu}(D - L + Y/mu), Y += mu (D - L - S),
    mu *= rho; stop when ||D - L - S||_F / ||D||_F < tol.

    Parameters
    ----------
    D : (M, N) array
        Data matrix, finite.
    tau : float, optional
        Weight of ||S||_1; default 1 / sqrt(max(M, N)).
    tol : float
        Relative residual at which to stop.
    max_iter : int
    rho : float
        Growth factor of mu, > 1.
    svd : {"auto", "partial", "full"}
        "full": a full SVD every iteration (the reference); "auto"/"partial": randomised
        partial SVD with rank prediction, warm-started across iterations.
    dtype : float32 or float64, optional
        Working precision; default float64 (float32 if D is float32). float32 cannot reach a
        relative residual much below 1e-6, so ``tol`` is raised to 1e-6 in float32.
    stable : bool
        Stable PCP for D = L + S + J with dense noise J: stop as soon as
        ||D - L - S||_F <= sqrt(M N) sigma instead of at exact equality.
    noise_sigma : float, optional
        sigma for ``stable``; default a robust estimate from D (:func:`robust_noise_sigma`).

    Returns
    -------
    RPCAResult
    """
    start = time.perf_counter()
    d, tau, tol, rho = _ialm_arguments(D, tau, tol, max_iter, rho, svd, dtype)
    m, n = d.shape
    norm_fro = float(np.linalg.norm(d))
    if norm_fro == 0.0:
        zeros = np.zeros_like(d)
        return RPCAResult(zeros, zeros.copy(), 0, 0, True, 0.0, time.perf_counter() - start)
    y, mu = _ialm_start(d, tau)
    stop_abs = tol * norm_fro
    if stable:
        sigma = robust_noise_sigma(d) if noise_sigma is None else float(noise_sigma)
        if not (np.isfinite(sigma) and sigma >= 0):
            raise ValueError(f"noise_sigma: expected a finite value >= 0, found {noise_sigma}")
        stop_abs = max(stop_abs, np.sqrt(m * n) * sigma)
    state = SubspaceState()
    low_rank, sparse, iteration, rank, converged, residual = _ialm_iterate(
        d, y, mu, rho, tau, stop_abs, norm_fro, int(max_iter), svd, state
    )
    seconds = time.perf_counter() - start
    log.debug(
        "rpca_ialm %dx%d: %d iterations, rank %d, residual %.2e, %.3f s (%d partial, %d full SVDs)",
        m,
        n,
        iteration,
        rank,
        residual,
        seconds,
        state.partial_svds,
        state.full_svds,
    )
    return RPCAResult(low_rank, sparse, iteration, rank, converged, residual, seconds)


def _ialm_arguments(
    D: np.ndarray, tau: float | None, tol: float, max_iter: int, rho: float, svd: str, dtype: np.dtype | type | None
) -> tuple[np.ndarray, float, float, float]:
    """:func:`rpca_ialm`'s arguments checked: (D in the working precision, tau, tol, rho)."""
    d_in = check_matrix(D)
    check_svd_method(svd)
    work = _working_dtype(d_in, dtype)
    d = d_in.astype(work, copy=False)
    tau = default_tau(d.shape) if tau is None else _positive(tau, "tau")
    tol = _positive(tol, "tol")
    if work == np.float32:
        tol = max(tol, 1e-6)
    rho = float(rho)
    if not rho > 1.0:
        raise ValueError(f"rho: expected > 1, found {rho}")
    if int(max_iter) < 1:
        raise ValueError(f"max_iter: expected >= 1, found {max_iter}")
    return d, tau, tol, rho


def _ialm_start(d: np.ndarray, tau: float) -> tuple[np.ndarray, float]:
    """Y0 = D / max(||D||_2, ||D||_inf / tau) and mu0 = 1.25 / ||D||_2 (thesis eq. 4.3)."""
    norm_two = float(np.linalg.norm(d.astype(np.float64), 2)) if min(d.shape) <= 64 else _spectral_norm(d)
    norm_inf = float(np.max(np.abs(d))) / tau
    return d / max(norm_two, norm_inf), 1.25 / norm_two


def _ialm_iterate(
    d: np.ndarray,
    y: np.ndarray,
    mu: float,
    rho: float,
    tau: float,
    stop_abs: float,
    norm_fro: float,
    max_iter: int,
    svd: str,
    state: SubspaceState,
) -> tuple[np.ndarray, np.ndarray, int, int, bool, float]:
    """The inexact ALM iterations (eqs. 4.4-4.9): (L, S, iterations, rank, converged, relative residual)."""
    mu_max = mu * 1e7
    sparse = np.zeros_like(d)
    low_rank = np.zeros_like(d)
    rank = 0
    residual = np.inf
    converged = False
    iteration = 0
    target = np.empty_like(d)
    gap = np.empty_like(d)
    for iteration in range(1, max_iter + 1):  # noqa: B007  (reported after the loop)
        inv_mu = 1.0 / mu
        np.multiply(y, inv_mu, out=target)
        target += d  # D + Y / mu, shared by both updates
        low_rank, rank = singular_value_threshold(target - sparse, inv_mu, state, svd)
        target -= low_rank
        sparse = _shrink_into(target, tau * inv_mu, sparse)
        np.subtract(d, low_rank, out=gap)
        gap -= sparse
        residual_abs = float(np.sqrt(np.vdot(gap, gap)))
        residual = residual_abs / norm_fro
        if residual_abs < stop_abs:
            converged = True
            break
        y += mu * gap
        mu = min(mu * rho, mu_max)
    return low_rank, sparse, iteration, rank, converged, residual


def _spectral_norm(d: np.ndarray) -> float:
    """Largest singular value by a short power iteration on D^T D (accurate to ~1e-6)."""
    rng = np.random.default_rng(0)
    v = np.asarray(rng.standard_normal(d.shape[1]), dtype=d.dtype)
    v /= np.linalg.norm(v)
    value = 0.0
    for _ in range(100):
        w = d.T @ (d @ v)
        new = float(np.sqrt(np.linalg.norm(w)))
        v = w / (new * new) if new > 0 else w
        if new == 0.0 or abs(new - value) <= 1e-7 * new:
            value = new
            break
        value = new
    return value


def rpca_adm(
    D: np.ndarray,
    tau: float | None = None,
    beta: float | None = None,
    tol: float = 1e-6,
    max_iter: int = 1000,
    t: float | None = None,
    svd: str = "auto",
) -> RPCAResult:
    """RPCA by the alternating direction method with a fixed penalty (thesis eq. 2.11).

    Minimises w_s ||S||_1 + w_l ||L||_* s.t. L + S = D with (w_s, w_l) = (tau, 1), or
    (t, 1 - t) when ``t`` is given (thesis ch. 3, eq. 3.4). Each iteration:
    S = shrink_{w_s/beta}(H/beta - L + D), L = SVT_{w_l/beta}(D - S + H/beta),
    H -= beta (S + L - D); stop when ||(L, S)_new - (L, S)_old||_F / (||(L, S)_old||_F + 1) < tol.

    Parameters
    ----------
    D : (M, N) array
    tau : float, optional
        Weight of ||S||_1 when ``t`` is not given; default 1 / sqrt(max(M, N)).
    beta : float, optional
        Penalty; default 0.25 M N / ||D||_1.
    tol : float
    max_iter : int
    t : float in (0, 1), optional
        The ch. 3 weighting; overrides ``tau``.
    svd : {"auto", "partial", "full"}

    Returns
    -------
    RPCAResult (``residual`` is ||D - L - S||_F / ||D||_F at the end)
    """
    start = time.perf_counter()
    d = check_matrix(D).astype(np.float64, copy=False)
    check_svd_method(svd)
    m, n = d.shape
    if t is not None:
        t = float(t)
        if not 0.0 < t < 1.0:
            raise ValueError(f"t: expected a value in (0, 1), found {t}")
        weight_sparse, weight_low = t, 1.0 - t
    else:
        weight_sparse = default_tau(d.shape) if tau is None else _positive(tau, "tau")
        weight_low = 1.0
    norm_one = float(np.sum(np.abs(d)))
    if norm_one == 0.0:
        zeros = np.zeros_like(d)
        return RPCAResult(zeros, zeros.copy(), 0, 0, True, 0.0, time.perf_counter() - start)
    beta = 0.25 * m * n / norm_one if beta is None else _positive(beta, "beta")
    tol = _positive(tol, "tol")
    if int(max_iter) < 1:
        raise ValueError(f"max_iter: expected >= 1, found {max_iter}")

    state = SubspaceState()
    sparse = np.zeros_like(d)
    low_rank = np.zeros_like(d)
    h = np.zeros_like(d)
    inv_beta = 1.0 / beta
    rank = 0
    change = np.inf
    converged = False
    iteration = 0
    for iteration in range(1, int(max_iter) + 1):  # noqa: B007  (reported after the loop)
        previous_norm = np.sqrt(float(np.vdot(low_rank, low_rank)) + float(np.vdot(sparse, sparse)))
        new_sparse = shrink(inv_beta * h - low_rank + d, weight_sparse * inv_beta)
        new_low, rank = singular_value_threshold(d - new_sparse + inv_beta * h, weight_low * inv_beta, state, svd)
        delta_s = new_sparse - sparse
        delta_l = new_low - low_rank
        change = np.sqrt(float(np.vdot(delta_s, delta_s)) + float(np.vdot(delta_l, delta_l))) / (previous_norm + 1.0)
        sparse, low_rank = new_sparse, new_low
        h -= beta * (sparse + low_rank - d)
        if change < tol:
            converged = True
            break
    residual = float(np.linalg.norm(d - low_rank - sparse) / np.linalg.norm(d))
    seconds = time.perf_counter() - start
    log.debug("rpca_adm %dx%d: %d iterations, rank %d, change %.2e, %.3f s", m, n, iteration, rank, change, seconds)
    return RPCAResult(low_rank, sparse, iteration, rank, converged, residual, seconds)
