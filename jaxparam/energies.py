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
from .errors import MeshError

__all__ = ["Energy", "Densities", "energy", "ENERGIES", "get", "mips_prop2", "total",
           "params_equal", "captures_tracer", "density_stretch"]


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

    def densities(self, params=None) -> Densities:
        """The density, ``of_J`` and ``of_sv`` with ``params`` (default: :attr:`params`)
        bound, each taking its usual arguments (``(frame, q)``, ``J``, ``(s1, s2)``)."""
        if not self.parametric:
            return Densities(self.density, self.of_J, self.of_sv)
        p = self.params if params is None else params
        return Densities(_bind(self.density, p), _bind(self.of_J, p), _bind(self.of_sv, p))

    def __call__(self, mesh, uv):
        """The mesh energy of ``uv: (n, 2)``: area-weighted mean of the density."""
        frames = geo.local_frames(jnp.asarray(mesh.vertices), mesh.faces)
        return total(self, frames, geo.face_areas(jnp.asarray(mesh.vertices), mesh.faces),
                     jnp.asarray(uv)[mesh.faces])


def total(en: Energy, frames, areas, Q, params=None):
    """``sum_T |T| f(frame_T, q_T) / sum_T |T|`` for per-face ``frames (m, 3, 2)``,
    ``areas (m,)`` and UV corners ``Q (m, 3, 2)``; ``params``: the energy's parameters
    (default ``en.params``)."""
    dens = jax.vmap(en.densities(params).density)(frames, Q)
    return jnp.sum(areas * dens) / jnp.sum(areas)


def _barrier(det, value):
    """``value`` where ``det > 0``, ``+inf`` elsewhere, with finite gradients on both sides."""
    return jnp.where(det > 0, value, jnp.inf)


# The three callables below are frozen dataclasses, not closures, so that an Energy built
# twice from the same user function compares (and hashes) equal field by field.

@dataclass(frozen=True)
class _OfJacobian:
    """``density(frame, q) = of_J(J)``, ``J`` the triangle's Jacobian (9)."""

    of_J: Callable

    def __call__(self, frame, q, *params):
        return self.of_J(geo.jacobian_from_frame(frame, q), *params)


@dataclass(frozen=True)
class _SingularValueForm:
    """``of_J(J) = fn(s1, s2)``, ``+inf`` where ``det J <= 0`` when ``barrier``
    (``|s2|`` otherwise)."""

    fn: Callable
    barrier: bool

    def __call__(self, J, *params):
        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
        s1, s2 = geo.singular_values(J)
        if not self.barrier:
            return self.fn(s1, jnp.abs(s2), *params)
        s2_safe = jnp.where(det > 0, s2, 1.0)
        s1_safe = jnp.where(det > 0, s1, 1.0)
        return _barrier(det, self.fn(s1_safe, s2_safe, *params))


@dataclass(frozen=True)
class _JacobianForm:
    """``of_J(J) = fn(J)``, ``+inf`` where ``det J <= 0`` when ``barrier``."""

    fn: Callable
    barrier: bool

    def __call__(self, J, *params):
        if not self.barrier:
            return self.fn(J, *params)
        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
        J_safe = jnp.where(det > 0, J, jnp.eye(2))
        return _barrier(det, self.fn(J_safe, *params))


def _from_sv(name, fn, scale_invariant=False, *, barrier=True, parametric=False,
             params=None) -> Energy:
    """An Energy from a function of the singular values (s1 >= s2 > 0 when unflipped);
    ``fn(s1, s2, params)`` when ``parametric``."""
    of_J = _SingularValueForm(fn, barrier)
    return Energy(name, _OfJacobian(of_J), scale_invariant, barrier, of_J=of_J,
                  of_sv=fn if barrier else None, parametric=parametric, params=params)


