"""Distortion energies (survey §6) as per-triangle JAX functions, and user energies.

Every energy is a *density* ``f(frame, q)`` of one triangle: ``frame: (3, 2)``
the triangle in its own orthonormal frame (from
:func:`jaxparam.geometry.local_frames`) and ``q: (3, 2)`` its corners' UVs.
The mesh energy (10) is the area-weighted mean over the faces,
``E = sum_T |T| f_T / sum_T |T|``, so an isometry scores the same on every mesh.
Most densities are functions of the Jacobian ``J`` (9) or of its singular
values ``s1 >= s2``; *barrier* energies are ``+inf`` where ``det J <= 0``.

Names (as in the design): ``condition_2`` (E1), ``mips`` (E2),
``condition_2_squared`` (E3), ``condition_f_squared`` (E4), ``angle``
(Sheffer–de Sturler), ``green_lagrange`` (Maillot), ``symmetric_dirichlet``,
``arap``, ``conformal`` (LSCM), ``dirichlet``, ``stretch`` (Sander et al.'s L2 stretch).

**Kinks.** ``s1`` and ``s2`` alone are not differentiable where a face is conformal
(``s1 = s2``); symmetric functions of them are (every energy here but two).
``condition_2`` (``s1 / s2``) and ``condition_2_squared`` kink there, as ``|x|`` does: at an
exactly conformal face JAX returns the mean of the two one-sided derivatives (the safe
square root in :func:`jaxparam.geometry.singular_values` gives ``s1 - s2`` a zero
gradient), and near one the energy's curvature grows like ``1 / (s1 - s2)``, so finite
differences need steps well below ``s1 - s2`` (tests/test_gradients.py).

**Derivatives.** The mesh energy ``energy(mesh, uv)`` of an energy of the Jacobian has a
hand-written derivative (a ``jax.custom_jvp``, :func:`_mesh_energy`): the closed-form
``dE/dJ`` of each form (:meth:`SingularValueForm.value_and_dJ`), chained through the Jacobian
and the local frame by hand; for the named symmetric functions of the singular values (all but
``condition_2`` and ``condition_2_squared``), written in the invariants ``s1^2 + s2^2`` and
``s1 s2``, through the Gram matrix of the 3D edges instead, a shorter chain
(:func:`_invariant_face_terms`).  Forward and reverse mode and Hessians all work, and agree
with JAX's own derivative of the formula to 1e-10 (tests/test_energies.py).  The minimizer's
kernels (:func:`total`) differentiate the densities with JAX; a named symmetric density is
evaluated from ``(s1^2 + s2^2, det J)``, polynomials of ``J``, so its Hessian (Newton's, the
implicit gradient's) is exact at a conformal face too, where the singular values' chain is
``0 / 0``; it is also the more accurate value (1e-16 against 1e-10 relative at ``s2 / s1 =
1e-7``).
"""
from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass, field
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import geometry as geo
from .energy_forms import (SCALE, SWAP, JacobianForm, OfJacobian, SingularValueForm,
                           inf_where_inverted, looks_invariant, safe_root)
from .errors import MeshError
from .io import as_mesh

__all__ = ["Energy", "Densities", "energy", "ENERGIES", "get", "mips_prop2", "total",
           "params_equal", "captures_tracer", "density_stretch", "NO_FREE_MINIMUM"]


class Densities(NamedTuple):
    """An energy's three functions with its parameters bound (:meth:`Energy.densities`):
    ``density(frame, q)``, ``of_J(J)`` or ``None``, ``of_sv(s1, s2)`` or ``None``."""

    density: Callable
    of_J: Callable | None
    of_sv: Callable | None


def _leaf_equal(a, b) -> bool:
    if a is b:
        return True
    if isinstance(a, jax.core.Tracer) or isinstance(b, jax.core.Tracer):
        return False          # traced values: equal only when they are the same tracer
    try:
        a, b = np.asarray(a), np.asarray(b)
    except Exception:         # not array-like: Python equality
        return bool(a == b)
    return a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b, equal_nan=True))


def params_equal(a, b) -> bool:
    """Whether two parameter pytrees are equal: the same structure, and leaves equal by value
    (shape, dtype and entries; NaN equals NaN); a JAX tracer equals only itself."""
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    return ta == tb and all(_leaf_equal(x, y) for x, y in zip(la, lb))


def _bind(fn, params):
    """``fn`` with ``params`` as its last argument (``None`` stays ``None``)."""
    if fn is None:
        return None
    return lambda *args: fn(*args, params)


