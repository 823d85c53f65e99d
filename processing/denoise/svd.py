"""Singular value thresholding for RPCA solvers: full SVD, and a fast partial SVD with rank adaptation.

Every RPCA iteration replaces a matrix by its singular value thresholding (SVT)
``U max(G - threshold, 0) V^T``. Only the singular values above the threshold matter, and for the
low-rank matrices of fringe projection there are few of them, so a partial SVD that finds just
those is much cheaper than a full one.

The partial path is a randomised range finder (Halko, Martinsson & Tropp 2011) with a few power
(subspace) iterations, warm-started from the right singular subspace of the previous call, and a
rank prediction in the spirit of Lin, Chen & Ma's inexact ALM (which uses PROPACK): ask for the
previous rank plus a margin; if every computed singular value is still above the threshold, the
margin was too small and the call is repeated with twice as many vectors. When the predicted rank
approaches the matrix size a full SVD is cheaper and is used instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SVD_METHODS = ("auto", "full", "partial")

# Above this fraction of min(M, N) a full SVD is cheaper than the randomised one.
_FULL_FRACTION = 0.2
_MIN_VECTORS = 8
_POWER_ITERATIONS = 1


@dataclass
class SubspaceState:
    """What one SVT call hands the next: the predicted rank and the last right singular vectors."""

    rank: int = 0
    right: np.ndarray | None = field(default=None, repr=False)  # (N, k) orthonormal columns
    full_svds: int = 0
    partial_svds: int = 0
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0), repr=False)


def check_svd_method(svd: str) -> str:
    """Validate an ``svd`` argument of the solvers."""
    if svd not in SVD_METHODS:
        raise ValueError(f"svd: expected one of {', '.join(SVD_METHODS)}, found {svd!r}")
    return svd


def _truncate(u: np.ndarray, s: np.ndarray, vt: np.ndarray, threshold: float) -> tuple[np.ndarray, int]:
    keep = int(np.count_nonzero(s > threshold))
    if keep == 0:
        return np.zeros((u.shape[0], vt.shape[1]), dtype=u.dtype), 0
    shrunk = (s[:keep] - threshold).astype(u.dtype)
    return (u[:, :keep] * shrunk) @ vt[:keep], keep


def _full(x: np.ndarray, threshold: float, state: SubspaceState) -> tuple[np.ndarray, int]:
    u, s, vt = np.linalg.svd(x, full_matrices=False)
    state.full_svds += 1
    low_rank, rank = _truncate(u, s, vt, threshold)
    state.rank = rank
    state.right = vt[: max(rank, 1)].T.copy()
    return low_rank, rank


def _randomised(x: np.ndarray, vectors: int, state: SubspaceState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Top ``vectors`` singular triplets of ``x`` by a warm-started randomised subspace iteration."""
    n = x.shape[1]
    start = state.right
    if start is None or start.shape[0] != n:
        start = np.empty((n, 0), dtype=x.dtype)
    start = start[:, :vectors].astype(x.dtype, copy=False)
    missing = vectors - start.shape[1]
    if missing > 0:
        fresh = state.rng.standard_normal((n, missing)).astype(x.dtype)
        start = np.concatenate([start, fresh], axis=1)
    q, _ = np.linalg.qr(x @ start)
    for _ in range(_POWER_ITERATIONS):
        z, _ = np.linalg.qr(x.T @ q)
        q, _ = np.linalg.qr(x @ z)
    u_small, s, vt = np.linalg.svd(q.T @ x, full_matrices=False)
    state.partial_svds += 1
    return q @ u_small, s, vt


def singular_value_threshold(
    x: np.ndarray, threshold: float, state: SubspaceState, method: str = "auto"
) -> tuple[np.ndarray, int]:
    """SVT of ``x``: ``U max(G - threshold, 0) V^T``, and the number of singular values kept.

    Parameters
    ----------
    x : (M, N) float array
    threshold : float
        Shrinkage applied to every singular value.
    state : SubspaceState
        Carried between the calls of one solver run (rank prediction, warm start); updated.
    method : {"auto", "partial", "full"}
        "full" always computes the full SVD (the reference); "auto" and "partial" use the
        randomised partial SVD while the predicted rank is small, the full one otherwise.
    """
    smallest = min(x.shape)
    if method == "full":
        return _full(x, threshold, state)
    vectors = max(_MIN_VECTORS, state.rank + max(5, state.rank // 4))
    while vectors <= _FULL_FRACTION * smallest:
        u, s, vt = _randomised(x, vectors, state)
        # The smallest computed value must fall below the threshold, else some were missed.
        if s[-1] <= threshold:
            low_rank, rank = _truncate(u, s, vt, threshold)
            state.rank = rank
            state.right = vt.T.copy()
            return low_rank, rank
        state.right = vt.T.copy()
        vectors *= 2
    return _full(x, threshold, state)
