"""Fringe order correction by RPCA on the fringe-order map (thesis ch. 3).

The fringe orders from temporal unwrapping are K_hat = K + E: a map K that steps by one at each
fringe boundary (low rank) plus sparse impulsive errors E. RPCA in the weighting of thesis
eq. 3.4, min t ||E||_1 + (1 - t) ||K||_* s.t. K + E = K_hat with t = 0.034, removes E; rounding K
gives integer orders. RPCA also smooths the fringe boundaries (misalignment errors of +-2 pi in
the absolute phase), which the post-processing pass along rows removes: wherever
|Phi(x+1) - Phi(x)| > pi, Phi(x+1) -= 2 pi round((Phi(x+1) - Phi(x)) / 2 pi), carried along the row.
"""

from __future__ import annotations

import numpy as np

from processing import _validate
from processing.correction.shadow_fill import fill_shadows, valid_mask
from processing.correction.voting import majority_per_label
from processing.denoise.rpca import RPCAResult, rpca_adm, rpca_ialm

TWO_PI = 2.0 * np.pi
ORDER_SOLVERS = ("ialm", "adm")


def monotonic_rows(phase: np.ndarray, anchor: np.ndarray | None = None, valid: np.ndarray | None = None) -> np.ndarray:
    """The thesis' post-processing pass along rows, vectorised (thesis ch. 3.3.3).

    Applying "if |Phi(x+1) - Phi(x)| > pi: Phi(x+1) -= 2 pi round(dPhi / 2 pi)" pixel by pixel,
    each step on the already corrected Phi(x), subtracts from Phi(x) the running sum of
    2 pi round(dPhi / 2 pi) over the original differences, so it is one cumulative sum.

    Parameters
    ----------
    phase : (H, W) array
        Absolute phase, varying along rows by less than pi per pixel where correct; finite at
        the ``valid`` pixels.
    anchor : (H, W) array, optional
        A phase to agree with. Without it, each row is trusted at its first pixel, as in the
        sequential pass. With it, each run of consecutive valid pixels is chained on its own and
        shifted by the multiple of 2 pi that makes most of its pixels agree with ``anchor``: a
        wrong first pixel, or a shadow the phase jumps across, then cannot offset the rest.
    valid : (H, W) bool array, optional
        Pixels to chain (default all); the others are returned unchanged.
    """
    phase = np.asarray(phase, dtype=np.float64)
    valid = np.ones(phase.shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    joined = valid[:, 1:] & valid[:, :-1]
    steps = np.where(joined, np.rint(np.nan_to_num(np.diff(phase, axis=1)) / TWO_PI), 0.0)
    turns = np.zeros(phase.shape)
    np.cumsum(steps, axis=1, out=turns[:, 1:])
    if anchor is not None:
        starts = valid.copy()
        starts[:, 1:] &= ~joined
        runs = np.cumsum(starts.ravel()).reshape(phase.shape) - 1
        offset = np.rint((phase - TWO_PI * turns - anchor)[valid] / TWO_PI).astype(np.int64)
        turns[valid] += majority_per_label(runs[valid], offset)[runs[valid]]
    return np.where(valid, phase - TWO_PI * turns, phase)


def postprocess_orders(phase: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Ch. 3's post-processing of an RPCA-corrected absolute phase (thesis ch. 3.3.3).

    :func:`monotonic_rows` along the rows, each run of ``valid`` pixels anchored to the majority
    of its own RPCA-corrected pixels rather than to its first pixel. Only the ``valid`` pixels are
    read and changed, so the result of :func:`correct_orders_rpca` with ``postprocess=False``
    (NaN outside its mask) gives, passed through this, that of ``postprocess=True``: a study can
    report both from one RPCA solve.
    """
    return monotonic_rows(phase, anchor=phase, valid=valid)


def correct_orders_rpca(
    orders: np.ndarray,
    wrapped_phase: np.ndarray,
    mask: np.ndarray | None = None,
    t: float = 0.034,
    beta: float | None = None,
    postprocess: bool = True,
    solver: str = "ialm",
    svd: str = "auto",
    dtype: np.dtype | type = np.float32,
) -> tuple[np.ndarray, np.ndarray, RPCAResult]:
    """RPCA fringe order correction (thesis ch. 3) with the monotonicity post-processing.

    Parameters
    ----------
    orders : (H, W) integer or float array
        Fringe orders k as :mod:`processing.unwrap.temporal` defines them:
        Phi = (wrapped_phase mod 2 pi) + 2 pi k. Values at invalid pixels are ignored.
    wrapped_phase : (H, W) array
        The wrapped phase the orders belong to (any 2 pi representation).
    mask : (H, W) bool array, optional
        True where valid; default the finite pixels of ``orders``. Shadows are filled from their
        neighbours before RPCA and are NaN in the result.
    t : float in (0, 1)
        Weight of ||E||_1 (thesis: 0.032 - 0.036).
    beta : float, optional
        ADM penalty, default 0.25 M N / ||K_hat||_1 (used by ``solver="adm"``).
    postprocess : bool
        Run the monotonicity pass along rows after rounding (each run of valid pixels anchored
        to the majority of its RPCA-corrected pixels rather than to its first pixel).
    solver : {"ialm", "adm"}
        "adm": the thesis' fixed-penalty ADM (hundreds of iterations); "ialm": the inexact ALM
        on the same objective (tau = t / (1 - t)), which reaches the same corrected orders in
        about 30 iterations.
    svd : {"auto", "partial", "full"}
    dtype : float32 or float64
        Working precision of the "ialm" solver. The orders are rounded, so float32 (relative
        residual 1e-6) is enough: on the Table 4.1 protocol it changes 1-18 of 786k rounded
        orders before post-processing and none after, at half the time.

    Returns
    -------
    corrected_absolute_phase : (H, W) float64, NaN outside the mask
    corrected_orders : (H, W) int64, in the convention of ``orders`` (0 outside the mask)
    result : RPCAResult of the order map
    """
    k_in = _validate.image(orders, "orders").astype(np.float64)
    wrapped = _validate.phase_map(wrapped_phase, "wrapped_phase", k_in.shape)
    valid = valid_mask(k_in, mask, "orders")
    if np.any(valid & ~np.isfinite(wrapped)):
        raise ValueError("wrapped_phase: NaN at pixels where the orders are valid")
    t = float(t)
    if not 0.0 < t < 1.0:
        raise ValueError(f"t: expected a value in (0, 1), found {t}")
    if solver not in ORDER_SOLVERS:
        raise ValueError(f"solver: expected one of {', '.join(ORDER_SOLVERS)}, found {solver!r}")

    phi = np.mod(np.where(valid, wrapped, 0.0), TWO_PI)
    k_filled = fill_shadows(k_in, valid)
    if solver == "adm":
        result = rpca_adm(k_filled, beta=beta, t=t, svd=svd)
    else:
        result = rpca_ialm(k_filled, tau=t / (1.0 - t), svd=svd, dtype=dtype)
    k_rpca = np.rint(result.low_rank.astype(np.float64))
    phase = phi + TWO_PI * k_rpca
    if postprocess:
        phase = postprocess_orders(phase, valid)
    k_out = np.where(valid, np.rint((phase - phi) / TWO_PI), 0).astype(np.int64)
    return np.where(valid, phase, np.nan), k_out, result