@dataclass(frozen=True, eq=False)
class Energy:
    """A per-triangle energy density and how to treat it.

    **Fields:**

    - ``name``: shown in progress bars, reports and error messages.
    - ``density``: ``density(frame (3, 2), q (3, 2)) -> scalar``, the energy of one
      triangle (``frame`` from :func:`jaxparam.geometry.local_frames`, ``q`` its UVs);
      ``density(frame, q, params)`` when ``parametric``.
    - ``scale_invariant``: unchanged when the UVs are scaled (E1–E4, MIPS, angle,
      conformal); a free-boundary minimization then keeps the start's area.
    - ``barrier``: ``+inf`` where a triangle is inverted.
    - ``of_J``: ``of_J(J (2, 2)) -> scalar`` when the density is a function of the
      Jacobian alone (``density(frame, q) == of_J(J(frame, q))``), else ``None``; the
      minimizer then takes Hessians in the 4 entries of ``J`` instead of the 6 UVs.
    - ``of_sv``: ``of_sv(s1, s2) -> scalar`` when the density is a barrier function of
      the singular values (``s1 >= s2 > 0``), else ``None``; the minimizer then projects
      its Hessian in closed form (analytic eigensystems).
    - ``parametric``: the three functions take the energy's parameters as a last
      argument (``of_J(J, params)``, ``of_sv(s1, s2, params)``); :meth:`densities` binds
      them.
    - ``params``: the parameters, any JAX pytree (arrays, floats, tuples, dicts: leaves
      may be JAX tracers, e.g. under ``jax.grad``); ``None`` when not ``parametric``.

    Equality is by value, field by field: two energies built from the same function object
    with the same name, flags and equal parameters are equal, so ``jp.energy(f) ==
    jp.energy(f)``; parameters compare by :func:`params_equal` (a tracer equals only
    itself).  The hash leaves the parameters out (equal energies still hash equal), and
    :func:`jaxparam.minimize`'s kernels take :attr:`static` (the energy without its
    parameters) as a static argument of ``jax.jit`` and the parameters as a dynamic
    one: equal energies share compiled code, so do energies that differ only in their
    parameter values (traced or not), and energies from different functions (compared
    by identity, as Python compares functions) never do.
    """

    name: str
    density: Callable = field(repr=False)
    scale_invariant: bool = False
    barrier: bool = True
    of_J: Callable | None = field(default=None, repr=False)
    of_sv: Callable | None = field(default=None, repr=False)
    parametric: bool = False
    params: Any = field(default=None, repr=False)

    def _key(self) -> tuple:
        return (self.name, self.density, self.scale_invariant, self.barrier, self.of_J,
                self.of_sv, self.parametric)

    def __eq__(self, other):
        if other.__class__ is not self.__class__:
            return NotImplemented
        return self._key() == other._key() and params_equal(self.params, other.params)

    def __hash__(self):
        return hash(self._key())

    @property
    def static(self) -> "Energy":
        """This energy without its parameters (``params=None``): what ``jax.jit`` kernels
        take as a static argument, next to the parameters as a dynamic one."""
        return self if self.params is None else dataclasses.replace(self, params=None)

    def with_params(self, params) -> "Energy":
        """The same energy with other parameters (e.g. traced ones)."""
        return dataclasses.replace(self, params=params)

    def __reduce__(self):
        # A named energy (or one with other parameters) pickles by its name: its functions
        # are lambdas, which pickle cannot store; a user's energy pickles field by field.
        named = ENERGIES.get(self.name)
        if named is not None and named.density is self.density:
            return _named_energy, (self.name, self.params)
        return super().__reduce__()

    def densities(self, params=None) -> Densities:
        """The density, ``of_J`` and ``of_sv`` with ``params`` (default: :attr:`params`)
        bound, each taking its usual arguments (``(frame, q)``, ``J``, ``(s1, s2)``)."""
        if not self.parametric:
            return Densities(self.density, self.of_J, self.of_sv)
        p = self.params if params is None else params
        return Densities(_bind(self.density, p), _bind(self.of_J, p), _bind(self.of_sv, p))

    def __call__(self, mesh, uv):
        """The mesh energy of ``uv: (n, 2)``: area-weighted mean of the density.

        Differentiable in the vertices, the UVs and the parameters, in both modes.  For the
        energies of the Jacobian (every named one but ``angle``, and every ``jp.energy(f)``)
        the derivative is written by hand (:func:`_mesh_energy`): the values are the
        density's own, bit for bit, and a gradient costs about two forward passes (three
        times less than JAX's derivative of the same formula; benchmarks/README.md)."""
        mesh = as_mesh(mesh, f"energy {self.name!r} (called as energy(mesh, uv))")
        if np.shape(uv) != (mesh.n_vertices, 2):
            raise MeshError(f"energy {self.name!r}: uv must have shape ({mesh.n_vertices}, 2), one "
                            f"row per vertex of the mesh, got {np.shape(uv)}.")
        V = jnp.asarray(mesh.vertices, jnp.float64)
        if (isinstance(self.density, OfJacobian) and V.ndim == 2 and V.shape[1] == 3
                and isinstance(self.of_J, (SingularValueForm, JacobianForm))):
            return _mesh_energy(self, V, mesh.faces, jnp.asarray(uv, jnp.float64)[mesh.faces])
        frames = geo.local_frames(V, mesh.faces)
        return total(self, frames, geo.face_areas(V, mesh.faces), jnp.asarray(uv)[mesh.faces])


