"""The per-triangle forms of a distortion density (survey §6, eq. (9)): a function of the
triangle's Jacobian ``J``, or of its singular values ``s1 >= s2`` (a barrier making it ``+inf``
where ``det J <= 0``), each with its closed-form ``dE/dJ`` for the mesh energy's hand-written
derivative (:mod:`jaxparam.energies`).

They are frozen dataclasses, not closures, so that an energy built twice from the same user
function compares (and hashes) equal field by field, and shares compiled kernels.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from . import geometry as geo
from . import tol

__all__ = ["OfJacobian", "SingularValueForm", "JacobianForm", "safe_root", "inf_where_inverted",
           "SYMMETRIC_TAYLOR", "samples", "looks_invariant", "SWAP", "SCALE"]


#: A symmetric user energy of the singular values is evaluated by its expansion in
#: ``S = ((s1 - s2) / 2)^2`` where ``S`` is below this times ``((s1 + s2) / 2)^2`` (``s1 - s2``
#: below 2e-4 of ``s1 + s2``): there the exact formula's second derivative loses about
#: ``eps (s1 + s2)^2 / (s1 - s2)^2`` (1e-8 at the threshold) and the expansion's two terms
#: are off by about as much (:meth:`SingularValueForm.of_QS`).
SYMMETRIC_TAYLOR = 1e-8


def inf_where_inverted(det, value):
    """``value`` where ``det > 0``, ``+inf`` elsewhere, with finite gradients on both sides."""
    return jnp.where(det > 0, value, jnp.inf)


@dataclass(frozen=True)
class OfJacobian:
    """``density(frame, q) = of_J(J)``, ``J`` the triangle's Jacobian (9)."""

    of_J: Callable

    def __call__(self, frame, q, *params):
        return self.of_J(geo.jacobian_from_frame(frame, q), *params)


