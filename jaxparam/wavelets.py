"""Multiresolution analysis of meshes with subdivision connectivity (survey §7, eq. (12)).

A mesh ``S^j = phi(T^j)`` from :func:`jaxparam.remesh` is a piecewise linear map
``f^j in S^j``; the nested spaces ``S^0 ⊂ S^1 ⊂ ... ⊂ S^j`` split it into a coarse
``f^0`` and details ``g^0, ..., g^{j-1}`` (``f^j = f^0 + g^0 + ... + g^{j-1}``).
Coefficients here are one 3-vector per vertex: the base positions for ``f^0`` and, for each
vertex new at level ``l + 1``, its wavelet coefficient in ``W^l``:

- ``"lazy"``: the interpolating (lazy) wavelet, ``d_w = x_w - (x_p + x_q) / 2`` for the vertex
  ``w`` splitting edge ``p-q``; the coarse levels are sub-samplings of the surface;
- ``"lifted"``: the same prediction followed by a lifting update (Schröder & Sweldens'
  lifting, as in their spherical wavelets, ref. [29]) of every coarse vertex,
  ``x_v += 3 / (4 k_v) * sum of d_w over the k_v new vertices around v``, which keeps the
  mean of the vertex positions from one level to the next on a regular mesh (valence 6);
  the coarse levels are then smoothed, not sampled, approximations.

Both are exactly invertible (:func:`synthesize` undoes :func:`analyze` step by step).
:func:`compress` keeps the largest coefficients, measured in the L2 norm of their hat
functions (``|d| 2^-l`` at level ``l``), and returns a :class:`Compressed`.

The input is a :class:`jaxparam.remesh.Remesh` (from :func:`jaxparam.remesh` or
:meth:`jaxparam.manifold.ManifoldParameterization.remesh`), a :class:`Compressed`, or a
:class:`~jaxparam.TriMesh` numbered as they write it (e.g. read back from an OBJ file), whose
:class:`~jaxparam.subdivision.Hierarchy` is then read from its faces or given as
``hierarchy=``.

Everything is written in JAX: analysis, synthesis and compression are differentiable (the
compression with its choice of kept coefficients held fixed, see :func:`compress`), they run
under ``jax.jit``, and the results are pytrees.
"""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .errors import MeshError
from .mesh import TriMesh
from .remesh import Remesh
from .subdivision import Hierarchy, hierarchy_from_faces

__all__ = ["WAVELETS", "Coefficients", "Compressed", "analyze", "synthesize", "compress"]

#: The wavelets :func:`analyze` knows.
WAVELETS = ("lazy", "lifted")


@jax.tree_util.register_pytree_node_class
@dataclass(frozen=True, eq=False)
class Coefficients:
    """``base (n_0, 3)``: positions of the base vertices (after lifting, for ``"lifted"``);
    ``details``: ``details[l]`` the ``(n_{l+1} - n_l, 3)`` coefficients of level ``l``;
    ``hierarchy`` and ``wavelet`` as analysed.  A JAX pytree (``base`` and ``details`` the
    leaves)."""

    base: jnp.ndarray
    details: tuple
    hierarchy: Hierarchy
    wavelet: str

    @property
    def count(self) -> int:
        """Number of wavelet coefficients (3-vectors) over all levels."""
        return int(sum(d.shape[0] for d in self.details))

    def tree_flatten(self):
        return (self.base, self.details), (self.hierarchy, self.wavelet)

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls(children[0], tuple(children[1]), *aux)


def _check_wavelet(wavelet: str) -> None:
    if wavelet not in WAVELETS:
        raise MeshError(f"wavelets: unknown wavelet {wavelet!r}; use one of {WAVELETS}.")