def total(en: Energy, frames, areas, Q, params=None):
    """``sum_T |T| f(frame_T, q_T) / sum_T |T|`` for per-face ``frames (m, 3, 2)``,
    ``areas (m,)`` and UV corners ``Q (m, 3, 2)``; ``params``: the energy's parameters
    (default ``en.params``)."""
    dens = jax.vmap(en.densities(params).density)(frames, Q)
    return jnp.sum(areas * dens) / jnp.sum(areas)


def _params_jvp(form, aux, params, dparams):
    """``(m,)`` derivative of ``m`` densities along the parameters' tangent ``dparams``, at
    the arguments :meth:`SingularValueForm.value_and_dJ` evaluated them at (``aux``)."""
    x, ok = (aux[:2], aux[2]) if isinstance(form, SingularValueForm) else (aux[:1], aux[1])
    fn = jax.vmap(form.fn, in_axes=(0,) * len(x) + (None,) * len(params))
    _, t = jax.jvp(lambda *p: fn(*x, *p), tuple(params), tuple(dparams))
    return t if ok is None else jnp.where(ok, t, 0.0)


def _face_terms(form, V, F, Q, params):
    """Per face, by hand: the area ``a``, the density ``f`` and their gradients in the
    corners, for :func:`_mesh_energy`.

    **Arguments:** ``form`` a :class:`SingularValueForm` or :class:`JacobianForm`,
    ``V (n, 3)``, ``F (m, 3)``, ``Q (m, 3, 2)`` the corners' UVs, ``params`` a tuple of 0 or
    1 parameter pytrees.  **Returns:** ``(a, f, e1, e2, gQ, aux)``: ``a, f (m,)``;
    ``e1, e2`` the edges ``p1 - p0, p2 - p0 (m, 3)``; ``gQ (m, 3, 2)`` = ``df / dQ``; and
    ``aux = (c11, c12, c22, h, (g11, g12, g22), form_aux)``: ``df/de1 = c11 e1 + c12 e2``,
    ``df/de2 = c12 e1 + c22 e2`` and ``da/de1 = h (g22 e1 - g12 e2)``, ``da/de2 = h (g11 e2 -
    g12 e1)`` with ``g = [e1 e2]^T [e1 e2]`` (a and f depend on the 3D triangle through its
    Gram matrix alone), ``form_aux`` the form's (:func:`_params_jvp`).

    The chain: the local frame ``(0, 0), (l1, 0), (x2, y2)`` of
    :func:`jaxparam.geometry.local_frames` (``l1 = |e1|``, ``x2 = g12 / l1``,
    ``y2 = |e1 x e2| / l1``), ``J = [q1 - q0, q2 - q0] Pinv`` with
    ``Pinv = [[y2, -x2], [0, l1]] / (l1 y2)`` (survey eq. (9)), the form's ``dE/dJ``; then
    ``dE/d[q1 - q0, q2 - q0] = M = dE/dJ Pinv^T`` and ``dE/dP = -J^T M`` for the frame's
    ``(l1, x2, y2)``, and the frame's derivatives in ``(e1, e2)``.  A form with invariants
    takes a shorter chain (:func:`_invariant_face_terms`).
    """
    if isinstance(form, SingularValueForm) and form.invariants is not None and not params:
        return _invariant_face_terms(form, V, F, Q)
    e1, e2, (g11, g12, g22), (nn, inn) = _edge_gram(V, F)
    l1, il1 = safe_root(g11)
    x2, y2 = g12 * il1, nn * il1
    u1, u2 = Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]
    idet = 1.0 / (l1 * y2)
    J00, J10 = u1[:, 0] * y2 * idet, u1[:, 1] * y2 * idet
    J01, J11 = (u2[:, 0] * l1 - u1[:, 0] * x2) * idet, (u2[:, 1] * l1 - u1[:, 1] * x2) * idet
    f, (Ga, Gb, Gc, Gd), form_aux = form.value_and_dJ(J00, J01, J10, J11, params)
    M00, M01 = (Ga * y2 - Gb * x2) * idet, Gb * l1 * idet
    M10, M11 = (Gc * y2 - Gd * x2) * idet, Gd * l1 * idet
    g_l1 = -(J00 * M00 + J10 * M10)
    g_x2 = -(J00 * M01 + J10 * M11)
    g_y2 = -(J01 * M01 + J11 * M11)
    k, il3 = inn * il1, il1 ** 3
    c11 = g_l1 * il1 - g_x2 * g12 * il3 + g_y2 * (g22 * k - nn * il3)
    c12 = g_x2 * il1 - g_y2 * g12 * k
    c22 = g_y2 * g11 * k
    gq1, gq2 = jnp.stack([M00, M10], -1), jnp.stack([M01, M11], -1)
    gQ = jnp.stack([-(gq1 + gq2), gq1, gq2], 1)
    return 0.5 * nn, f, e1, e2, gQ, (c11, c12, c22, 0.5 * inn, (g11, g12, g22), form_aux)


