"""Smooth surfaces over a parameterization (survey §1, eq. (1); Figs. 4, 6, 8).

Given points ``x_i`` with parameters ``u_i`` (a mesh and its UV map, or a
meshless map), build ``s(u) = (s1(u), s2(u), s3(u))`` with ``s(u_i) ~ x_i``:

- ``kind="spline"``: a least-squares tensor-product cubic B-spline over the
  parameters' bounding rectangle (uniform interior knots, one spline per
  coordinate; the least-squares problem FITPACK's ``LSQBivariateSpline`` solves,
  solved here in JAX);
- ``kind="clough_tocher"``: the C¹ piecewise-cubic Clough–Tocher interpolant
  over the Delaunay triangulation of the parameters (SciPy's
  ``CloughTocher2DInterpolator``, with a JAX derivative).

Both are differentiable in the points ``x_i``, the parameters ``u_i`` and the
places ``uv`` where the surface is evaluated, with their discrete choices held
fixed: see :func:`fit_surface`.

The survey's point: the better the parameterization, the better behaved the
iso-curves of ``s`` (Fig. 6 uniform vs Fig. 8 shape-preserving).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np

from . import sparse
from .errors import MeshError
from .mesh import TriMesh, concrete_values, grid_faces
from .io import as_mesh
from .options import choose, is_integer, is_number
from .triangles import barycentric

__all__ = ["Surface", "fit_surface", "KINDS", "SMOOTHING"]

KINDS = ("spline", "clough_tocher")
#: :func:`fit_surface`'s default spline penalty (relative; its docstring gives the figures).
SMOOTHING = 1e-4


def _traced(*arrays) -> bool:
    return any(isinstance(a, jax.core.Tracer) for a in arrays)


@dataclass(frozen=True, eq=False)
class Surface:
    """A parametric surface ``s: [u0, u1] x [v0, v1] -> R^3``.

    ``evaluate(uv (q, 2)) -> (q, 3)`` (``nan`` outside the domain for
    Clough–Tocher); ``sample(resolution)`` a grid :class:`TriMesh` of it.

    Built from concrete data and evaluated at concrete ``uv`` the values are NumPy
    arrays; when the data (:func:`fit_surface` called under ``jax.grad``) or ``uv``
    are traced they are JAX arrays, differentiable in both (``residual_rms`` is then a
    JAX scalar too).

    Pickles (for ``multiprocessing``, ``joblib``, caches) when fitted to concrete data: as
    the points and parameters it was fitted to, fitted again on loading (the same values,
    bit for bit).  A surface fitted to traced data refuses to pickle.
    """

    kind: str
    bbox: tuple
    _eval: object
    residual_rms: float
    _defined: object = None
    #: ``(points (N, 3), uv (N, 2), kind, knots, smoothing)`` of a fit to concrete data
    _source: tuple | None = None

    def __reduce__(self):
        if self._source is None:
            raise MeshError("fit_surface: a Surface fitted to traced points or parameters (under "
                            "jax.grad or jax.jit) cannot be pickled; fit it again from concrete "
                            "arrays, or pickle the arrays.")
        return _refit, self._source

    def evaluate(self, uv):
        if isinstance(uv, jax.core.Tracer):
            uv = jnp.atleast_2d(jnp.asarray(uv, jnp.float64))
        else:
            uv = np.atleast_2d(np.asarray(uv, np.float64))
        return self._eval(uv)

    def sample(self, resolution: int = 64) -> TriMesh:
        """A ``resolution x resolution`` grid over the domain, triangulated, clipped to where
        the surface is defined; UVs kept in ``.uv``.  Raises :class:`MeshError` unless
        ``resolution`` is an integer of at least 2."""
        if not (is_integer(resolution) and resolution >= 2):
            raise MeshError(f"fit_surface: the sampling resolution (grid points along each side) "
                            f"must be an integer >= 2, got {resolution!r}.")
        (u0, u1), (v0, v1) = self.bbox
        u, v = np.meshgrid(np.linspace(u0, u1, resolution), np.linspace(v0, v1, resolution), indexing="ij")
        UV = np.column_stack([u.ravel(), v.ravel()])
        X = self.evaluate(UV)
        F = grid_faces(resolution, resolution)
        Xc = concrete_values(X)
        ok = np.all(np.isfinite(Xc), axis=1) if Xc is not None else self._defined(UV)
        F = F[ok[F].all(1)]
        if F.size == 0:
            raise MeshError("fit_surface: the sampled surface is empty; raise the resolution.")
        used = np.unique(F)
        remap = np.full(len(UV), -1, np.int64)
        remap[used] = np.arange(used.size)
        return TriMesh(X[used], remap[F], uv=UV[used], validate=False, name=f"{self.kind}_surface")


def fit_surface(mesh_or_points, uv, *, kind: str = "spline", knots: int | None = None,
                smoothing: float = SMOOTHING) -> Surface:
    """Fit a smooth surface to points over their parameters (eq. (1)).

    **Arguments:** ``mesh_or_points``: a :class:`TriMesh` or ``(N, 3)`` points;
    ``uv: (N, 2)`` their parameters (``nan`` rows are ignored); ``kind``
    ``"spline"`` or ``"clough_tocher"``; ``knots``: interior knots per direction
    of the spline (default ``~sqrt(N)/3``, at most 40); ``smoothing``: the spline's
    penalty on the second differences of its coefficients, relative (below; 0: plain
    least squares, FITPACK's).

    **Returns:** a :class:`Surface`.

    Example::

        surf = jp.fit_surface(mesh, uv, kind="clough_tocher")
        patch = surf.sample(100)

    **The spline.** The cubic tensor-product B-spline on the knots
    ``[a]*4 + interior + [b]*4`` of each direction, ``[a, b]`` the parameters' range
    widened by ``1e-9`` of its size (as FITPACK's ``LSQBivariateSpline`` takes them),
    whose coefficients ``C`` minimize ``|B C - X|^2 + lam |D C|^2``: ``D`` the second
    differences of the coefficient grid along each direction (a P-spline penalty, Eilers
    & Marx 1996; it leaves the bilinear functions alone), ``lam = smoothing tr(B^T B) /
    tr(D^T D)``.  Without it (``smoothing=0``) the coefficients of basis functions that
    see few parameters are barely determined: over a disk's circle map a plain
    least-squares spline swung to 7.6e9 in the rectangle's empty corners for a mesh of
    size 12, and to 2.5e4 inside the disk where the parameters were sparse (session 20,
    a held-out ``jaxparam fit`` of halftunnel's flattening; camelhead's circle map: 1.2e7
    for a mesh of size 0.53).  At the default 1e-4 the residual at the points rises by
    0.1-2.5 % (lilium, snail, halftunnel, camelhead) and the surface sampled over the
    parameters' hull stays within 1.4x the points' extent (1e-6: up to 18x).  One Cholesky solve
    of ``B^T B + lam D^T D`` with three steps of iterative refinement (JAX, differentiable,
    ``lam`` too).  With ``smoothing=0`` it agrees with FITPACK's
    ``LSQBivariateSpline`` to about ``1e-10`` relative (tested), solved as follows
    (coefficients ``C`` as JAX linear solves): basis functions that meet no parameter get ``C = 0``;
    when the others are well determined (as many points as coefficients, the
    column-scaled normal matrix of reciprocal condition above ``1e-13``), Cholesky on
    the column-scaled normal equations ``B^T B C = B^T X`` with three steps of
    iterative refinement (memory ``O(N + M^2)`` for ``M`` coefficients); otherwise the
    minimum-norm least-squares solution, as FITPACK gives it, from a pivoted QR of
    the dense ``(N, M)`` design matrix (rank and pivots from the concrete values).

    Both kinds are defined on the convex hull of the parameters (``nan`` outside;
    :meth:`Surface.sample` keeps the grid faces inside): beyond the points there is
    nothing to fit, and a spline there only extrapolates.

    **The Clough–Tocher interpolant.** The values are SciPy's, unchanged.  The
    derivative is that of the same interpolant with its vertex gradients solved
    exactly (SciPy stops its Gauss–Seidel iteration at a tolerance of ``1e-6``): the
    global curvature-minimizing system of ``2N`` equations, one sparse Cholesky
    solve (:func:`jaxparam.sparse.solve`), and the Clough–Tocher patches evaluated
    in JAX.  SciPy's values and those of the exactly solved interpolant differ by
    about ``1e-8`` of the surface's size (measured on the test meshes), its
    gradient estimates by about ``1e-7``: the forward values and the map whose
    derivative is returned differ by that much.

    **Differentiable** under ``jax.grad`` and ``jax.jvp``: in the points (both kinds
    are linear in them for fixed parameters), in the parameters ``uv`` and in the
    evaluation places (``Surface.evaluate(uv)``, ``Surface.sample``'s points).
    **Held fixed** (chosen on the concrete values): the rows kept (finite ``uv`` and
    points; for a mesh, the vertices some face uses), the bounding rectangle ``bbox`` and so the knots (moving parameters
    do not move them), and which spline coefficients are zero, the rank and the
    pivots; for Clough–Tocher the Delaunay triangulation, the triangle holding each
    evaluation place and which places are outside (``nan``).  Under ``jax.jit`` the
    points and the evaluation places may be traced, not ``uv`` (the knots and the
    triangulation need its values; a :class:`MeshError` says so); rows are then
    filtered on ``uv`` alone.
    """
    if not hasattr(mesh_or_points, "shape"):
        mesh_or_points = as_mesh(mesh_or_points, "fit_surface")
    kind = choose(kind, KINDS, what="kind", where="fit_surface")
    if not (is_number(smoothing) and np.isfinite(smoothing) and smoothing >= 0):
        raise MeshError(f"fit_surface: smoothing must be a number >= 0 (0: plain least squares), "
                        f"got {smoothing!r}.")
    if hasattr(uv, "uv_faces") and hasattr(uv, "chart"):
        raise MeshError("fit_surface: got an Atlas, whose charts lie side by side in [0, 1]^2 with "
                        "UVs per face corner; a surface is fitted over one chart, uv of shape "
                        "(N, 2) with one parameter per point (e.g. jp.convex_map(mesh) of a disk). "
                        "Fit one chart at a time: the faces where atlas.chart == c, with their "
                        "vertices' UVs from atlas.uv[atlas.uv_faces].")
    if not isinstance(uv, jax.core.Tracer):
        try:
            np.asarray(uv, np.float64)
        except (TypeError, ValueError):
            raise MeshError(f"fit_surface: uv must be an (N, 2) array of parameters, got "
                            f"{type(uv).__name__}.") from None
    X_in = mesh_or_points.vertices if isinstance(mesh_or_points, TriMesh) else mesh_or_points
    Uc = concrete_values(uv)
    if Uc is None:
        raise MeshError("fit_surface: uv is traced without a value (inside jax.jit or jax.vmap); "
                        "the knots and the triangulation are chosen from its values: call "
                        "fit_surface outside jax.jit (jax.grad and jax.jvp are fine), or pass "
                        "concrete uv (the points may be traced).")
    n_pts = np.shape(X_in)[0] if np.ndim(X_in) else 0
    if Uc.shape != (n_pts, 2):
        raise MeshError(f"fit_surface: uv must have shape ({n_pts}, 2), got {Uc.shape}.")
    Xc = concrete_values(X_in)
    ok = np.all(np.isfinite(Uc), axis=1)
    if isinstance(mesh_or_points, TriMesh):
        # a vertex no face uses is not on the surface (e.g. a reconstruction's outliers, which
        # carry their nearest kept point's UV): it would be a second value at the same place
        ok &= np.asarray(mesh_or_points.topology.referenced, bool)
    if Xc is not None:
        ok &= np.all(np.isfinite(Xc), axis=1)
    if int(ok.sum()) < 16:
        raise MeshError(f"fit_surface: {int(ok.sum())} points with parameters are too few: both "
                        "surfaces need at least 16 (the spline's smallest grid of coefficients is "
                        "6 x 6); refine the mesh first (jp.shapes.refine(mesh), then flatten it "
                        "again) or sample more points.")
    rows = np.flatnonzero(ok)
    X = jnp.asarray(X_in, jnp.float64)[rows] if isinstance(X_in, jax.core.Tracer) else Xc[ok]
    U = jnp.asarray(uv, jnp.float64)[rows] if isinstance(uv, jax.core.Tracer) else Uc[ok]
    Xc = Xc[ok] if Xc is not None else None
    Uc = Uc[ok]
    lo, hi = Uc.min(0), Uc.max(0)
    bbox = ((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])))
    if kind == "clough_tocher":
        surf = _clough_tocher(U, X, Uc, Xc, bbox)
    else:
        surf = _spline(U, X, Uc, lo, hi, bbox, knots, float(smoothing))
    if _traced(U, X):
        return surf
    return dataclasses.replace(surf, _source=(Xc, Uc, kind, knots, float(smoothing)))


def _refit(points, uv, kind, knots, smoothing) -> Surface:
    """A pickled :class:`Surface`, fitted again (``Surface.__reduce__``)."""
    return fit_surface(points, uv, kind=kind, knots=knots, smoothing=smoothing)


# ---------------------------------------------------------------------------------------------
# Tensor-product cubic B-splines


def _spans(T: np.ndarray, u, xp):
    """The knot span ``k`` (``T[k] <= u < T[k+1]``, the last closed) of each ``u``: basis
    functions ``k-3 .. k`` are those not zero there."""
    return xp.clip(xp.searchsorted(T, u, side="right") - 1, 3, len(T) - 5)


def _cubic_basis(T: np.ndarray, k, u, xp):
    """``(n, 4)``: the cubic B-splines ``k-3 .. k`` on the knots ``T`` at ``u (n,)``
    (Cox–de Boor's triangular scheme; ``k`` from :func:`_spans`)."""
    T = xp.asarray(T)
    N = [xp.ones_like(u)]
    left, right = [None] * 4, [None] * 4
    for j in range(1, 4):
        left[j], right[j] = u - T[k + 1 - j], T[k + j] - u
        saved, nxt = 0.0, []
        for r in range(j):
            temp = N[r] / (right[r + 1] + left[j - r])
            nxt.append(saved + right[r + 1] * temp)
            saved = left[j - r] * temp
        N = nxt + [saved]
    return xp.stack(N, axis=1)


def _design_rows(Tu, Tv, q, ku, kv, xp):
    """The design matrix's non-zeros at the points ``q (n, 2)``: ``(cols (n, 16) int,
    vals (n, 16))``; coefficient ``(i, j)`` is column ``i * (len(Tv) - 4) + j``."""
    nv = len(Tv) - 4
    Bu, Bv = _cubic_basis(Tu, ku, q[:, 0], xp), _cubic_basis(Tv, kv, q[:, 1], xp)
    a = np.arange(4)
    cols = ((ku - 3)[:, None, None] + a[None, :, None]) * nv + (kv - 3)[:, None, None] + a[None, None, :]
    vals = Bu[:, :, None] * Bv[:, None, :]
    return cols.reshape(-1, 16), vals.reshape(-1, 16)


def _apply(cols, vals, C):
    """``B C`` from the non-zeros of ``B``: ``(n, 3)`` (JAX)."""
    return jnp.einsum("nk,nkd->nd", vals, C[cols])


class _Rows:
    """The design matrix ``(N, M)`` from its non-zeros ``cols``, ``vals`` (``(N, 16)``), with
    the products the solve needs: NumPy/SciPy (``xp=np``) or JAX (``xp=jnp``, differentiable
    in ``vals``)."""

    def __init__(self, cols, vals, M: int, xp):
        self.cols, self.vals, self.M, self.xp = cols, vals, M, xp
        self.N = cols.shape[0]
        if xp is np:
            import scipy.sparse as sps

            self.B = sps.csr_matrix((vals.ravel(), cols.ravel(), np.arange(0, vals.size + 1, 16)),
                                    shape=(self.N, M))

    def mv(self, Z):
        return self.B @ Z if self.xp is np else _apply(self.cols, self.vals, Z)

    def rmv(self, R):
        if self.xp is np:
            return self.B.T @ R
        return jnp.zeros((self.M, R.shape[1]), R.dtype).at[self.cols].add(
            self.vals[:, :, None] * R[:, None, :])

    def gram(self):
        if self.xp is np:
            return (self.B.T @ self.B).toarray()
        v = self.vals
        return jnp.zeros((self.M, self.M), v.dtype).at[self.cols[:, :, None], self.cols[:, None, :]].add(
            v[:, :, None] * v[:, None, :])

    def dense(self):
        if self.xp is np:
            return self.B.toarray()
        return jnp.zeros((self.N, self.M), self.vals.dtype).at[
            jnp.arange(self.N)[:, None], self.cols].add(self.vals)


def _add_rows(xp, Z, rows, V):
    if xp is np:
        Z = Z.copy()
        Z[rows] += V
        return Z
    return Z.at[rows].add(V)


def second_differences(nu: int, nv: int) -> np.ndarray:
    """``D^T D (nu nv, nu nv)`` of the second differences along both directions of an
    ``nu x nv`` coefficient grid (coefficient ``(i, j)`` at ``i nv + j``); its null space is
    the bilinear ``a + b i + c j + d i j``."""
    def along(n):
        D = np.diff(np.eye(n), 2, axis=0)
        return D.T @ D
    return np.kron(along(nu), np.eye(nv)) + np.kron(np.eye(nu), along(nv))


def _lsq_coefficients(cols, vals, X, cols_c, vals_c, M: int, xp, penalty=None):
    """The least-squares spline coefficients ``(M, 3)`` (see :func:`fit_surface`), in NumPy
    (``xp=np``) or JAX (``xp=jnp``, differentiable in ``vals`` and ``X``); the structure
    (zero columns, conditioning, rank, pivots) from the concrete ``cols_c``, ``vals_c``.
    ``penalty``: ``(smoothing, D^T D (M, M))``, whose ``lam D^T D`` (``lam = smoothing
    tr(B^T B) / tr(D^T D)``, differentiable through ``B``) is added to the normal matrix
    (None: plain least squares)."""
    import scipy.linalg as sl

    lin = sl if xp is np else jsl
    if penalty is not None:
        smoothing, P = penalty
        scale = smoothing / float(np.trace(P))
        lamP_c = scale * float(np.sum(vals_c * vals_c)) * P
        Lc, info = sl.lapack.dpotrf(_Rows(cols_c, vals_c, M, np).gram() + lamP_c, lower=1)
        if info == 0:             # else the parameters fix no bilinear function: as below
            B = _Rows(cols, vals, M, xp)
            if xp is np and vals is vals_c:
                lamP, cf = lamP_c, (Lc, True)          # the check's factor is this matrix's
            else:
                lamP = scale * xp.sum(vals * vals) * xp.asarray(P)
                cf = lin.cho_factor(B.gram() + lamP, lower=True)
            Z = lin.cho_solve(cf, B.rmv(X))
            for _ in range(3):    # refinement: the normal matrix's condition is ~1e10 here
                Z = Z + lin.cho_solve(cf, B.rmv(X - B.mv(Z)) - lamP @ Z)
            return Z
    colsq = np.bincount(cols_c.ravel(), weights=(vals_c * vals_c).ravel(), minlength=M)
    active = colsq > 0
    act = np.flatnonzero(active)
    N = cols_c.shape[0]
    scale = np.where(active, 1.0 / np.sqrt(np.where(active, colsq, 1.0)), 0.0)
    well = False
    if N >= act.size:
        G = _Rows(cols_c, vals_c * scale[cols_c], M, np).gram()[np.ix_(act, act)]
        Lc, info = sl.lapack.dpotrf(G, lower=1)
        if info == 0:
            rcond, info2 = sl.lapack.dpocon(Lc, np.abs(G).sum(0).max(), uplo="L")
            well = info2 == 0 and rcond > 1e-13
    if well:
        # Column-scaled normal equations, Cholesky, three steps of iterative refinement.
        B = _Rows(cols, vals * xp.asarray(scale)[cols], M, xp)
        if xp is np and vals is vals_c:
            cf = (Lc, True)                    # the factor of the check is this matrix's
        else:
            cf = lin.cho_factor(B.gram()[np.ix_(act, act)], lower=True)
        Z, R = xp.zeros((M, X.shape[1])), X
        for _ in range(4):
            Z = _add_rows(xp, Z, act, lin.cho_solve(cf, B.rmv(R)[act]))
            R = X - B.mv(Z)
        return Z * xp.asarray(scale)[:, None]
    # Minimum-norm least squares with the rank and pivots of the concrete matrix: B P = Q1 T
    # (T of full row rank r), the solutions of T c = Q1^T X, the shortest from a QR of T^T.
    _, Rp, perm = sl.qr(_Rows(cols_c, vals_c, M, np).dense()[:, act], mode="economic", pivoting=True)
    d = np.abs(np.diag(Rp))
    r = int(np.sum(d > max(N, act.size) * np.finfo(float).eps * d[0]))
    B = _Rows(cols, vals, M, xp).dense()[:, act[perm]]
    Q1, _ = xp.linalg.qr(B[:, :r])
    Q2, R2 = xp.linalg.qr((Q1.T @ B).T)
    c = Q2 @ lin.solve_triangular(R2, Q1.T @ X, trans="T", lower=False)
    return _add_rows(xp, xp.zeros((M, X.shape[1])), act[perm], c)


def _spline(U, X, Uc, lo, hi, bbox, knots, smoothing) -> Surface:
    nk = knots if knots is not None else int(np.clip(np.sqrt(Uc.shape[0]) / 3, 2, 40))
    tu = np.linspace(lo[0], hi[0], nk + 2)[1:-1]
    tv = np.linspace(lo[1], hi[1], nk + 2)[1:-1]
    eps = 1e-9 * max(hi[0] - lo[0], hi[1] - lo[1])
    box = (lo[0] - eps, hi[0] + eps, lo[1] - eps, hi[1] + eps)
    Tu = np.concatenate([[box[0]] * 4, tu, [box[1]] * 4])
    Tv = np.concatenate([[box[2]] * 4, tv, [box[3]] * 4])
    M = (len(Tu) - 4) * (len(Tv) - 4)
    ku, kv = _spans(Tu, Uc[:, 0], np), _spans(Tv, Uc[:, 1], np)
    cols_c, vals_c = _design_rows(Tu, Tv, Uc, ku, kv, np)
    traced = _traced(U, X)
    xp = jnp if traced else np
    cols, vals = _design_rows(Tu, Tv, U, ku, kv, jnp) if isinstance(U, jax.core.Tracer) else (cols_c, vals_c)
    penalty = (smoothing, second_differences(len(Tu) - 4, len(Tv) - 4)) if smoothing > 0 else None
    C = _lsq_coefficients(cols, vals if xp is np else jnp.asarray(vals), xp.asarray(X), cols_c, vals_c,
                          M, xp, penalty)
    R = _Rows(cols, xp.asarray(vals), M, xp).mv(C) - X
    res = xp.sqrt(xp.mean(xp.sum(R * R, axis=1)))
    if not traced:
        res = float(res)

    hull = _hull_halfplanes(Uc)

    def inside(q):
        return hull(q) & (q[:, 0] >= box[0]) & (q[:, 0] <= box[1]) & (q[:, 1] >= box[2]) & (q[:, 1] <= box[3])

    def ev(q):
        qc = concrete_values(q)
        xp = np if qc is not None else jnp
        src = qc if qc is not None else q
        ku, kv = _spans(Tu, src[:, 0], xp), _spans(Tv, src[:, 1], xp)
        if not (traced or isinstance(q, jax.core.Tracer)):
            c, v = _design_rows(Tu, Tv, q, ku, kv, np)
            out = np.einsum("nk,nkd->nd", v, C[c])
            out[~inside(q)] = np.nan
            return out
        c, v = _design_rows(Tu, Tv, jnp.asarray(q), ku, kv, jnp)
        return jnp.where(inside(src)[:, None], _apply(c, v, jnp.asarray(C)), jnp.nan)

    return Surface("spline", bbox, ev, res, inside)


def _hull_halfplanes(Uc: np.ndarray):
    """``inside(q (n, 2)) -> (n,) bool``: within the convex hull of ``Uc (N, 2)``, widened by
    ``1e-9`` of its size (NumPy or JAX ``q``); everywhere when the points span no area."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        eq = ConvexHull(Uc).equations
    except QhullError:
        return lambda q: q[:, 0] == q[:, 0]
    tol = 1e-9 * float(np.max(np.ptp(Uc, axis=0)))

    def inside(q):
        a, b, c = (np.asarray(eq[None, :, i]) for i in range(3))
        return (q[:, :1] * a + q[:, 1:2] * b + c <= tol).all(axis=1)

    return inside


# ---------------------------------------------------------------------------------------------
# Clough–Tocher


def _ct_gradient_system(tri):
    """The pattern of the curvature-minimizing gradient system (SciPy's
    ``estimate_gradients_2d_global``, solved exactly): ``(pattern, i, j, pos)``: the directed
    edges ``i -> j`` and, for each of their 8 contributions (4 to the ``(i, i)`` block, 4 to
    ``(i, j)``, components ``a, b`` in row-major order), the entry of ``pattern`` it adds to."""
    indptr, indices = tri.vertex_neighbor_vertices
    n = tri.npoints
    i = np.repeat(np.arange(n), np.diff(indptr)).astype(np.int64)
    j = indices.astype(np.int64)
    rows, cols = [], []
    for a in range(2):
        for b in range(2):
            rows += [2 * i + a, 2 * i + a]
            cols += [2 * i + b, 2 * j + b]
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    key = rows * (2 * n) + cols
    uniq, pos = np.unique(key, return_inverse=True)
    r, c = uniq // (2 * n), uniq % (2 * n)
    ptr = np.zeros(2 * n + 1, np.int64)
    np.cumsum(np.bincount(r, minlength=2 * n), out=ptr[1:])
    return sparse.Pattern(ptr, c, 2 * n), i, j, pos


def _ct_gradients(U, X, system):
    """``(n, 2, 3)``: the vertex gradients ``[F_x, F_y]`` of each coordinate, the exact
    solution of SciPy's global estimate (JAX in ``U`` and ``X``)."""
    pattern, i, j, pos = system
    E = U[j] - U[i]
    w = jnp.sum(E * E, axis=1) ** -1.5
    parts = []
    for a in range(2):
        for b in range(2):
            wee = w * E[:, a] * E[:, b]
            parts += [4 * wee, 2 * wee]
    values = jnp.zeros(pattern.nnz, U.dtype).at[pos].add(jnp.concatenate(parts))
    n = U.shape[0]
    diff = (w[:, None, None] * E[:, :, None]) * (X[i] - X[j])[:, None, :]      # (e, 2, 3)
    rhs = -6.0 * jnp.zeros((n, 2, X.shape[1]), U.dtype).at[i].add(diff)
    y = sparse.solve(pattern, values, rhs.reshape(2 * n, -1), symmetric=True)
    return y.reshape(n, 2, -1)


def _ct_patch(U, X, G, simplices, neighbors, s, q):
    """The Clough–Tocher interpolant at ``q (k, 2)`` in triangles ``s (k,)`` (SciPy's
    ``_clough_tocher_2d_single``, vectorized, in JAX): ``(k, 3)``."""
    S = simplices[s]                                          # (k, 3)
    P = U[S]                                                  # (k, 3, 2)
    b = barycentric(P, q, xp=jnp)
    f = X[S]                                                  # (k, 3, d)
    df = G[S]                                                 # (k, 3, 2, d)
    e12, e23, e31 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 1], P[:, 0] - P[:, 2]

    def dot(g, e):                                            # (k, 2, d) . (k, 2) -> (k, d)
        return jnp.einsum("kad,ka->kd", g, e)

    df12, df21 = dot(df[:, 0], e12), -dot(df[:, 1], e12)
    df23, df32 = dot(df[:, 1], e23), -dot(df[:, 2], e23)
    df31, df13 = dot(df[:, 2], e31), -dot(df[:, 0], e31)
    c3000, c0300, c0030 = f[:, 0], f[:, 1], f[:, 2]
    c2100 = (df12 + 3 * c3000) / 3
    c2010 = (df13 + 3 * c3000) / 3
    c1200 = (df21 + 3 * c0300) / 3
    c0210 = (df23 + 3 * c0300) / 3
    c1020 = (df31 + 3 * c0030) / 3
    c0120 = (df32 + 3 * c0030) / 3
    c2001 = (c2100 + c2010 + c3000) / 3
    c0201 = (c1200 + c0300 + c0210) / 3
    c0021 = (c1020 + c0120 + c0030) / 3
    # The cross-boundary direction of each edge: towards the neighbour's centroid (affine
    # invariant), or the centroid direction where there is no neighbour.
    nb = neighbors[s]                                         # (k, 3), -1: none
    cen = jnp.mean(U[simplices[jnp.maximum(nb, 0)]], axis=2)  # (k, 3, 2)
    c = jnp.stack([barycentric(P, cen[:, k], xp=jnp) for k in range(3)], axis=1)   # (k, edge, 3)
    g = jnp.stack([(2 * c[:, 0, 2] + c[:, 0, 1] - 1) / (2 - 3 * c[:, 0, 2] - 3 * c[:, 0, 1]),
                   (2 * c[:, 1, 0] + c[:, 1, 2] - 1) / (2 - 3 * c[:, 1, 0] - 3 * c[:, 1, 2]),
                   (2 * c[:, 2, 1] + c[:, 2, 0] - 1) / (2 - 3 * c[:, 2, 1] - 3 * c[:, 2, 0])], axis=1)
    g = jnp.where(nb >= 0, g, -0.5)[:, :, None]
    c0111 = (g[:, 0] * (-c0300 + 3 * c0210 - 3 * c0120 + c0030)
             + (-c0300 + 2 * c0210 - c0120 + c0021 + c0201)) / 2
    c1011 = (g[:, 1] * (-c0030 + 3 * c1020 - 3 * c2010 + c3000)
             + (-c0030 + 2 * c1020 - c2010 + c2001 + c0021)) / 2
    c1101 = (g[:, 2] * (-c3000 + 3 * c2100 - 3 * c1200 + c0300)
             + (-c3000 + 2 * c2100 - c1200 + c2001 + c0201)) / 2
    c1002 = (c1101 + c1011 + c2001) / 3
    c0102 = (c1101 + c0111 + c0201) / 3
    c0012 = (c1011 + c0111 + c0021) / 3
    c0003 = (c1002 + c0102 + c0012) / 3
    m = jnp.min(b, axis=1, keepdims=True)
    b1, b2, b3 = [(b[:, k:k + 1] - m) for k in range(3)]
    b4 = 3 * m
    return (b1 ** 3 * c3000 + 3 * b1 ** 2 * b2 * c2100 + 3 * b1 ** 2 * b3 * c2010
            + 3 * b1 ** 2 * b4 * c2001 + 3 * b1 * b2 ** 2 * c1200
            + 6 * b1 * b2 * b4 * c1101 + 3 * b1 * b3 ** 2 * c1020 + 6 * b1 * b3 * b4 * c1011
            + 3 * b1 * b4 ** 2 * c1002 + b2 ** 3 * c0300 + 3 * b2 ** 2 * b3 * c0210
            + 3 * b2 ** 2 * b4 * c0201 + 3 * b2 * b3 ** 2 * c0120 + 6 * b2 * b3 * b4 * c0111
            + 3 * b2 * b4 ** 2 * c0102 + b3 ** 3 * c0030 + 3 * b3 ** 2 * b4 * c0021
            + 3 * b3 * b4 ** 2 * c0012 + b4 ** 3 * c0003)


def _clough_tocher(U, X, Uc, Xc, bbox) -> Surface:
    from scipy.interpolate import CloughTocher2DInterpolator  # noqa: F401 - used in interpolant
    from scipy.spatial import Delaunay

    tri = Delaunay(Uc)
    # SciPy's gradient iteration stops at an absolute tolerance (1e-6 by default): scaled down
    # with gradients smaller than 1, so small units are as exact as unit ones (at 1e-3 of the
    # size the derivative, of the exactly solved interpolant, was 3e-5 off SciPy's values; now
    # 1.5e-7 as at unit size); larger ones keep 1e-6 (already tighter for them)
    span = float(np.max(np.ptp(Uc, axis=0)))

    def interpolant(Xv):
        scale = float(np.max(np.ptp(Xv, axis=0))) / span if span > 0 else 1.0
        return CloughTocher2DInterpolator(tri, Xv, tol=1e-6 * min(max(scale, 1e-300), 1.0))

    f = interpolant(Xc) if Xc is not None else None
    traced = _traced(U, X)
    cache = {}

    def gradients():
        if "system" not in cache:
            cache["system"] = _ct_gradient_system(tri)
        if traced:            # tracers of the caller's transformation: not kept
            return _ct_gradients(U, X, cache["system"])
        if "G" not in cache:  # concrete data: solved once, also when first asked under jax.jit
            with jax.ensure_compile_time_eval():
                cache["G"] = _ct_gradients(jnp.asarray(U), jnp.asarray(X), cache["system"])
        return cache["G"]

    def host_values(Xv, qv):
        g = f if f is not None else interpolant(np.asarray(Xv, np.float64))
        return np.asarray(g(np.asarray(qv)), np.float64).reshape(-1, 3)

    def host_simplex(qv):
        return np.asarray(tri.find_simplex(np.asarray(qv)), np.int32)

    def ev(q):
        if not (traced or isinstance(q, jax.core.Tracer)):
            return np.asarray(f(q)).reshape(-1, 3)
        qc = concrete_values(q)
        if qc is not None and f is not None:
            value = jnp.asarray(host_values(None, qc))
        else:
            value = jax.pure_callback(host_values, jax.ShapeDtypeStruct((q.shape[0], 3), jnp.float64),
                                      jax.lax.stop_gradient(jnp.asarray(X)), jax.lax.stop_gradient(q))
        if qc is not None:
            s = jnp.asarray(host_simplex(qc))
        else:
            s = jax.pure_callback(host_simplex, jax.ShapeDtypeStruct((q.shape[0],), jnp.int32),
                                  jax.lax.stop_gradient(q))
        smooth = _ct_patch(jnp.asarray(U), jnp.asarray(X), gradients(), jnp.asarray(tri.simplices),
                           jnp.asarray(tri.neighbors), jnp.maximum(s, 0), jnp.asarray(q))
        smooth = jnp.where((s >= 0)[:, None], smooth, 0.0)
        # SciPy's values, with the derivative of the exactly solved interpolant.
        return value + (smooth - jax.lax.stop_gradient(smooth))

    return Surface("clough_tocher", bbox, ev, 0.0, lambda q: tri.find_simplex(q) >= 0)
