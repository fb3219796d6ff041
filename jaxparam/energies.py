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
``arap``, ``conformal`` (LSCM), ``dirichlet``.
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Callable

import jax
import jax.numpy as jnp

from . import geometry as geo
from .errors import MeshError

__all__ = ["Energy", "energy", "ENERGIES", "get", "mips_prop2", "total"]


@dataclass(frozen=True, eq=False)
class Energy:
    """A per-triangle energy density and how to treat it.

    **Fields:** ``name``; ``density(frame (3, 2), q (3, 2)) -> scalar``;
    ``scale_invariant`` (unchanged when the UVs are scaled: E1–E4, MIPS,
    angle, conformal); ``barrier`` (``+inf`` where a triangle is inverted).
    """

    name: str
    density: Callable = field(repr=False)
    scale_invariant: bool = False
    barrier: bool = True

    def __call__(self, mesh, uv):
        """The mesh energy of ``uv: (n, 2)``: area-weighted mean of the density."""
        frames = geo.local_frames(jnp.asarray(mesh.vertices), mesh.faces)
        return total(self, frames, geo.face_areas(jnp.asarray(mesh.vertices), mesh.faces),
                     jnp.asarray(uv)[mesh.faces])


def total(en: Energy, frames, areas, Q):
    """``sum_T |T| f(frame_T, q_T) / sum_T |T|`` for per-face ``frames (m, 3, 2)``,
    ``areas (m,)`` and UV corners ``Q (m, 3, 2)``."""
    dens = jax.vmap(en.density)(frames, Q)
    return jnp.sum(areas * dens) / jnp.sum(areas)


def _barrier(det, value):
    """``value`` where ``det > 0``, ``+inf`` elsewhere, with finite gradients on both sides."""
    return jnp.where(det > 0, value, jnp.inf)


def _with_J(of_J):
    """A density ``f(frame, q) = g(J)`` that also carries ``g`` as ``density.of_J``, so the
    minimizer can take Hessians in the 4 entries of ``J`` instead of the 6 UV coordinates."""
    def density(frame, q):
        return of_J(geo.jacobian_from_frame(frame, q))
    density.of_J = of_J
    return density


def _from_sv(fn, *, barrier=True):
    """Density from a function of the singular values (s1 >= s2 > 0 when unflipped)."""
    def of_J(J):
        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
        s1, s2 = geo.singular_values(J)
        if not barrier:
            return fn(s1, jnp.abs(s2))
        s2_safe = jnp.where(det > 0, s2, 1.0)
        s1_safe = jnp.where(det > 0, s1, 1.0)
        return _barrier(det, fn(s1_safe, s2_safe))
    density = _with_J(of_J)
    if barrier:
        density.of_sv = fn      # the energy as a function of (s1, s2), for analytic eigensystems
    return density


def _from_J(fn, *, barrier=True):
    """Density from a function of the 2x2 Jacobian."""
    def of_J(J):
        if not barrier:
            return fn(J)
        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
        J_safe = jnp.where(det > 0, J, jnp.eye(2))
        return _barrier(det, fn(J_safe))
    return _with_J(of_J)


def _angle_density(frame, q):
    """Sheffer–de Sturler: ``sum_i (theta_i - alpha_i)^2`` over the corners, theta the UV
    angles, alpha the 3D (= frame) angles; +inf when inverted.  Not convex in the UVs: on
    camelhead Newton from the Tutte map stops in a local minimum (0.0137), from the MIPS
    optimum it reaches 0.0044, so start it from ``minimize(mesh, "mips", ...).uv``."""
    alpha = geo.corner_angles(frame, jnp.array([[0, 1, 2]]))[0]
    theta = geo.corner_angles(q, jnp.array([[0, 1, 2]]))[0]
    det = geo.signed_areas(q, jnp.array([[0, 1, 2]]))[0]
    return _barrier(det, jnp.sum((jnp.where(det > 0, theta, alpha) - alpha) ** 2))


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
    "condition_2": Energy("condition_2", _from_sv(lambda s1, s2: s1 / s2), True),
    "mips": Energy("mips", _from_sv(lambda s1, s2: s1 / s2 + s2 / s1), True),
    "condition_2_squared": Energy("condition_2_squared", _from_sv(lambda s1, s2: (s1 / s2) ** 2), True),
    "condition_f_squared": Energy("condition_f_squared",
                                  _from_sv(lambda s1, s2: (s1 / s2) ** 2 + (s2 / s1) ** 2), True),
    "angle": Energy("angle", _angle_density, True),
    # Maillot et al.: the Green–Lagrange tensor ||J^T J - I||_F^2 (not a deformation functional).
    "green_lagrange": Energy("green_lagrange",
                             _from_J(lambda J: jnp.sum((J.T @ J - jnp.eye(2)) ** 2), barrier=False),
                             False, False),
    "symmetric_dirichlet": Energy("symmetric_dirichlet",
                                  _from_sv(lambda s1, s2: s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2)),
    "arap": Energy("arap", _from_sv(lambda s1, s2: (s1 - 1) ** 2 + (s2 - 1) ** 2, barrier=False),
                   False, False),
    "conformal": Energy("conformal", _from_sv(lambda s1, s2: 0.5 * (s1 - s2) ** 2, barrier=False),
                        True, False),
    "dirichlet": Energy("dirichlet", _from_J(lambda J: 0.5 * jnp.sum(J ** 2), barrier=False),
                        False, False),
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


def energy(fn: Callable, *, name: str | None = None, scale_invariant: bool = False,
           barrier: bool = True) -> Energy:
    """A user energy from ``f(s1, s2)`` (singular values) or ``f(J)`` (the 2x2 Jacobian).

    The number of positional parameters decides which.  The energy is
    ``+inf`` on inverted triangles when ``barrier`` (the default), and works
    with every solver of :func:`jaxparam.minimize`: JAX supplies its
    gradient and Hessian.

    Example::

        e = jp.energy(lambda s1, s2: s1 / s2 + s2 / s1)       # MIPS, written by hand
        res = jp.minimize(mesh, e)
    """
    try:
        params = [p for p in inspect.signature(fn).parameters.values()
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty]
    except (TypeError, ValueError):
        params = [None]
    n = len(params)
    if n == 2:
        dens = _from_sv(fn, barrier=barrier)
    elif n == 1:
        dens = _from_J(fn, barrier=barrier)
    else:
        raise MeshError(f"energy: a user energy takes (s1, s2) or (J), got a function of {n} "
                        "arguments.")
    return Energy(name or getattr(fn, "__name__", "user"), dens, scale_invariant, barrier)