def _edge_gram(V, F):
    """Each face's edges ``e1 = p1 - p0``, ``e2 = p2 - p0`` (``(m, 3)`` each), their Gram
    matrix ``(g11, g12, g22)`` and ``(|e1 x e2|, 1 / |e1 x e2|)`` (twice the area and its
    inverse, both 0 on a degenerate face), ``(m,)`` each."""
    P = V[F]
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    cr = jnp.cross(e1, e2)
    return (e1, e2, (geo.dot(e1, e1), geo.dot(e1, e2), geo.dot(e2, e2)),
            safe_root(geo.dot(cr, cr)))


def _invariant_face_terms(form, V, F, Q):
    """:func:`_face_terms` for a form with ``invariants`` (and no parameters), through the 3D
    edges' Gram matrix ``g = [e1 e2]^T [e1 e2]`` instead of the local frame; same returns
    (``form_aux`` is ``None``).

    ``J J^T = U P^-1 P^-T U^T = U g^-1 U^T`` (``U = [q1 - q0, q2 - q0]``, ``P`` the frame's
    edges, ``P^T P = g``), so ``tr = s1^2 + s2^2 = tr(g^-1 K)`` with ``K = U^T U``, and
    ``det J = s1 s2 = det U / sqrt(det g)``: the density is a function of ``(tr, det J)``
    and of the 3D triangle only through ``g``.  The chain has no frame, no Jacobian and no
    singular values (their square roots and reciprocals), and no ``0 / 0`` at a conformal
    face, where the frame's chain divides ``df/ds1 - df/ds2`` by ``s1 - s2``.  ``det g =
    |e1 x e2|^2`` comes from the cross product, which keeps its accuracy on needle triangles.
    """
    e1, e2, (g11, g12, g22), (nn, inn) = _edge_gram(V, F)
    idg = inn * inn
    u1, u2 = Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]
    K11, K12, K22 = geo.dot(u1, u1), geo.dot(u1, u2), geo.dot(u2, u2)
    tr = (g22 * K11 - 2.0 * g12 * K12 + g11 * K22) * idg
    det = (u1[:, 0] * u2[:, 1] - u1[:, 1] * u2[:, 0]) * inn
    fn = jax.vmap(jax.value_and_grad(form.invariants, argnums=(0, 1)))
    if form.barrier:
        ok = det > 0
        f, (f_tr, f_det) = fn(tr, jnp.where(ok, det, 1.0))
        f = jnp.where(ok, f, jnp.inf)
        f_tr, f_det = jnp.where(ok, f_tr, 0.0), jnp.where(ok, f_det, 0.0)
    else:
        f, (f_tr, f_det) = fn(tr, jnp.abs(det))
        f_det = f_det * jnp.sign(det)
    # d tr = (dN - tr d(det g)) / det g and d(det J) = -det J d(det g) / (2 det g), with
    # N = g22 K11 - 2 g12 K12 + g11 K22 and det g = g11 g22 - g12^2; then df/de1 =
    # 2 df/dg11 e1 + df/dg12 e2 and df/de2 = df/dg12 e1 + 2 df/dg22 e2.
    b = -(f_tr * tr + 0.5 * f_det * det)
    c11 = 2.0 * idg * (f_tr * K22 + b * g22)
    c12 = -2.0 * idg * (f_tr * K12 + b * g12)
    c22 = 2.0 * idg * (f_tr * K11 + b * g11)
    # d tr / du1 = 2 (g22 u1 - g12 u2) / det g,  d det U / du1 = (u2y, -u2x); likewise u2.
    kt, kd = 2.0 * idg * f_tr, f_det * inn
    gq1 = (kt * g22)[:, None] * u1 - (kt * g12)[:, None] * u2 + kd[:, None] * jnp.stack(
        [u2[:, 1], -u2[:, 0]], -1)
    gq2 = (kt * g11)[:, None] * u2 - (kt * g12)[:, None] * u1 + kd[:, None] * jnp.stack(
        [-u1[:, 1], u1[:, 0]], -1)
    gQ = jnp.stack([-(gq1 + gq2), gq1, gq2], 1)
    return 0.5 * nn, f, e1, e2, gQ, (c11, c12, c22, 0.5 * inn, (g11, g12, g22), None)


def _is_zero(t) -> bool:
    """Whether a ``symbolic_zeros`` tangent (pytree) is zero in every leaf."""
    zero = jax.custom_derivatives.SymbolicZero
    return all(isinstance(leaf, zero) for leaf in jax.tree_util.tree_leaves(
        t, is_leaf=lambda x: isinstance(x, zero)))


