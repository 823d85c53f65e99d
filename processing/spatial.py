"""Quality-guided spatial phase unwrapping for single-frequency data.

Quality-guided unwrapping integrates wrapped phase differences along paths that visit the most
reliable pixels first. The classic flood fill grows the unwrapped region through the best edge
next to it, which is Prim's algorithm: it integrates along a maximum-quality spanning tree of
the 4-neighbour pixel graph. scipy builds that tree without a Python loop over pixels:

1. edges between 4-neighbours inside the mask, weight = 3 - (q_a + q_b) for qualities
   normalised to [0, 1] (a constant added to every edge does not change the tree, and keeps
   weights positive as scipy needs), ``scipy.sparse.csgraph.minimum_spanning_tree``;
2. one breadth-first traversal from a virtual node tied to the best pixel of every connected
   region gives each pixel its parent;
3. the integer wrap count of each pixel relative to its parent, ``-round((phi - phi_parent) / 2 pi)``,
   is summed up to the root by pointer jumping (``acc += acc[parent]; parent = parent[parent]``),
   about log2(depth) vectorised passes.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

from processing import _validate
from processing.angles import wrap_to_pi
from processing.temporal import UnwrapResult

TWO_PI = 2.0 * np.pi
QUALITY_KINDS = ("variance",)


def phase_derivative_variance(phi: np.ndarray, window: int = 3) -> np.ndarray:
    """Phase-derivative variance (Ghiglia and Pritt): low where the phase is smooth.

    Parameters
    ----------
    phi : (H, W) array
        Wrapped phase; NaN pixels count as zero phase (mask them in the unwrapper).
    window : int
        Odd side k of the square neighbourhood, >= 3.

    Returns
    -------
    z : (H, W) float64 array >= 0
        ``sqrt(var(dx)) + sqrt(var(dy))`` over the k x k window, with dx, dy the wrapped
        differences to the next pixel along x and y (the last column / row repeats its
        neighbour's). Use ``-z`` or ``1 / (1 + z)`` as a quality.
    """
    p = _validate.phase_map(phi, "phi")
    window = _validate.positive_int(window, "window", minimum=3)
    if window % 2 == 0:
        raise ValueError(f"window: expected an odd size, found {window}")
    p = np.nan_to_num(p, nan=0.0)
    dx = np.zeros_like(p)
    dy = np.zeros_like(p)
    if p.shape[1] > 1:
        dx[:, :-1] = wrap_to_pi(np.diff(p, axis=1))
        dx[:, -1] = dx[:, -2]
    if p.shape[0] > 1:
        dy[:-1] = wrap_to_pi(np.diff(p, axis=0))
        dy[-1] = dy[-2]
    spread = np.zeros_like(p)
    for d in (dx, dy):
        mean = ndimage.uniform_filter(d, size=window, mode="nearest")
        mean_sq = ndimage.uniform_filter(d * d, size=window, mode="nearest")
        spread += np.sqrt(np.maximum(mean_sq - mean * mean, 0.0))
    return spread


def _normalised_quality(q: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Quality scaled to [0, 1] over the mask (constant quality -> all ones)."""
    inside = q[mask]
    low, high = float(inside.min()), float(inside.max())
    if high > low:
        return np.clip((q - low) / (high - low), 0.0, 1.0)
    return np.ones_like(q)


def _spanning_tree_edges(mask: np.ndarray, quality: np.ndarray) -> coo_matrix:
    """Maximum-quality spanning forest of the 4-neighbour graph of the masked pixels."""
    height, width = mask.shape
    index = np.arange(height * width).reshape(height, width)
    heads, tails, weights = [], [], []
    for a, b in (
        ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
        ((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
    ):
        both = mask[a] & mask[b]
        heads.append(index[a][both])
        tails.append(index[b][both])
        weights.append(3.0 - (quality[a][both] + quality[b][both]))
    n = height * width
    graph = coo_matrix((np.concatenate(weights), (np.concatenate(heads), np.concatenate(tails))), shape=(n, n))
    return minimum_spanning_tree(graph.tocsr()).tocoo()


def unwrap_quality_guided(
    phi: np.ndarray,
    quality: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    quality_kind: str = "variance",
) -> np.ndarray:
    """Quality-guided spatial unwrapping (maximum-quality spanning tree).

    Parameters
    ----------
    phi : (H, W) array
        Wrapped phase (any 2 pi representation); NaN pixels are excluded.
    quality : (H, W) array, optional
        Higher = more reliable, e.g. modulation B or data modulation B / A. Default: computed
        according to ``quality_kind``.
    mask : (H, W) bool array, optional
        Pixels to unwrap (True); default every finite pixel of ``phi``.
    quality_kind : str
        Quality used when ``quality`` is None: ``"variance"``, the negated
        :func:`phase_derivative_variance` (3 x 3).

    Returns
    -------
    unwrapped : (H, W) float64 array, NaN outside the mask
        Continuous phase up to a constant 2 pi k per connected region of the mask: regions that
        no 4-neighbour path joins (isolated objects, islands cut by shadows) are unwrapped
        independently, each anchored at its best pixel, and their offsets are arbitrary.
        Spatial unwrapping cannot recover true jumps of more than pi between neighbours; use
        temporal unwrapping (:mod:`processing.temporal`) for absolute phase.
    """
    p = _validate.phase_map(phi, "phi")
    valid = np.isfinite(p)
    user_mask = _validate.bool_mask(mask, "mask", p.shape)
    if user_mask is not None:
        valid &= user_mask
    if quality is None:
        if quality_kind not in QUALITY_KINDS:
            raise ValueError(f"quality_kind: expected one of {', '.join(QUALITY_KINDS)}, found {quality_kind!r}")
        q = -phase_derivative_variance(np.where(valid, p, 0.0))
    else:
        q = _validate.phase_map(quality, "quality", p.shape)
        valid &= np.isfinite(q)
    out = np.full(p.shape, np.nan)
    if not valid.any():
        return out
    qn = _normalised_quality(q, valid)
    parent = _tree_parents(valid, qn)
    flat_valid = valid.ravel()
    flat_phi = np.where(flat_valid, p.ravel(), 0.0)
    result = flat_phi + TWO_PI * _wraps_to_root(flat_phi, parent)
    out.ravel()[flat_valid] = result[flat_valid]
    return out


def _tree_parents(valid: np.ndarray, quality: np.ndarray) -> np.ndarray:
    """Each pixel's parent (flat index) in the maximum-quality spanning forest; -1 or n for roots and outsiders.

    One root per connected region (its best pixel), tied to a virtual node n = ``valid.size`` so
    that one breadth-first traversal visits every region.
    """
    tree = _spanning_tree_edges(valid, quality)
    n = valid.size
    flat_valid = valid.ravel()
    flat_q = np.where(flat_valid, quality.ravel(), -1.0)
    symmetric = coo_matrix((np.ones(tree.nnz), (tree.row, tree.col)), shape=(n + 1, n + 1))
    _, labels = connected_components(symmetric, directed=False)
    pixels = np.flatnonzero(flat_valid)
    best_first = pixels[np.argsort(-flat_q[pixels], kind="stable")]
    _, first = np.unique(labels[best_first], return_index=True)
    roots = best_first[first]
    links = coo_matrix(
        (
            np.ones(tree.nnz + roots.size),
            (np.concatenate([tree.row, np.full(roots.size, n)]), np.concatenate([tree.col, roots])),
        ),
        shape=(n + 1, n + 1),
    ).tocsr()
    _, parent = breadth_first_order(links, n, directed=False, return_predecessors=True)
    return parent[:n].copy()


def _wraps_to_root(flat_phi: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """Integer wrap count of each pixel relative to its region's root, summed along the tree (``parent`` is consumed)."""
    n = flat_phi.size
    # Pixels outside the mask and roots point to themselves and carry no wrap count.
    own = (parent < 0) | (parent == n)
    parent[own] = np.flatnonzero(own)
    wraps = -np.rint((flat_phi - flat_phi[parent]) / TWO_PI).astype(np.int64)
    wraps[own] = 0
    # Pointer jumping: after i passes each pixel holds the sum over its 2**i nearest ancestors.
    while True:
        grand = parent[parent]
        if np.array_equal(grand, parent):
            break
        wraps += wraps[parent]
        parent = grand
    return wraps


def unwrap_spatial(phi: np.ndarray, mask: np.ndarray | None = None) -> UnwrapResult:
    """:func:`unwrap_quality_guided` as an :class:`~processing.temporal.UnwrapResult`, the type every
    unwrapping method returns.

    Parameters
    ----------
    phi : (H, W) array
        Wrapped phase (any 2 pi representation); NaN pixels are excluded.
    mask : (H, W) bool array, optional
        Pixels to unwrap (True); default every finite pixel of ``phi``.

    Returns
    -------
    UnwrapResult
        ``phase`` continuous up to 2 pi k per connected region (NaN outside the mask), ``orders``
        None, ``valid`` where ``phase`` is finite, ``absolute`` False.
    """
    phase = unwrap_quality_guided(phi, mask=mask)
    return UnwrapResult(phase=phase, orders=None, valid=np.isfinite(phase), absolute=False)


def remove_region_offsets(delta: np.ndarray) -> np.ndarray:
    """Subtract from each 4-connected region of finite ``delta`` the multiple of 2 pi nearest its median.

    For a phase known up to 2 pi k per region (spatial unwrapping): ``delta`` is the object's
    phase minus the reference plane's, (H, W) with NaN where invalid; the result has each
    region's median within pi of 0, right where the reference plane shows in the region.
    """
    finite = np.isfinite(delta)
    labels, count = ndimage.label(finite)
    if count == 0:
        return delta
    medians = np.asarray(ndimage.median(np.where(finite, delta, 0.0), labels, np.arange(1, count + 1)))
    offsets = np.concatenate([[0.0], 2.0 * np.pi * np.round(medians / (2.0 * np.pi))])
    return delta - offsets[labels]
