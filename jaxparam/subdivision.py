"""The dyadic (one-to-four) split and the nested hierarchy it builds (survey §7, Fig. 18).

One refinement splits every triangle ``(v1, v2, v3)`` into four at its edge midpoints
``w1, w2, w3`` (``w_i`` opposite ``v_i``).  The numbering is a contract that the rest of the
package relies on:

- the new vertices follow the old ones, one per edge, in the order of the edges' sorted
  ``(min, max)`` endpoint pairs (:func:`dyadic_refine`);
- face ``f`` becomes faces ``4f .. 4f+3``, its children in :data:`CHILDREN`'s order.

So ``j`` refinements of a base mesh ``T^0`` number the vertices level by level
(``V^0 ⊂ V^1 ⊂ ... ⊂ V^j``) and :class:`Hierarchy` records, per level, the two parents of
every new vertex: what :mod:`jaxparam.wavelets` needs, what :func:`jaxparam.remesh` and
:meth:`jaxparam.manifold.ManifoldParameterization.remesh` write, and what
:func:`hierarchy_from_faces` reads back from a mesh file.  All numpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import MeshError

__all__ = ["CHILDREN", "Hierarchy", "dyadic_refine", "dyadic_hierarchy", "split_corner_values",
           "midpoint_refine", "hierarchy_from_faces"]

#: The four children of a triangle ``(v1, v2, v3)`` in the dyadic refinement, as indices into
#: ``(v1, v2, v3, w1, w2, w3)`` (``w_i`` the midpoint of the edge opposite ``v_i``),
#: anticlockwise, corner children first; face ``f`` becomes faces ``4f .. 4f+3`` in this order.
CHILDREN = np.array([[0, 5, 4], [5, 1, 3], [4, 3, 2], [3, 4, 5]])


@dataclass(frozen=True, eq=False, repr=False)
class Hierarchy:
    """The nested vertex sets of a mesh with subdivision connectivity.

    - ``counts``: ``(n_0, n_1, ..., n_j)`` vertex counts of ``T^0 ... T^j``;
    - ``parents``: ``parents[l]`` is ``(n_{l+1} - n_l, 2) int``: the endpoints of the edge of
      ``T^l`` that each vertex new in ``T^{l+1}`` splits (``p -> q`` along a face of ``T^l``,
      anticlockwise);
    - ``faces``: ``faces[l]`` the ``(4^l m_0, 3)`` faces of ``T^l``;
    - ``on_boundary``: ``on_boundary[l]`` is ``(n_{l+1} - n_l,) bool``: whether that edge is
      on ``T^l``'s boundary.

    Equal only to itself (``eq=False``), so it can be static data of a JAX pytree.
    """

    counts: tuple
    parents: tuple
    faces: tuple
    on_boundary: tuple

    @property
    def levels(self) -> int:
        """The number of refinements ``j``."""
        return len(self.parents)

    def __repr__(self) -> str:
        return f"Hierarchy(levels={self.levels}, counts={self.counts})"


def dyadic_refine(faces: np.ndarray, n_vertices: int):
    """One dyadic refinement (the one-to-four split of §7, Fig. 18).

    **Arguments:** ``faces (m, 3) int`` anticlockwise, over ``n_vertices`` vertices.

    **Returns:** ``(faces (4m, 3), parents (e, 2), on_boundary (e,) bool)``: the new faces
    (anticlockwise; face ``f`` of the input becomes faces ``4f .. 4f+3``, corner children
    first), the two endpoints ``(p, q)`` of each input edge (vertex ``n_vertices + i`` is the
    midpoint of edge ``i``; ``p -> q`` runs along a face, anticlockwise), and whether the
    edge is on the boundary.
    """
    F = np.asarray(faces, np.int64)
    m = F.shape[0]
    # Edge opposite corner i: w_i = (v_{i+1} + v_{i+2}) / 2 (survey's w1, w2, w3).
    src, dst = F[:, [1, 2, 0]], F[:, [2, 0, 1]]
    key = (np.minimum(src, dst) * np.int64(n_vertices) + np.maximum(src, dst)).ravel()
    uniq, first, inverse, count = np.unique(key, return_index=True, return_inverse=True, return_counts=True)
    w = n_vertices + inverse.reshape(m, 3)
    parents = np.stack([src.ravel()[first], dst.ravel()[first]], axis=1)
    children = np.concatenate([F, w], axis=1)[:, CHILDREN]        # (m, 4, 3)
    return children.reshape(4 * m, 3), parents, count == 1


def dyadic_hierarchy(faces: np.ndarray, n_vertices: int, levels: int) -> Hierarchy:
    """``levels`` dyadic refinements of ``faces (m, 3)`` over ``n_vertices`` vertices, as a
    :class:`Hierarchy` (``faces[-1]`` the finest faces, ``counts[-1]`` its vertex count)."""
    F = np.asarray(faces, np.int64)
    counts, parents, all_faces, bnd = [int(n_vertices)], [], [F], []
    for _ in range(int(levels)):
        F, par, on_bnd = dyadic_refine(F, counts[-1])
        counts.append(counts[-1] + par.shape[0])
        parents.append(par)
        all_faces.append(F)
        bnd.append(on_bnd)
    return Hierarchy(tuple(counts), tuple(parents), tuple(all_faces), tuple(bnd))


def split_corner_values(values: np.ndarray) -> np.ndarray:
    """Per-corner values ``(m, 3, d)`` of faces carried to their four children: ``(4m, 3, d)``
    in :func:`dyadic_refine`'s face order, a midpoint's value the mean of its edge's ends.

    For quantities that live on face corners rather than on vertices (a vertex shared by
    several charts has one value in each), e.g. barycentric coordinates in a base face."""
    C = np.asarray(values)
    mid = (C[:, [1, 2, 0]] + C[:, [2, 0, 1]]) / 2                  # w1, w2, w3
    return np.concatenate([C, mid], axis=1)[:, CHILDREN].reshape(-1, 3, C.shape[2])


def midpoint_refine(vertices: np.ndarray, faces: np.ndarray):
    """One dyadic refinement of a mesh's arrays, new vertices at the edge midpoints (the same
    surface, four times the faces).  **Returns:** ``(vertices (n + e, d), faces (4m, 3))``,
    numbered as :func:`dyadic_refine` numbers them."""
    V = np.asarray(vertices)
    F, parents, _ = dyadic_refine(faces, V.shape[0])
    return np.concatenate([V, 0.5 * (V[parents[:, 0]] + V[parents[:, 1]])]), F


def hierarchy_from_faces(faces: np.ndarray, n_vertices: int) -> Hierarchy:
    """Recover the :class:`Hierarchy` of a mesh numbered as :func:`jaxparam.remesh` writes it
    (faces ``4f .. 4f+3`` the children of face ``f`` of the level above, in
    :func:`dyadic_refine`'s order; new vertices after old ones), e.g. one read back from an
    OBJ file.  Coarsens while every group of four faces is such a split.  Raises
    :class:`MeshError` when not even one level is found."""
    F = np.asarray(faces, np.int64)
    levels_faces = [F]
    while F.shape[0] % 4 == 0 and F.shape[0] > 0:
        c = F.reshape(-1, 4, 3)
        v1, v2, v3 = c[:, 0, 0], c[:, 1, 1], c[:, 2, 2]
        w1, w2, w3 = c[:, 1, 2], c[:, 0, 2], c[:, 0, 1]
        ok = (np.array_equal(c[:, 1, 0], w3) and np.array_equal(c[:, 2, 0], w2)
              and np.array_equal(c[:, 2, 1], w1) and np.array_equal(c[:, 3], np.stack([w1, w2, w3], 1)))
        parent = np.stack([v1, v2, v3], 1)
        if not ok or parent.max() >= np.stack([w1, w2, w3]).min():
            break
        levels_faces.append(parent)
        F = parent
    if len(levels_faces) == 1:
        raise MeshError("the mesh does not have subdivision connectivity in jaxparam's numbering "
                        "(each face split into four children, new vertices after old ones): make "
                        "it with jaxparam remesh / jp.remesh at 1 level or more (a remesh of "
                        "level 0 is its base domain alone, with no detail to compress).")
    levels_faces.reverse()
    H = dyadic_hierarchy(levels_faces[0], int(levels_faces[0].max()) + 1, len(levels_faces) - 1)
    for lv in range(1, len(levels_faces)):
        if not np.array_equal(H.faces[lv], levels_faces[lv]):
            raise MeshError(f"the mesh's level {lv} is not numbered as jaxparam's dyadic "
                            "refinement numbers it (new vertices in edge order): make it with "
                            "jaxparam remesh / jp.remesh.")
    if H.counts[-1] != n_vertices:
        raise MeshError(f"the mesh has {n_vertices} vertices but its subdivision hierarchy has "
                        f"{H.counts[-1]}: unreferenced or extra vertices.")
    return H