def _mesh_energy(en: Energy, V, F, Q):
    """``E = sum_T |T| f_T / sum_T |T|`` (eq. (10)) of an energy of the Jacobian, with its
    derivative written by hand: a ``jax.custom_jvp`` whose values are :func:`total`'s (the
    same operations, so the same numbers) and whose tangent is the closed-form
    ``dE/dV : dV + dE/dQ : dQ + dE/dparams . dparams`` (:func:`_face_terms`).  Reverse mode
    comes by transposition of that linear map, so ``jax.grad``, ``jax.jvp``, ``jacfwd`` and
    Hessians all work; the gradient then costs one pass of per-face arithmetic and one
    scatter into the vertices instead of JAX's backward through the frames, the singular
    values and the barrier (benchmarks/README.md, ``gradients.py``).

    ``V (n, 3)``, ``F (m, 3)`` int, ``Q (m, 3, 2)`` the corners' UVs."""
    form = en.of_J

    def primal(V, Q, p):
        return total(en, geo.local_frames(V, F), geo.face_areas(V, F), Q, p)

    def tangent(primals, tangents):
        V, Q, p = primals
        dV, dQ, dp = tangents
        params = (p,) if en.parametric else ()
        a, f, e1, e2, gQ, (c11, c12, c22, h, (g11, g12, g22), form_aux) = _face_terms(
            form, V, F, Q, params)
        A = jnp.sum(a)
        E = jnp.sum(a * f) / A
        t = jnp.zeros((), E.dtype)
        iA = 1.0 / A
        wa, wf = a * iA, (f - E) * h * iA          # per face: of df/dP and of da/dP
        if not _is_zero(dV):
            w11 = wa * c11 + wf * g22
            w12 = wa * c12 - wf * g12
            w22 = wa * c22 + wf * g11
            W1 = w11[:, None] * e1 + w12[:, None] * e2
            W2 = w12[:, None] * e1 + w22[:, None] * e2
            # dE/dV summed here, in the primal, by one chain of scatters into one buffer; the
            # tangent is <dE/dV, dV>, whose transpose is dE/dV itself.  The transpose of a
            # gather per corner made three scatters into three zeroed buffers and added them
            # (session 15: 1.11 -> 1.01 ms for symmetric Dirichlet's gradient on camelhead).
            gV = jnp.zeros_like(V)
            for c, Wc in enumerate((-(W1 + W2), W1, W2)):
                gV = gV.at[F[:, c]].add(Wc)
            t = t + jnp.sum(gV * dV)
        if not _is_zero(dQ):
            t = t + jnp.sum(wa[:, None, None] * gQ * dQ)
        if params and not _is_zero(dp):
            SymbolicZero = jax.custom_derivatives.SymbolicZero
            dps = jax.tree_util.tree_map(
                lambda x, d: (jnp.zeros(jnp.shape(x), jax.dtypes.float0)
                              if not jnp.issubdtype(jnp.result_type(x), jnp.inexact)
                              else jnp.zeros_like(x)) if isinstance(d, SymbolicZero) else d,
                p, dp, is_leaf=lambda x: isinstance(x, SymbolicZero))
            t = t + jnp.sum(wa * _params_jvp(form, form_aux, params, (dps,)))
        return E, t

    fn = jax.custom_jvp(primal)
    fn.defjvp(tangent, symbolic_zeros=True)
    return fn(V, Q, en.params)


def _from_sv(name, fn, scale_invariant=False, *, barrier=True, parametric=False,
             params=None, invariants=None, symmetric=False) -> Energy:
    """An Energy from a function of the singular values (s1 >= s2 > 0 when unflipped);
    ``fn(s1, s2, params)`` when ``parametric``; ``invariants(s1^2 + s2^2, s1 s2)`` the same
    function, when it is symmetric (:class:`SingularValueForm`); ``symmetric``: ``fn`` is
    (:meth:`SingularValueForm.of_QS`)."""
    of_J = SingularValueForm(fn, barrier, invariants, symmetric)
    return Energy(name, OfJacobian(of_J), scale_invariant, barrier, of_J=of_J,
                  of_sv=fn if barrier else None, parametric=parametric, params=params)


def _from_J(name, fn, scale_invariant=False, *, barrier=True, parametric=False,
            params=None) -> Energy:
    """An Energy from a function of the 2x2 Jacobian; ``fn(J, params)`` when ``parametric``."""
    of_J = JacobianForm(fn, barrier)
    return Energy(name, OfJacobian(of_J), scale_invariant, barrier, of_J=of_J,
                  parametric=parametric, params=params)


def _angle_density(frame, q):
    """Sheffer–de Sturler: ``sum_i (theta_i - alpha_i)^2`` over the corners, theta the UV
    angles, alpha the 3D (= frame) angles; +inf when inverted.  Not convex in the UVs: from
    the Tutte map Newton can stop in a local minimum, so start it from
    ``minimize(mesh, "mips", ...).uv`` (benchmarks/README.md has the figures)."""
    alpha = geo.corner_angles(frame, jnp.array([[0, 1, 2]]))[0]
    theta = geo.corner_angles(q, jnp.array([[0, 1, 2]]))[0]
    det = geo.signed_areas(q, jnp.array([[0, 1, 2]]))[0]
    return inf_where_inverted(det, jnp.sum((jnp.where(det > 0, theta, alpha) - alpha) ** 2))