def _from_J(name, fn, scale_invariant=False, *, barrier=True, parametric=False,
            params=None) -> Energy:
    """An Energy from a function of the 2x2 Jacobian; ``fn(J, params)`` when ``parametric``."""
    of_J = _JacobianForm(fn, barrier)
    return Energy(name, _OfJacobian(of_J), scale_invariant, barrier, of_J=of_J,
                  parametric=parametric, params=params)


def _angle_density(frame, q):
    """Sheffer–de Sturler: ``sum_i (theta_i - alpha_i)^2`` over the corners, theta the UV
    angles, alpha the 3D (= frame) angles; +inf when inverted.  Not convex in the UVs: from
    the Tutte map Newton can stop in a local minimum, so start it from
    ``minimize(mesh, "mips", ...).uv`` (benchmarks/README.md has the figures)."""
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
    "condition_2": _from_sv("condition_2", lambda s1, s2: s1 / s2, True),
    "mips": _from_sv("mips", lambda s1, s2: s1 / s2 + s2 / s1, True),
    "condition_2_squared": _from_sv("condition_2_squared", lambda s1, s2: (s1 / s2) ** 2, True),
    "condition_f_squared": _from_sv("condition_f_squared",
                                    lambda s1, s2: (s1 / s2) ** 2 + (s2 / s1) ** 2, True),
    "angle": Energy("angle", _angle_density, True),
    # Maillot et al.: the Green–Lagrange tensor ||J^T J - I||_F^2 (not a deformation functional).
    "green_lagrange": _from_J("green_lagrange", lambda J: jnp.sum((J.T @ J - jnp.eye(2)) ** 2),
                              barrier=False),
    "symmetric_dirichlet": _from_sv("symmetric_dirichlet",
                                    lambda s1, s2: s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2),
    "arap": _from_sv("arap", lambda s1, s2: (s1 - 1) ** 2 + (s2 - 1) ** 2, barrier=False),
    "conformal": _from_sv("conformal", lambda s1, s2: 0.5 * (s1 - s2) ** 2, True, barrier=False),
    "dirichlet": _from_J("dirichlet", lambda J: 0.5 * jnp.sum(J ** 2), barrier=False),
    # Sander et al. 2001 (survey ref. [27]): the L2 stretch of the inverse map UV -> surface,
    # whose singular values are 1/s2 >= 1/s1: (Gamma^2 + gamma^2) / 2; its area-weighted mean
    # is L2(M)^2.  Penalizes UV triangles small for their 3D area (the squeeze that starves
    # a remesh of samples); not scale invariant, so minimize it with a fixed boundary.
    "stretch": _from_sv("stretch", lambda s1, s2: 0.5 * (s1 ** -2 + s2 ** -2)),
}


def _captured(fn, depth: int = 0):
    """The values a function reaches without being passed them: its closure cells and
    defaults, a ``functools.partial``'s arguments, the wrapped function of our wrappers."""
    if depth > 4 or fn is None:
        return []
    out = []
    for attr in ("of_J", "fn", "func"):             # _OfJacobian, the forms, partial
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
           scale_invariant: bool = False, barrier: bool = True) -> Energy:
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

    Example::

        e = jp.energy(lambda s1, s2: s1 / s2 + s2 / s1)       # MIPS, written by hand
        res = jp.minimize(mesh, e)
        w = jp.energy(lambda s1, s2, a: s1 ** 2 + s2 ** 2 + a * (s1 ** -2 + s2 ** -2), 2.0)
        jax.grad(lambda a: jnp.sum(jp.minimize(mesh, jp.energy(f, a)).uv ** 2))(2.0)
    """
    parametric = params is not _NO_PARAMS
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
    make = _from_sv if n == 2 else _from_J
    return make(name or getattr(fn, "__name__", "user"), fn, scale_invariant, barrier=barrier,
                parametric=parametric, params=params if parametric else None)


_STRETCH_OF_J = _SingularValueForm(lambda s1, s2: 0.5 * (s1 ** -2 + s2 ** -2), True)


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
