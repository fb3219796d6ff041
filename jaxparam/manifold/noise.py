"""Noisy inputs for :mod:`jaxparam.manifold.maps`: whether noise at the edge scale outweighs
a closed mesh's bending, and the smoothed positions such a mesh is decimated on."""
from __future__ import annotations

import numpy as np

from ..host import vertex_normals

__all__ = ["NOISE_SMOOTHING_STEPS", "noise_dominates", "decision_positions"]

#: Umbrella smoothing steps (factor 0.5) of the positions a noisy input is decimated on
#: (:func:`decision_positions`).
NOISE_SMOOTHING_STEPS = 2


def _umbrella(V: np.ndarray, F: np.ndarray):
    """``(L (n, 3), E (2e, 2))``: each vertex less the mean of its neighbours, and the
    directed edges of the closed mesh ``(V (n, 3), F (m, 3))``."""
    n = V.shape[0]
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    deg = np.maximum(np.bincount(E[:, 0], minlength=n), 1)
    mean = np.stack([np.bincount(E[:, 0], V[E[:, 1], d], minlength=n) for d in range(3)], 1)
    return V - mean / deg[:, None], E


def noise_dominates(V: np.ndarray, F: np.ndarray) -> bool:
    """Whether noise at the scale of the edges outweighs the bending of the surface
    ``(V (n, 3), F (m, 3))``: the normal components of the vertices' umbrella Laplacians
    (each vertex less its neighbours' mean, along its normal) are anti-correlated across the
    edges.  A surface bends the same way at neighbouring vertices, however coarse its mesh
    (correlation 0.33-0.91 on the closed meshes of ``../shared/data`` and a 111k-face
    bunny); white noise pushes neighbours apart (-0.19 on that bunny with Gaussian noise of
    0.1 % of the diagonal; the noise then decides which rings the decimation's rules find
    flat).  A local measure of the offsets alone does not tell the two apart: coarse
    decimated-knight is rougher per edge than the noisy bunny."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    L, E = _umbrella(V, F)
    s = np.einsum("ij,ij->i", L, vertex_normals(V, F))
    power = float(np.mean(s * s))
    return power > 0 and float(np.mean(s[E[:, 0]] * s[E[:, 1]])) < 0.0


def decision_positions(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``(n, 3)``: the positions the decimation decides on: ``V``, or where
    :func:`noise_dominates`, ``V`` after :data:`NOISE_SMOOTHING_STEPS` umbrella steps of
    factor 0.5.  The decimation's flatness rules pass few rings of a noisy mesh, which then
    decimates in hundreds of small levels (a 111k-face bunny with noise of 0.1 % of its
    diagonal: 602 levels against 160 clean, map + level-4 remesh 33.9 s); decided on the
    smoothed positions it took 14.2 s and its remesh came closer, 1.134 -> 0.643 % of the
    diagonal.  The map itself is built on the input's positions.  Smoothing clean meshes
    cuts their tips (cow 0.607 -> 0.803 %), hence the test."""
    V = np.asarray(V, np.float64)
    if not noise_dominates(V, F):
        return V
    W = V.copy()
    for _ in range(NOISE_SMOOTHING_STEPS):
        W = W - 0.5 * _umbrella(W, np.asarray(F, np.int64))[0]
    return W