@jax.tree_util.register_pytree_node_class
@dataclass(frozen=True, eq=False, repr=False)
class Compressed:
    """What :func:`compress` returns.

    - ``mesh``: a :class:`TriMesh` with the input's connectivity, vertex order and UVs, its
      vertices synthesized from the kept coefficients;
    - ``hierarchy``: the input's :class:`~jaxparam.subdivision.Hierarchy`;
    - ``kept``: the number of wavelet coefficients (3-vectors) kept;
    - ``stored_fraction``: the base vertices plus the kept coefficients over the vertex
      count (the survey's "less than 2 %").

    A JAX pytree: ``mesh`` is the leaf, the rest static data.
    """

    mesh: TriMesh
    hierarchy: Hierarchy
    kept: int
    stored_fraction: float

    def __repr__(self) -> str:
        return (f"Compressed({self.mesh!r}, kept {self.kept} coefficients, "
                f"{100 * self.stored_fraction:.2f} % stored)")

    def tree_flatten(self):
        return (self.mesh,), (self.hierarchy, self.kept, self.stored_fraction)

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls(children[0], *aux)


def _mesh_and_hierarchy(semi, hierarchy, where: str):
    """The mesh and hierarchy of a :class:`Remesh`, a :class:`Compressed` or a TriMesh."""
    if isinstance(semi, (Remesh, Compressed)):
        if hierarchy is not None:
            raise MeshError(f"wavelets.{where}: hierarchy= is for a TriMesh; a {type(semi).__name__} "
                            "carries its own.")
        return semi.mesh, semi.hierarchy
    if not isinstance(semi, TriMesh):
        raise MeshError(f"wavelets.{where}: expected a Remesh (jp.remesh), a Compressed or a TriMesh, "
                        f"got {type(semi).__name__}.")
    if hierarchy is None:
        hierarchy = hierarchy_from_faces(semi.faces, semi.n_vertices)
    elif not isinstance(hierarchy, Hierarchy) or hierarchy.counts[-1] != semi.n_vertices:
        raise MeshError(f"wavelets.{where}: hierarchy must be a Hierarchy of the mesh's "
                        f"{semi.n_vertices} vertices.")
    return semi, hierarchy


def _update_weights(H: Hierarchy, level: int) -> np.ndarray:
    """``(n_level,)``: the lifting weight ``3 / (4 k_v)`` of each coarse vertex, ``k_v`` its
    number of new neighbours (edges of ``T^level`` at ``v``); 0 where it has none."""
    k = np.bincount(H.parents[level].ravel(), minlength=H.counts[level])
    return np.where(k > 0, 0.75 / np.maximum(k, 1), 0.0)


def _lift(X, H: Hierarchy, level: int, d, sign: float):
    par = H.parents[level]
    sigma = jnp.asarray(_update_weights(H, level))
    s = jnp.zeros_like(X).at[par[:, 0]].add(d).at[par[:, 1]].add(d)
    return X + sign * sigma[:, None] * s


def analyze(semi, *, wavelet: str = "lifted", hierarchy: Hierarchy | None = None) -> Coefficients:
    """Wavelet decomposition of a mesh with subdivision connectivity (eq. (12)).

    **Arguments:** ``semi`` a :class:`~jaxparam.remesh.Remesh` (:func:`jaxparam.remesh`), a
    :class:`Compressed`, or a :class:`TriMesh` whose faces and vertex order are as they
    write them; ``wavelet`` ``"lifted"`` or ``"lazy"``; ``hierarchy`` only with a TriMesh:
    its :class:`~jaxparam.subdivision.Hierarchy` (read from its faces when left out).

    **Returns:** :class:`Coefficients`.

    Example::

        c = jp.wavelets.analyze(semi)
        jp.wavelets.synthesize(c)        # == semi.mesh.vertices up to rounding
    """
    _check_wavelet(wavelet)
    mesh, H = _mesh_and_hierarchy(semi, hierarchy, "analyze")
    X = jnp.asarray(mesh.vertices, dtype=jnp.float64)
    details = []
    for level in reversed(range(H.levels)):
        n = H.counts[level]
        par = H.parents[level]
        coarse, new = X[:n], X[n:H.counts[level + 1]]
        d = new - 0.5 * (coarse[par[:, 0]] + coarse[par[:, 1]])
        if wavelet == "lifted":
            coarse = _lift(coarse, H, level, d, +1.0)
        details.append(d)
        X = coarse
    return Coefficients(X, tuple(reversed(details)), H, wavelet)