def mips_prop2(frame, q):
    """E2 in the rational-quadratic form of Proposition 2:
    ``(cot a1 |l1|^2 + cot a2 |l2|^2 + cot a3 |l3|^2) / (l2 x l3)`` with ``a_i`` the
    triangle's angles and ``l_i`` the UV edges opposite them."""
    a = geo.corner_angles(frame, jnp.array([[0, 1, 2]]))[0]
    cot = jnp.cos(a) / jnp.sin(a)
    l1, l2, l3 = q[2] - q[1], q[2] - q[0], q[1] - q[0]
    num = cot[0] * jnp.sum(l1 ** 2) + cot[1] * jnp.sum(l2 ** 2) + cot[2] * jnp.sum(l3 ** 2)
    # The denominator is twice the UV area: l2 x l3 in the survey's clockwise labelling of
    # Fig. 15, l3 x l2 for our counter-clockwise faces.
    return num / (l3[0] * l2[1] - l3[1] * l2[0])


ENERGIES: dict[str, Energy] = {
    # Corollary 1 (survey §6): condition numbers, all proper deformation functionals.
    "condition_2": _from_sv("condition_2", lambda s1, s2: s1 / s2, True),
    "mips": _from_sv("mips", lambda s1, s2: s1 / s2 + s2 / s1, True,
                     invariants=lambda tr, d: tr / d),
    "condition_2_squared": _from_sv("condition_2_squared", lambda s1, s2: (s1 / s2) ** 2, True),
    "condition_f_squared": _from_sv("condition_f_squared",
                                    lambda s1, s2: (s1 / s2) ** 2 + (s2 / s1) ** 2, True,
                                    invariants=lambda tr, d: (tr / d) ** 2 - 2.0),
    "angle": Energy("angle", _angle_density, True),
    # Maillot et al.: the Green–Lagrange tensor ||J^T J - I||_F^2 (not a deformation functional).
    "green_lagrange": _from_J("green_lagrange", lambda J: jnp.sum((J.T @ J - jnp.eye(2)) ** 2),
                              barrier=False),
    "symmetric_dirichlet": _from_sv("symmetric_dirichlet",
                                    lambda s1, s2: s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2,
                                    invariants=lambda tr, d: tr + tr / (d * d)),
    # Without a barrier the forms see |s2|, so d = s1 |s2| and s1 + |s2| = sqrt(tr + 2 d).
    "arap": _from_sv("arap", lambda s1, s2: (s1 - 1) ** 2 + (s2 - 1) ** 2, barrier=False,
                     invariants=lambda tr, d: tr - 2.0 * geo.safe_sqrt(tr + 2.0 * d) + 2.0),
    # Quadratic in the UVs (0.5 |J|^2 - det J unflipped), so not scale-invariant: 4x at 2x the
    # map, and 0 at a point, its only free-boundary minimum (NO_FREE_MINIMUM).
    "conformal": _from_sv("conformal", lambda s1, s2: 0.5 * (s1 - s2) ** 2, barrier=False,
                          invariants=lambda tr, d: 0.5 * tr - d),
    "dirichlet": _from_J("dirichlet", lambda J: 0.5 * jnp.sum(J ** 2), barrier=False),
    # Sander et al. 2001 (survey ref. [27]): the L2 stretch of the inverse map UV -> surface,
    # whose singular values are 1/s2 >= 1/s1: (Gamma^2 + gamma^2) / 2; its area-weighted mean
    # is L2(M)^2.  Penalizes UV triangles small for their 3D area (the squeeze that starves
    # a remesh of samples); not scale invariant, so minimize it with a fixed boundary.
    "stretch": _from_sv("stretch", lambda s1, s2: 0.5 * (s1 ** -2 + s2 ** -2),
                        invariants=lambda tr, d: 0.5 * tr / (d * d)),
}


def _named_energy(name: str, params) -> Energy:
    """``ENERGIES[name]`` with ``params`` (unpickling, :meth:`Energy.__reduce__`)."""
    en = ENERGIES[name]
    return en if params is None else en.with_params(params)


def _captured(fn, depth: int = 0):
    """The values a function reaches without being passed them: its closure cells and
    defaults, a ``functools.partial``'s arguments, the wrapped function of our wrappers."""
    if depth > 4 or fn is None:
        return []
    out = []
    for attr in ("of_J", "fn", "func"):             # OfJacobian, the forms, partial
        inner = getattr(fn, attr, None)
        if callable(inner) and inner is not fn:
            out += _captured(inner, depth + 1)
    args, kw = getattr(fn, "args", None), getattr(fn, "keywords", None)
    out += list(args) if isinstance(args, tuple) else []
    out += list(kw.values()) if isinstance(kw, dict) else []
    for cell in getattr(fn, "__closure__", None) or ():
        try:
            v = cell.cell_contents
        except ValueError:      # an empty cell
            continue
        out += _captured(v, depth + 1) if callable(v) else [v]
    out += list(getattr(fn, "__defaults__", None) or ())
    return out


def captures_tracer(en: Energy) -> bool:
    """Whether the energy's functions close over a JAX tracer (e.g. a parameter under
    ``jax.grad`` captured by a ``lambda``): the compiled kernels cannot take it; it must be
    passed as ``jp.energy(f, params)``."""
    vals = _captured(en.density) + _captured(en.of_J) + _captured(en.of_sv)
    return any(isinstance(leaf, jax.core.Tracer) for v in vals
               for leaf in jax.tree_util.tree_leaves(v))