@dataclass(frozen=True)
class SingularValueForm:
    """``of_J(J) = fn(s1, s2)``, ``+inf`` where ``det J <= 0`` when ``barrier``
    (``|s2|`` otherwise).

    ``invariants``, when given, is the same function of ``(s1^2 + s2^2, s1 s2)`` (``s1 |s2|``
    without a barrier): ``fn(s1, s2) == invariants(s1**2 + s2**2, s1 * s2)``, which only a
    symmetric ``fn`` has.  The derivative of the mesh energy then takes the Gram chain
    (the mesh energy's Gram chain in :mod:`jaxparam.energies`)."""

    fn: Callable
    barrier: bool
    invariants: Callable | None = None
    symmetric: bool = False

    def __call__(self, J, *params):
        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
        if self.symmetric and self.invariants is None:
            if self.barrier:                # inverted: +inf, with finite gradients
                J = jnp.where(det > 0, J, jnp.eye(2))
            E, F = 0.5 * (J[0, 0] + J[1, 1]), 0.5 * (J[0, 0] - J[1, 1])
            G, H = 0.5 * (J[1, 0] + J[0, 1]), 0.5 * (J[1, 0] - J[0, 1])
            value = self.of_QS(safe_root(E * E + H * H)[0], F * F + G * G, params)
            return inf_where_inverted(det, value) if self.barrier else value
        if self.invariants is not None:
            # tr and det J are polynomials of J: no singular value's square root, so the
            # second derivative has no 0 / 0 at a conformal face (s1 = s2), where the
            # singular values' chain divides df/ds1 - df/ds2 by s1 - s2 and loses every
            # digit (the implicit gradient's Hessian and mixed derivative need it there).
            tr = jnp.sum(J * J)
            if not self.barrier:
                return self.invariants(tr, jnp.abs(det), *params)
            return inf_where_inverted(det, self.invariants(tr, jnp.where(det > 0, det, 1.0), *params))
        s1, s2 = geo.singular_values(J)
        if not self.barrier:
            return self.fn(s1, jnp.abs(s2), *params)
        s2_safe = jnp.where(det > 0, s2, 1.0)
        s1_safe = jnp.where(det > 0, s1, 1.0)
        return inf_where_inverted(det, self.fn(s1_safe, s2_safe, *params))

    def of_QS(self, Q, S, params=()):
        """A symmetric ``fn`` as a function of ``Q = (s1 + s2) / 2`` and ``S = ((s1 - s2) /
        2)^2``, smooth in both: ``fn(Q + sqrt S, Q - sqrt S)`` (``|s2|`` without a barrier), and
        where ``S < SYMMETRIC_TAYLOR * Q^2`` its expansion ``g(0) + g''(0) S / 2`` in ``S``
        (``g(r) = fn(Q + r, Q - r)``, even: its odd terms vanish), so that no derivative divides
        by ``s1 - s2`` (0 / 0 at a conformal face: the singular values' chain has no Hessian
        there).  Scalars (one face)."""
        small = S < SYMMETRIC_TAYLOR * Q * Q
        # the branch not taken is evaluated at a harmless place (finite values and derivatives)
        R = jnp.where(small, 0.5 * Q, safe_root(jnp.where(small, 1.0, S))[0])
        s2 = Q - R if self.barrier else jnp.abs(Q - R)
        exact = self.fn(Q + R, s2, *params)
        Qs = jnp.where(small, Q, 1.0)
        g = lambda r: self.fn(Qs + r, Qs - r, *params)
        taylor = g(0.0) + 0.5 * jax.grad(jax.grad(g))(0.0) * S
        return jnp.where(small, taylor, exact)

    def value_and_dJ(self, a, b, c, d, params=()):
        """Closed-form values and ``dE/dJ`` of ``m`` Jacobians ``[[a, b], [c, d]]`` (each
        ``(m,)``): ``(values (m,), (dE/da, dE/db, dE/dc, dE/dd), (s1s, s2s, ok))``, by the
        singular values' chain (a ``symmetric`` form's through ``(Q, S)``, :meth:`of_QS`), as
        JAX's derivative of :meth:`__call__` without ``invariants`` gives them (a form with invariants takes
        the mesh energy's Gram chain in :mod:`jaxparam.energies` instead, unless it has parameters; the safe square roots' zero
        gradient at 0 included; 0 where the barrier is infinite); ``(s1s, s2s)`` are the
        singular values ``fn`` was evaluated at and ``ok`` where the value is finite
        (``None`` without a barrier), for the parameters' derivative."""
        E, F = 0.5 * (a + d), 0.5 * (a - d)
        G, H = 0.5 * (c + b), 0.5 * (c - b)
        Q, iQ = safe_root(E * E + H * H)
        R, iR = safe_root(F * F + G * G)
        s1, s2 = Q + R, Q - R
        if self.symmetric:
            # through (Q, S = R^2): dE/dR / (2 R) is dE/dS, with no 0 / 0 where R = 0
            qs = jax.vmap(jax.value_and_grad(self.of_QS, argnums=(0, 1)),
                          in_axes=(0, 0, None))
            ok = a * d - b * c > 0 if self.barrier else None
            Qv, Sv = (Q, F * F + G * G) if ok is None else (jnp.where(ok, Q, 1.0),
                                                            jnp.where(ok, F * F + G * G, 0.0))
            y, (fQ, fS) = qs(Qv, Sv, tuple(params))
            if self.barrier:
                y, fQ, fS = jnp.where(ok, y, jnp.inf), jnp.where(ok, fQ, 0.0), jnp.where(ok, fS, 0.0)
            hq, hr = 0.5 * fQ * iQ, fS
            s1, s2 = ((jnp.where(ok, s1, 1.0), jnp.where(ok, s2, 1.0)) if self.barrier
                      else (s1, jnp.abs(s2)))
            return y, (hq * E + hr * F, hr * G - hq * H, hq * H + hr * G, hq * E - hr * F), (s1, s2, ok)
        fn = jax.vmap(jax.value_and_grad(self.fn, argnums=(0, 1)),
                      in_axes=(0, 0) + (None,) * len(params))
        if self.barrier:
            ok = a * d - b * c > 0
            s1, s2 = jnp.where(ok, s1, 1.0), jnp.where(ok, s2, 1.0)
            y, (f1, f2) = fn(s1, s2, *params)
            y, f1, f2 = jnp.where(ok, y, jnp.inf), jnp.where(ok, f1, 0.0), jnp.where(ok, f2, 0.0)
        else:
            ok = None
            y, (f1, f2) = fn(s1, jnp.abs(s2), *params)
            f2 = f2 * jnp.sign(s2)
            s2 = jnp.abs(s2)
        # s1 = Q + R, s2 = Q - R;  dQ = (E, -H, H, E) / (2 Q),  dR = (F, G, G, -F) / (2 R)
        hq, hr = 0.5 * (f1 + f2) * iQ, 0.5 * (f1 - f2) * iR
        return y, (hq * E + hr * F, hr * G - hq * H, hq * H + hr * G, hq * E - hr * F), (s1, s2, ok)