def synthesize(coeffs: Coefficients, *, level: int | None = None):
    """The vertex positions rebuilt from ``coeffs``: ``(n_j, 3)``, or with ``level=l`` the
    ``(n_l, 3)`` positions of ``T^l``'s vertices in the level-``l`` approximation ``f^l``."""
    H = coeffs.hierarchy
    top = H.levels if level is None else int(level)
    if not 0 <= top <= H.levels:
        raise MeshError(f"wavelets.synthesize: level must be in [0, {H.levels}], got {level!r}.")
    X = coeffs.base
    for lv in range(top):
        d = coeffs.details[lv]
        if coeffs.wavelet == "lifted":
            X = _lift(X, H, lv, d, -1.0)
        par = H.parents[lv]
        X = jnp.concatenate([X, 0.5 * (X[par[:, 0]] + X[par[:, 1]]) + d])
    return X


def compress(semi, keep: float = 0.02, *, wavelet: str = "lifted",
             hierarchy: Hierarchy | None = None) -> Compressed:
    """Keep the largest fraction ``keep`` of the wavelet coefficients, drop the rest, and
    synthesize (the survey's data compression, §7 and Fig. 26).

    **Arguments:** ``semi`` as :func:`analyze` takes it (a :func:`jaxparam.remesh` result, or
    a TriMesh with ``hierarchy``); ``keep`` in ``[0, 1]``; ``wavelet`` ``"lifted"`` or
    ``"lazy"``.

    **Returns:** a :class:`Compressed`: ``.mesh`` with ``semi``'s connectivity, vertex order
    and UVs, ``.kept`` the number of coefficients kept, ``.stored_fraction`` the base
    vertices plus kept coefficients over the vertex count.

    Example::

        small = jp.wavelets.compress(semi, keep=0.02)
        jp.save("small.obj", small.mesh)

    **Which coefficients.** The ``k = round(keep * count)`` coefficients with the largest
    scores ``|d| 2^-l`` (ties to the lower index: base-first level order, then vertex order),
    chosen by ``jax.lax.top_k``, so the count ``k`` is static and ``compress`` runs under
    ``jax.jit`` too.

    **Differentiable** in ``semi``'s vertex positions (``jax.grad``, ``jax.jvp``, under
    ``jax.jit``): the result is ``synthesize`` of the base and the kept coefficients, linear
    in the positions for a given choice.  **Held fixed**: the choice of kept coefficients (the
    mask).  It is made on the values with the gradient stopped, so it is piecewise constant in
    the positions, and the derivative is that of the compression with the mask frozen: exact
    wherever a small move leaves the ranking of the scores at the ``k``-th place unchanged (no
    tie between the last kept and the first dropped score).
    """
    if not (isinstance(keep, (int, float, np.floating)) and 0.0 <= float(keep) <= 1.0):
        raise MeshError(f"wavelets.compress: keep must be a fraction in [0, 1], got {keep!r}.")
    mesh, H = _mesh_and_hierarchy(semi, hierarchy, "compress")
    c = analyze(mesh, wavelet=wavelet, hierarchy=H)
    sizes = [d.shape[0] for d in c.details]
    n_keep = int(round(float(keep) * c.count))
    if n_keep == 0:
        details = tuple(jnp.zeros_like(d) for d in c.details)
    elif n_keep == c.count:
        details = c.details
    else:
        stopped = [jax.lax.stop_gradient(d) for d in c.details]
        try:         # concrete values (eager, or under jax.grad): the scores as numpy computes them
            score = jnp.asarray(np.concatenate([np.linalg.norm(np.asarray(d), axis=1) * 2.0 ** -lv
                                                for lv, d in enumerate(stopped)]))
        except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
            score = jnp.concatenate([jnp.linalg.norm(d, axis=1) * 2.0 ** -lv
                                     for lv, d in enumerate(stopped)])        # under jax.jit
        chosen = jnp.zeros(c.count, bool).at[jax.lax.top_k(score, n_keep)[1]].set(True)
        starts = np.concatenate([[0], np.cumsum(sizes)])
        details = tuple(jnp.where(chosen[a:b, None], d, 0.0)
                        for a, b, d in zip(starts[:-1], starts[1:], c.details))
    X = synthesize(Coefficients(c.base, details, H, wavelet))
    return Compressed(mesh.with_vertices(X), H, n_keep, (H.counts[0] + n_keep) / mesh.n_vertices)