#: Built-in energies that have no useful minimum with a free boundary, and why: the map
#: runs off to a trivial one (measured on snail scaled by 1e4: "dirichlet" shrank it to
#: 1e-4 across, "stretch" grew it to 2e7, both reported converged).
NO_FREE_MINIMUM = {
    "dirichlet": "shrinks the map towards a point (its energy falls to 0 there)",
    "stretch": "grows the map without bound (its energy falls to 0 as the map grows)",
    # It was marked scale-invariant, so each iterate was rescaled to the start's area: a
    # constrained optimum, not a stationary point, which Newton never reached (max_iters) and
    # whose implicit gradient was off by 42x on a sheared grid (session 22's gradient sweep).
    "conformal": ("shrinks the map towards a point (its energy 0.5 (s1 - s2)^2 grows with the "
                  "map's area and is 0 there); for a free-boundary conformal map use "
                  "jp.least_squares_map (LSCM), which pins two vertices"),
}


def get(e) -> Energy:
    """An :class:`Energy` from a name (hyphens or underscores) or an Energy."""
    if isinstance(e, Energy):
        return e
    if isinstance(e, str):
        key = e.replace("-", "_")
        if key in ENERGIES:
            return ENERGIES[key]
        raise MeshError(f"energy: unknown energy {e!r}; use one of {sorted(ENERGIES)} or "
                        "jp.energy(f) for your own.")
    if callable(e):
        return energy(e)
    raise MeshError(f"energy: expected a name or a jp.energy(...), got {type(e).__name__}.")


_NO_PARAMS = object()


def energy(fn: Callable, params=_NO_PARAMS, *, name: str | None = None,
           scale_invariant: bool | None = None, barrier: bool = True,
           symmetric: bool | None = None) -> Energy:
    """A user energy from ``f(s1, s2)`` (singular values) or ``f(J)`` (the 2x2 Jacobian),
    optionally with parameters: ``f(s1, s2, params)`` or ``f(J, params)``.

    The number of positional parameters decides which (one more when ``params`` is
    given).  The energy is ``+inf`` on inverted triangles when ``barrier`` (the
    default), and works with every solver of :func:`jaxparam.minimize`: JAX supplies its
    gradient and Hessian.

    ``params``: any JAX pytree (a float, an array, a tuple or dict of them), passed to
    ``f`` as its last argument.  They are data, not part of the compiled code: energies
    that differ only in their parameters share :func:`jaxparam.minimize`'s compiled
    kernels, and the parameters may be traced, so ``jax.grad`` of a function of
    ``minimize(mesh, jp.energy(f, p)).uv`` with respect to ``p`` is the implicit
    gradient of the optimum (:mod:`jaxparam.optimize.implicit`).

    ``scale_invariant``: whether ``f`` is unchanged when the map is scaled (MIPS, the
    condition numbers); ``symmetric`` (for ``f(s1, s2)``): whether ``f(s1, s2) == f(s2, s1)``.
    ``None`` (the default) tests each on 16 random arguments (with parameters, also that the
    difference does not change with them to first order: ``s1^2 + a s2^2`` is symmetric at
    ``a = 1`` only; traced parameters are not tested: ``False``, pass ``True`` where it
    holds).  A scale-invariant energy's free-boundary result is rescaled to the start's
    area and centroid (it has a minimum at every scale), and its implicit gradient leaves
    the scaling out.  A symmetric ``f`` is evaluated in ``(s1 + s2, (s1 - s2)^2)``, so its
    Hessian is exact at a conformal face (``s1 = s2``), where the singular values themselves
    are not differentiable: Newton's steps and the implicit gradient of :func:`minimize` need
    it there (a planar mesh flattened to itself has only conformal faces).  An asymmetric
    ``f`` (``s1 / s2``) kinks there, as ``condition_2`` does.

    Example::

        e = jp.energy(lambda s1, s2: s1 / s2 + s2 / s1)       # MIPS, written by hand
        res = jp.minimize(mesh, e)
        w = jp.energy(lambda s1, s2, a: s1 ** 2 + s2 ** 2 + a * (s1 ** -2 + s2 ** -2), 2.0)
        jax.grad(lambda a: jnp.sum(jp.minimize(mesh, jp.energy(f, a)).uv ** 2))(2.0)
    """
    if not callable(fn):
        hint = (f"; for the named energy pass {fn!r} itself (jp.minimize(mesh, {fn!r})) or use "
                f"jp.ENERGIES[{fn!r}]" if isinstance(fn, str) else "")
        raise MeshError(f"energy: fn must be a function of the singular values (s1, s2) or of "
                        f"the Jacobian (J), got {fn!r}{hint}.")
    parametric = params is not _NO_PARAMS
    if parametric:
        _check_params(params)
    try:
        args = [p for p in inspect.signature(fn).parameters.values()
                if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty]
    except (TypeError, ValueError):
        args = [None] * (2 if parametric else 1)
    n = len(args) - (1 if parametric else 0)
    if n not in (1, 2):
        want = "(s1, s2, params) or (J, params)" if parametric else "(s1, s2) or (J)"
        raise MeshError(f"energy: a user energy takes {want}, got a function of {len(args)} "
                        "arguments.")
    _check_scalar(fn, n, params if parametric else None, parametric)
    label = name or getattr(fn, "__name__", "user")
    extra = (params,) if parametric else ()
    for flag, value in (("scale_invariant", scale_invariant), ("symmetric", symmetric)):
        if value is not None and not isinstance(value, bool):
            raise MeshError(f"energy: {flag} must be True, False or None (test it), got {value!r}.")
    if scale_invariant is None:
        scale_invariant = looks_invariant(fn, n, SCALE, *extra)
    if n == 1:
        return _from_J(label, fn, scale_invariant, barrier=barrier, parametric=parametric,
                       params=params if parametric else None)
    if symmetric is None:
        symmetric = looks_invariant(fn, 2, SWAP, *extra)
    return _from_sv(label, fn, scale_invariant, barrier=barrier, parametric=parametric,
                    params=params if parametric else None, symmetric=symmetric)