@dataclass(frozen=True)
class JacobianForm:
    """``of_J(J) = fn(J)``, ``+inf`` where ``det J <= 0`` when ``barrier``."""

    fn: Callable
    barrier: bool

    def __call__(self, J, *params):
        if not self.barrier:
            return self.fn(J, *params)
        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
        J_safe = jnp.where(det > 0, J, jnp.eye(2))
        return inf_where_inverted(det, self.fn(J_safe, *params))

    def value_and_dJ(self, a, b, c, d, params=()):
        """Values and ``dE/dJ`` of ``m`` Jacobians ``[[a, b], [c, d]]`` (each ``(m,)``), as
        :meth:`SingularValueForm.value_and_dJ` (``fn``'s own gradient by JAX, the barrier's
        mask by hand); the third item is ``(J_safe (m, 2, 2), ok)``."""
        J = jnp.stack([jnp.stack([a, b], -1), jnp.stack([c, d], -1)], -2)
        fn = jax.vmap(jax.value_and_grad(self.fn), in_axes=(0,) + (None,) * len(params))
        ok = None
        if self.barrier:
            ok = a * d - b * c > 0
            J = jnp.where(ok[:, None, None], J, jnp.eye(2))
        y, g = fn(J, *params)
        if self.barrier:
            y, g = jnp.where(ok, y, jnp.inf), jnp.where(ok[:, None, None], g, 0.0)
        return y, (g[:, 0, 0], g[:, 0, 1], g[:, 1, 0], g[:, 1, 1]), (J, ok)


def safe_root(x):
    """``(sqrt(x), 1 / sqrt(x))``, both 0 at or below the safe square root's floor (the value
    and the derivative :func:`jaxparam.geometry.safe_sqrt` has there)."""
    pos = x > tol.SAFE_SQRT_FLOOR
    r = jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)
    return r, jnp.where(pos, 1.0 / jnp.where(pos, r, 1.0), 0.0)


def samples(n: int) -> tuple:
    """16 random arguments of a density: pairs ``(s1, s2)`` in ``[0.3, 3]^2`` (``n = 2``), or
    Jacobians ``U diag(s1, s2) V^T`` with those singular values and ``det > 0`` (``n = 1``)."""
    rng = np.random.default_rng(0)
    s = rng.uniform(0.3, 3.0, (2, 16))
    if n == 2:
        return tuple(jnp.asarray(x) for x in s)
    t, u = rng.uniform(0.0, 2 * np.pi, (2, 16))
    rot = lambda a: np.stack([np.stack([np.cos(a), -np.sin(a)], -1),
                              np.stack([np.sin(a), np.cos(a)], -1)], -2)
    return (jnp.asarray(rot(t) @ (s.T[:, :, None] * np.eye(2)) @ rot(u).transpose(0, 2, 1)),)


def looks_invariant(fn: Callable, n: int, moves, *params) -> bool:
    """Whether ``fn(*x, *params) == fn(*move(*x), *params)`` (to 1e-12 relative) for every
    ``move`` of ``moves`` on :func:`samples`' 16 arguments, and, with parameters, whether the
    differences' derivatives in their float leaves vanish too (``s1^2 + a s2^2`` is symmetric
    at ``a = 1`` only); ``False`` when that cannot be evaluated (traced parameters, a function
    JAX cannot map)."""
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(params)):
        return False
    xs = samples(n)
    w = jnp.asarray(np.random.default_rng(1).standard_normal(16))
    at = lambda args, p: jax.vmap(lambda *a: fn(*a, *p))(*args)
    try:
        with jax.ensure_compile_time_eval():
            x = np.asarray(at(xs, params), np.float64)
            if x.shape != (16,) or not np.all(np.isfinite(x)):
                return False
            size = max(1.0, float(np.mean(np.abs(x))))
            for move in moves:
                y = np.asarray(at(move(*xs), params), np.float64)
                if not np.all(np.abs(x - y) <= 1e-12 * np.maximum(1.0, np.abs(x))):
                    return False
                if not any(jnp.issubdtype(jnp.result_type(leaf), jnp.inexact)
                           for leaf in jax.tree_util.tree_leaves(params)):
                    continue
                gap = lambda p: jnp.sum(w * (at(xs, p) - at(move(*xs), p)))
                d = jax.grad(gap, allow_int=True)(params)
                if not all(np.all(np.abs(np.asarray(g, np.float64)) <= 1e-10 * size)
                           for g in jax.tree_util.tree_leaves(d)
                           if jnp.issubdtype(jnp.result_type(g), jnp.inexact)):
                    return False
            return True
    except Exception:       # noqa: BLE001 - a function JAX cannot map is not ours to judge
        return False


#: The moves a user energy is tested against (:func:`jaxparam.energies.energy`): the singular
#: values swapped (symmetric), and the map scaled up and down (scale-invariant).
SWAP = (lambda a, b: (b, a),)
SCALE = (lambda *x: tuple(2.0 * v for v in x), lambda *x: tuple(0.37 * v for v in x))
