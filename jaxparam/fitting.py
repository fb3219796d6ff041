"""Smooth surfaces over a parameterization (survey §1, eq. (1); Figs. 4, 6, 8).

Given points ``x_i`` with parameters ``u_i`` (a mesh and its UV map, or a
meshless map), build ``s(u) = (s1(u), s2(u), s3(u))`` with ``s(u_i) ~ x_i``:

- ``kind="spline"``: a least-squares tensor-product cubic B-spline over the
  parameters' bounding rectangle (FITPACK's ``LSQBivariateSpline``, uniform
  interior knots, one spline per coordinate);
- ``kind="clough_tocher"``: the C¹ piecewise-cubic Clough–Tocher interpolant
  over the Delaunay triangulation of the parameters (SciPy).

The survey's point: the better the parameterization, the better behaved the
iso-curves of ``s`` (Fig. 6 uniform vs Fig. 8 shape-preserving).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import MeshError
from .mesh import TriMesh, grid_faces
from .options import choose

__all__ = ["Surface", "fit_surface", "KINDS"]

KINDS = ("spline", "clough_tocher")


@dataclass(frozen=True, eq=False)
class Surface:
    """A parametric surface ``s: [u0, u1] x [v0, v1] -> R^3``.

    ``evaluate(uv (q, 2)) -> (q, 3)`` (``nan`` outside the domain for
    Clough–Tocher); ``sample(resolution)`` a grid :class:`TriMesh` of it.
    """

    kind: str
    bbox: tuple
    _eval: object
    residual_rms: float

    def evaluate(self, uv) -> np.ndarray:
        uv = np.atleast_2d(np.asarray(uv, np.float64))
        return self._eval(uv)

    def sample(self, resolution: int = 64) -> TriMesh:
        """A ``resolution x resolution`` grid over the domain, triangulated, clipped to where
        the surface is defined; UVs kept in ``.uv``."""
        (u0, u1), (v0, v1) = self.bbox
        u, v = np.meshgrid(np.linspace(u0, u1, resolution), np.linspace(v0, v1, resolution), indexing="ij")
        UV = np.column_stack([u.ravel(), v.ravel()])
        X = self.evaluate(UV)
        F = grid_faces(resolution, resolution)
        ok = np.all(np.isfinite(X), axis=1)
        F = F[ok[F].all(1)]
        if F.size == 0:
            raise MeshError("fit_surface: the sampled surface is empty; raise the resolution.")
        used = np.unique(F)
        remap = np.full(len(UV), -1, np.int64)
        remap[used] = np.arange(used.size)
        return TriMesh(X[used], remap[F], uv=UV[used], validate=False, name=f"{self.kind}_surface")


def fit_surface(mesh_or_points, uv, *, kind: str = "spline", knots: int | None = None) -> Surface:
    """Fit a smooth surface to points over their parameters (eq. (1)).

    **Arguments:** ``mesh_or_points``: a :class:`TriMesh` or ``(N, 3)`` points;
    ``uv: (N, 2)`` their parameters (``nan`` rows are ignored); ``kind``
    ``"spline"`` or ``"clough_tocher"``; ``knots``: interior knots per direction
    of the spline (default ``~sqrt(N)/3``, at most 40).

    **Returns:** a :class:`Surface`.

    Example::

        surf = jp.fit_surface(mesh, uv, kind="clough_tocher")
        patch = surf.sample(100)
    """
    kind = choose(kind, KINDS, what="kind", where="fit_surface")
    X = np.asarray(mesh_or_points.vertices if isinstance(mesh_or_points, TriMesh) else mesh_or_points,
                   np.float64)
    U = np.asarray(uv, np.float64)
    if U.shape != (X.shape[0], 2):
        raise MeshError(f"fit_surface: uv must have shape ({X.shape[0]}, 2), got {U.shape}.")
    ok = np.all(np.isfinite(U), axis=1) & np.all(np.isfinite(X), axis=1)
    X, U = X[ok], U[ok]
    if X.shape[0] < 16:
        raise MeshError(f"fit_surface: {X.shape[0]} points with parameters are too few (need 16).")
    lo, hi = U.min(0), U.max(0)
    bbox = ((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])))
    if kind == "clough_tocher":
        from scipy.interpolate import CloughTocher2DInterpolator

        f = CloughTocher2DInterpolator(U, X)
        return Surface(kind, bbox, lambda q: np.asarray(f(q)).reshape(-1, 3), 0.0)
    import warnings

    from scipy.interpolate import LSQBivariateSpline

    nk = knots if knots is not None else int(np.clip(np.sqrt(X.shape[0]) / 3, 2, 40))
    tu = np.linspace(lo[0], hi[0], nk + 2)[1:-1]
    tv = np.linspace(lo[1], hi[1], nk + 2)[1:-1]
    eps = 1e-9 * max(hi[0] - lo[0], hi[1] - lo[1])
    box = [lo[0] - eps, hi[0] + eps, lo[1] - eps, hi[1] + eps]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # FITPACK warns when some knot spans hold few points
        splines = [LSQBivariateSpline(U[:, 0], U[:, 1], X[:, c], tu, tv, bbox=box, kx=3, ky=3)
                   for c in range(3)]
    res = np.sqrt(np.mean(np.sum((np.column_stack([s.ev(U[:, 0], U[:, 1]) for s in splines]) - X) ** 2, 1)))

    def ev(q):
        out = np.column_stack([s.ev(q[:, 0], q[:, 1]) for s in splines])
        inside = (q[:, 0] >= lo[0] - eps) & (q[:, 0] <= hi[0] + eps) & (q[:, 1] >= lo[1] - eps) & (q[:, 1] <= hi[1] + eps)
        out[~inside] = np.nan
        return out

    return Surface(kind, bbox, ev, float(res))