def _check_params(params) -> None:
    """Refuse energy parameters that are not a pytree of real numbers or real arrays (a
    string, an object, complex numbers): JAX would fail on them only inside minimize."""
    for path, leaf in jax.tree_util.tree_leaves_with_path(params):
        if isinstance(leaf, jax.core.Tracer):
            continue
        try:
            kind = np.asarray(leaf).dtype.kind
        except Exception:       # noqa: BLE001 - an object numpy cannot hold as an array
            kind = "O"
        if kind not in "biuf":
            where = jax.tree_util.keystr(path) or "params"
            raise MeshError(f"energy: params must be a pytree of real numbers or real arrays (a "
                            f"float, an array, a tuple or dict of them), got {leaf!r} at "
                            f"{where}.")


def _check_scalar(fn: Callable, n: int, params, parametric: bool) -> None:
    """Refuse, when the energy is made, an ``fn`` whose value is not one real number per
    triangle (found by :func:`jax.eval_shape`, no arithmetic); a function JAX cannot trace
    abstractly is left to fail, with its own message, where it is used."""
    probe = ((jax.ShapeDtypeStruct((), jnp.float64),) * 2 if n == 2
             else (jax.ShapeDtypeStruct((2, 2), jnp.float64),))
    extra = (params,) if parametric else ()
    try:
        out = jax.eval_shape(lambda *a: fn(*a, *extra), *probe)
    except Exception:       # noqa: BLE001 - not ours to judge here
        return
    shape = getattr(out, "shape", None)
    if shape != () or not jnp.issubdtype(getattr(out, "dtype", jnp.int32), jnp.floating):
        got = (f"shape {shape} and dtype {getattr(out, 'dtype', None)}" if shape is not None
               else type(out).__name__)
        what = "f(s1, s2)" if n == 2 else "f(J) of the 2x2 Jacobian J"
        raise MeshError(f"energy: {what} must return one real number (a density per "
                        f"triangle), got {got}; reduce it, e.g. with jnp.sum.")


_STRETCH_OF_J = SingularValueForm(lambda s1, s2: 0.5 * (s1 ** -2 + s2 ** -2), True)


def _density_stretch(frame, q, params):
    """Sander et al.'s L2 stretch of one triangle times ``(|T| / mean_area) ** -power``
    (``params = (mean_area, power)``; ``|T|`` from the frame ``(3, 2)``)."""
    mean_area, power = params
    e1, e2 = frame[1] - frame[0], frame[2] - frame[0]
    a = 0.5 * jnp.abs(e1[0] * e2[1] - e1[1] * e2[0])
    return (a / mean_area) ** (-power) * _STRETCH_OF_J(geo.jacobian_from_frame(frame, q))


def density_stretch(mean_area: float, power: float = 1.0) -> Energy:
    """The L2 stretch (``ENERGIES["stretch"]``) weighted by the input's face density: each
    triangle's density times ``(|T| / mean_area) ** -power``.

    With ``power = 1`` every face counts the same in the mesh energy (10) instead of by its
    3D area, so regions the input resolves with many small faces (a scan's detail) get
    proportionally more parameter area, and a remesh's dyadic grid more samples there.
    ``mean_area`` (mesh units squared, e.g. the mean face area) only scales the energy.
    A function of the frame (the weight needs the 3D area), so the minimizer differentiates
    it in the 6 UVs of each face.  Used by :func:`jaxparam.remesh.area_aware_map`.

    Example::

        en = density_stretch(float(jnp.mean(jp.geometry.face_areas(V, F))))
        jp.minimize(mesh, en, init=jp.convex_map(mesh))
    """
    if not isinstance(mean_area, jax.core.Tracer):
        if not (np.isfinite(mean_area) and mean_area > 0):
            raise MeshError(f"density_stretch: mean_area must be a positive area, got "
                            f"{mean_area!r}.")
        mean_area = float(mean_area)
    return Energy("density_stretch", _density_stretch, parametric=True,
                  params=(mean_area, float(power)))
