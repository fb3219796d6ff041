"""Consistent normal orientation of a point set (Hoppe et al. 1992): signs propagated along a
minimum spanning tree of the neighbour graph, so that neighbouring normals agree.

numpy / scipy on concrete points (topology); everything is vectorized: the tree by
:func:`scipy.sparse.csgraph.minimum_spanning_tree`, the sign products along its paths to the
root by pointer doubling (``log2(depth)`` gathers).
"""
from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

from ..blocks import for_blocks

__all__ = ["orient_normals", "NonOrientableWarning", "warn_non_orientable", "OPPOSED_PAIRS"]

#: Pairs per block of the tree's weights (:func:`jaxparam.blocks.for_blocks`).
PAIR_BLOCK = 1 << 16

#: :func:`warn_non_orientable` warns when the neighbour pairs in each other's tangent planes
#: with opposed oriented normals number more than this times ``k sqrt(N)`` (they lie along a
#: seam, a line of the surface).  Measured (session 22): a Moebius strip 0.25 (3k points) and
#: 0.53 (20k); camelhead.xyz 0.002, the issue-14 scan sets (noise, eightfold density,
#: outliers; 8k-50k points) 0, every other held-out set 0.
OPPOSED_PAIRS = 0.05


class NonOrientableWarning(UserWarning):
    """The normals of a point set cannot be oriented consistently (a Moebius strip): no disk
    map of it exists, and the mesh reconstructed from it bridges its seam."""


def warn_non_orientable(opposed: int, n: int, k: int | None) -> None:
    """Warn :class:`NonOrientableWarning` when ``opposed`` pairs (``drop_steep_pairs``'
    count) exceed :data:`OPPOSED_PAIRS` ``k sqrt(n)`` (``k`` the neighbours per point; 10 when
    the graph is by radius)."""
    if opposed > OPPOSED_PAIRS * (k or 10) * np.sqrt(n):
        warnings.warn(f"{opposed} neighbour pairs lie in each other's tangent plane with opposed "
                      "normals after the orientation: the points look like a non-orientable "
                      "surface (a Moebius strip), which has no disk map; the reconstruction "
                      "bridges across that seam. Cut the surface open so that it is orientable.",
                      NonOrientableWarning, stacklevel=4)


def orient_normals(P: np.ndarray, indptr: np.ndarray, indices: np.ndarray, normal: np.ndarray,
                   towards: np.ndarray) -> np.ndarray:
    """Normals ``(N, 3)`` with signs made consistent over the neighbour graph.

    **Arguments:** ``P (N, 3)`` points; ``indptr (N+1,)``, ``indices`` their neighbour graph
    (CSR); ``normal (N, 3)`` unit normals of any signs; ``towards (3,)`` the direction each
    connected component's normals are turned to on the whole (their sum has a non-negative
    component along it).

    The tree is the minimum spanning tree of the graph under the weight ``1 - |n_v . n_w|``
    (Hoppe's: sign information travels between nearly parallel normals) plus the pair's
    slope ``max(|n_v . d|, |n_w . d|) / |d|`` (a pair that leaves the tangent planes, as one
    crossing between two sheets of a thin part does, is used only when nothing else
    connects).  Along each tree edge the child takes the sign that makes
    ``n_child . n_parent >= 0``.

    **Returns:** ``(N, 3)`` the normals, each equal to ``normal`` up to sign.
    """
    N = P.shape[0]
    rows = np.repeat(np.arange(N), np.diff(indptr))
    cols = np.asarray(indices)
    up = rows < cols
    G = sp.csr_matrix((np.ones(cols.size, np.int8), cols, indptr), shape=(N, N))
    symmetric = bool(G.has_sorted_indices) and _same_pattern(G, G.T.tocsr())
    if symmetric:
        # Every pair is listed both ways (a symmetrized kNN graph, column indices sorted in
        # each row): its (smaller, larger) entries, in CSR order, are the upper triangle below
        # exactly, each weight computed once (half the gathers, no COO sort).
        rows, cols = rows[up], cols[up]
    else:
        # Each pair once, as (smaller, larger) (the weight is symmetric; a directed pair counts
        # as undirected); a pair listed both ways is averaged below.
        rows, cols = np.where(up, rows, cols), np.where(up, cols, rows)
    w = np.empty(rows.size)

    def block(lo, hi):
        r, c = rows[lo:hi], cols[lo:hi]
        d = P[c] - P[r]
        n_r, n_c = normal[r], normal[c]
        ln = np.sqrt(np.einsum("ij,ij->i", d, d)) + 1e-300
        slope = np.maximum(np.abs(np.einsum("ij,ij->i", d, n_r)),
                           np.abs(np.einsum("ij,ij->i", d, n_c))) / ln
        # Strictly positive: a zero weight would be read as no edge.
        w[lo:hi] = 1.0 - np.abs(np.einsum("ij,ij->i", n_r, n_c)) + slope + 1e-9

    for_blocks(block, rows.size, PAIR_BLOCK)        # pairs in blocks: each weight on its own
    if symmetric:
        ptr = np.zeros(N + 1, np.int64)
        np.cumsum(np.bincount(rows, minlength=N), out=ptr[1:])
        W = sp.csr_matrix((w, cols, ptr), shape=(N, N))
    else:
        W = sp.csr_matrix((w, (rows, cols)), shape=(N, N))
        W.data /= sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(N, N)).data
    T = minimum_spanning_tree(W)
    T = (T + T.T).tocsr()
    nc, lab = connected_components(T, directed=False)
    parent = np.arange(N)
    # One breadth-first tree per component, from its first point.
    roots = np.unique(lab, return_index=True)[1]
    for r in roots[np.bincount(lab)[lab[roots]] > 1]:     # loop over components, not points
        order, pred = breadth_first_order(T, int(r), directed=False, return_predecessors=True)
        parent[order[1:]] = pred[order[1:]]
    # Sign of each point relative to its parent, then products along the paths to the roots.
    sign = np.where(np.einsum("ij,ij->i", normal, normal[parent]) < 0, -1.0, 1.0)
    anc = parent.copy()
    while True:
        nxt = anc[anc]
        sign = sign * np.where(anc == nxt, 1.0, sign[anc])
        if np.array_equal(nxt, anc):
            break
        anc = nxt
    n = normal * sign[:, None]
    # Each component turned towards ``towards`` on the whole.
    s = np.bincount(lab, weights=n @ np.asarray(towards, np.float64), minlength=nc)
    return n * np.where(s[lab] < 0, -1.0, 1.0)[:, None]


def _same_pattern(A: sp.csr_matrix, B: sp.csr_matrix) -> bool:
    """Whether CSR ``A`` (sorted column indices; not modified: it may share the caller's
    arrays) and ``B`` (sorted here) have the same nonzero pattern."""
    B.sort_indices()
    return bool(np.array_equal(A.indptr, B.indptr) and np.array_equal(A.indices, B.indices))
