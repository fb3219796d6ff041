"""Shape buckets for the host-loop kernels (issue 17, item 2): a minimization's arrays padded
to bucket sizes, so that meshes of similar size, and the atlas's repeated split rounds, share
compiled code.

XLA compiles a kernel once per input shape.  The vertex count ``n``, face count ``m``, free
vertex count ``k`` and Hessian ``nnz`` are each rounded up to :func:`bucket` (steps of
``2 ** (1 / BUCKET_STEPS)``), and the padding contributes exactly nothing:

- padded faces are copies of one *ghost triangle* on three padded vertices, whose frame is
  ``(0, 0), (1, 0), (0, 1)`` and whose fixed UVs ``(0, 0), (2, 0), (0, 1)`` give the finite,
  well-conditioned Jacobian ``diag(2, 1)`` (distinct singular values: no singular
  derivative); its weight (area) is 0 and its Hessian entries land nowhere (``pos = -1``);
- padded free DOFs all write into one *sink* vertex that no face references (x = 0 there,
  gradient exactly 0);
- padded Hessian slots receive no entry.

The sums over faces then see the same nonzero terms, added in a different grouping: results
agree with the unpadded kernels to rounding (about 1e-16 relative), not bitwise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import numpy as np

from .. import geometry as geo
from ..settings import config

__all__ = ["BUCKET_STEPS", "MIN_BUCKET", "bucket", "Padded", "padded_arrays", "pad_positions"]

#: Buckets per doubling: sizes are rounded up to ``MIN_BUCKET * 2 ** (j / BUCKET_STEPS)``
#: (at most 19 % more work in the energy kernels, 9 % on average).
BUCKET_STEPS = 4
#: The smallest bucket: every smaller problem shares it (a kernel over 2048 faces costs
#: microseconds, compiling one costs a second or more).
MIN_BUCKET = 2048

_GHOST_XY = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])     # its frame
_GHOST_UV = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]])     # its fixed UVs: J = diag(2, 1)


def bucket(size: int) -> int:
    """The bucket of ``size >= 0``: the smallest ``ceil(MIN_BUCKET * 2 ** (j / BUCKET_STEPS))``,
    ``j >= 0``, that is at least ``size``; ``size`` itself when ``jp.config.buckets`` is off."""
    if not config.buckets:
        return int(size)
    if size <= MIN_BUCKET:
        return MIN_BUCKET
    j = max(math.ceil(BUCKET_STEPS * math.log2(size / MIN_BUCKET)) - 1, 0)
    while True:
        b = math.ceil(MIN_BUCKET * 2.0 ** (j / BUCKET_STEPS))
        if b >= size:
            return b
        j += 1


@dataclass(frozen=True)
class Padded:
    """A :class:`~jaxparam.optimize.Problem`'s kernel arrays at bucket sizes.

    **Fields:** ``base (N, 2)`` start UVs (sink and ghost rows appended), ``free (K,)``
    (padded with the sink row ``N - 4``), ``F (M, 3)`` (padded with the ghost triangle
    ``N - 3, N - 2, N - 1``), ``frames (M, 3, 2)``, ``areas (M,)`` (0 on ghost faces),
    ``D (M, 4, 6)`` the Jacobian maps; ``k`` and ``m`` the real free-vertex and face counts.
    """

    base: object
    free: object
    F: object
    frames: object
    areas: object
    D: object
    k: int
    m: int

    @property
    def K(self) -> int:
        """The padded free-vertex count."""
        return int(self.free.shape[0])

    def x(self, x) -> np.ndarray:
        """``(2 K,)``: the free DOFs ``x (2 k,)`` with zeros appended (a host array)."""
        out = np.zeros(2 * self.K)
        out[:2 * self.k] = np.asarray(x, np.float64).reshape(-1)
        return out


@jax.jit
def _frames_and_areas(V, F):
    """:func:`jaxparam.geometry.local_frames` and :func:`~jaxparam.geometry.face_areas`."""
    return geo.local_frames(V, F), geo.face_areas(V, F)


def padded_arrays(vertices, faces, free, base, areas=None) -> Padded:
    """:class:`Padded` arrays of one minimization: ``vertices (n, d)``, ``faces (m, 3)``,
    ``free (k,)`` vertex indices, ``base (n, 2)`` start UVs (finite), ``areas (m,)`` the
    face weights (default: the 3D areas)."""
    from .problem import jacobian_maps

    V = np.asarray(vertices, np.float64)
    F = np.asarray(faces, np.int64)
    n, dim = V.shape
    m, k = F.shape[0], int(np.size(free))
    N, M, K = bucket(n + 4), bucket(m), bucket(k)
    ghost = np.arange(N - 3, N)
    Vp = np.zeros((N, dim))
    Vp[:n] = V
    Vp[ghost, :2] = _GHOST_XY
    Fp = np.empty((M, 3), np.int64)
    Fp[:m], Fp[m:] = F, ghost
    Bp = np.zeros((N, 2))
    Bp[:n] = base
    Bp[ghost] = _GHOST_UV
    fp = np.full(K, N - 4, np.int64)
    fp[:k] = free
    # device_put, not jnp.asarray: in this JAX, jnp.asarray of a NumPy array compiles a
    # conversion kernel per new shape; device_put compiles nothing.
    Vj, Fj = jax.device_put(Vp), jax.device_put(Fp)
    if config.buckets:          # one fused kernel a bucket (rounds like the eager ops to 1e-17)
        frames, A = _frames_and_areas(Vj, Fj)
        A = np.array(A)
    else:                       # eager, op by op: bitwise the unpadded problem's
        frames, A = geo.local_frames(Vj, Fj), np.array(geo.face_areas(Vj, Fj))
    A[m:] = 0.0
    if areas is not None:
        A[:m] = np.asarray(areas, np.float64)
    return Padded(base=jax.device_put(Bp), free=jax.device_put(fp), F=Fj, frames=frames,
                  areas=jax.device_put(A), D=jacobian_maps(frames), k=k, m=m)


def pad_positions(pos: np.ndarray, m_padded: int) -> np.ndarray:
    """``(M * 36,)``: the face Hessian entries' CSR slots ``pos (m * 36,)`` with ``-1``
    (land nowhere) for the ghost faces."""
    out = np.full(m_padded * 36, -1, np.int64)
    out[:pos.size] = pos
    return out
