"""Convex-combination and spring weights, one value per one-ring entry (survey §4, §5).

Each kind is computed for every entry ``(v, w)`` of an *interior* vertex's
one-ring at once (no loop over vertices), in JAX, differentiable in the
vertex positions.  The entries are those of :func:`ring_entries`: the
topology's CSR one-rings restricted to interior rows, anticlockwise.  The same
kinds (but ``harmonic``, which needs faces) are computed on the fans of a
neighbour graph of unorganized points (survey §8): :func:`fan_entries`,
:func:`fan_weights`.  Both go through one formula per kind,
:func:`weights_from_angles`, given each entry's angle, previous angle and length.

Two families:

- *spring* weights ``mu`` (``uniform``, ``inverse_distance``, ``harmonic``,
  user edge weights): symmetric, ``mu_vw = mu_wv``; the map minimizes the
  spring energy (8) and the system can be solved as a symmetric one;
- *barycentric* weights (``shape_preserving``, ``mean_value``): one row per
  vertex, positive, reproducing the vertex from its flattened neighbours.

:func:`convex_weights` normalizes either kind to ``lambda_vw`` summing to 1
per vertex, the coefficients of eq. (3).
"""
from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass

import numpy as np

from .lazy_jax import jax, jnp  # JAX loads on first use (issue 17)
from .options import choose
from .errors import MeshError
from .geometry import dot as geo_dot, safe_norm
from . import host as _host

__all__ = [
    "KINDS", "SYMMETRIC_KINDS", "FAN_KINDS", "RingEntries", "ring_entries", "entry_weights",
    "convex_weights", "normalize", "edge_values_to_entries", "weights_from_angles",
    "shape_preserving_weights", "loop_bound", "host_entry_weights", "is_concrete", "FanEntries", "fan_entries", "fan_weights",
]

KINDS = ("uniform", "inverse_distance", "shape_preserving", "mean_value", "harmonic")
SYMMETRIC_KINDS = ("uniform", "inverse_distance", "harmonic")
#: The kinds defined on point fans (no faces, so no ``harmonic``).
FAN_KINDS = ("uniform", "inverse_distance", "shape_preserving", "mean_value")


@dataclass(frozen=True, eq=False)
class RingEntries:
    """The one-ring entries of the interior vertices, as flat numpy arrays.

    **Fields** (``k`` entries, ``ni`` interior vertices):
    ``entry (k,)`` index into the topology's ring arrays; ``row (k,)`` interior
    slot of the centre vertex; ``center``, ``nbr``, ``prev``, ``next`` ``(k,)``
    vertex indices (the neighbour and the ones before/after it, anticlockwise);
    ``row_start (k,)``, ``row_end (k,)`` entry range of the row; ``degree (ni,)``.
    """

    entry: np.ndarray
    row: np.ndarray
    center: np.ndarray
    nbr: np.ndarray
    prev: np.ndarray
    next: np.ndarray
    wedge: np.ndarray
    prev_wedge: np.ndarray
    row_start: np.ndarray
    row_end: np.ndarray
    degree: np.ndarray
    n_rows: int


@functools.lru_cache(maxsize=16)
def ring_entries(topology) -> RingEntries:
    """Build (once per topology) the interior one-ring entries."""
    t = topology
    interior_row = ~t.is_boundary[t.ring_row] & t.referenced[t.ring_row]
    entry = np.flatnonzero(interior_row)
    center = t.ring_row[entry]
    row = t.slot[center]
    degree = np.bincount(row, minlength=t.interior.size)
    starts = np.zeros(t.interior.size + 1, np.int64)
    np.cumsum(degree, out=starts[1:])
    k = np.arange(entry.size)
    row_start, row_end = starts[row], starts[row + 1]
    prev_k = np.where(k > row_start, k - 1, row_end - 1)
    wedge = t.ring_wedge[entry]
    return RingEntries(entry=entry, row=row, center=center, nbr=t.ring_idx[entry],
                       prev=t.ring_prev[entry], next=t.ring_next[entry], wedge=wedge,
                       prev_wedge=wedge[prev_k], row_start=row_start, row_end=row_end,
                       degree=degree, n_rows=int(t.interior.size))


def _corner_geometry(V, F):
    """Per corner ``3 f + c`` of every face: the angle there, its cotangent, and the length
    of the half-edge leaving it (corner c -> c + 1).  Computed once per face, so that
    every one-ring quantity below is a gather (survey §4–5 need only these).

    The corner angles are unsigned, ``arctan2(|e x f|, e . f)``: smooth on every triangle
    with a nonzero area (angles in ``(0, pi)``), kinked only on a flat one (0 or ``pi``),
    which :class:`~jaxparam.TriMesh` refuses on construction
    (:class:`~jaxparam.DegenerateFaceError`, unless ``validate=False``)."""
    P = V[F]                                            # (m, 3, 3)
    e = jnp.roll(P, -1, axis=1) - P                     # half-edge c -> c+1
    f = jnp.roll(P, 1, axis=1) - P                      # c -> c-1
    cr = safe_norm(jnp.cross(e, f))
    dot = geo_dot(e, f)
    return (jnp.arctan2(cr, dot).reshape(-1), (dot / cr).reshape(-1),
            safe_norm(e).reshape(-1))


@functools.partial(jax.jit, static_argnames=("kind", "n_rows", "max_degree"))
def _weights_kernel(V, F, wedge, prev_wedge, row, row_start, row_end, degree, *, kind, n_rows,
                    max_degree):
    if kind == "mean_value":
        # Floater's weights from each corner's tan(delta / 2) directly (no arctan2, no tan).
        half, length = _corner_half_tangents(V[F])
        half, length = half.reshape(-1), length.reshape(-1)
        return (half[prev_wedge] + half[wedge]) / length[wedge]
    angle, cot, length = _corner_geometry(V, F)
    if kind == "harmonic":
        # mu_vw = (cot alpha + cot beta) / 2 with alpha, beta opposite [v, w] (survey §5): in the
        # wedge's face the opposite corner is c + 2, in the previous wedge's face c + 1.
        nxt_face = wedge - wedge % 3 + (wedge + 2) % 3
        prv_face = prev_wedge - prev_wedge % 3 + (prev_wedge + 1) % 3
        return 0.5 * (cot[nxt_face] + cot[prv_face])
    # angle[wedge] = ang(v_j, v, v_{j+1}), length[wedge] = |v_j - v|.
    return weights_from_angles(kind, angle[wedge], angle[prev_wedge], length[wedge], row,
                               row_start, row_end, degree, n_rows=n_rows, max_degree=max_degree)


def weights_from_angles(kind: str, angle, prev_angle, length, row, row_start, row_end, degree, *,
                        n_rows: int, max_degree: int):
    """Weights of one of :data:`FAN_KINDS` on entries ``(v, w_j)`` of anticlockwise fans, from
    the fans' angles and lengths: the one formula of each kind for mesh one-rings and point fans.

    **Arguments** (``k`` entries, rows contiguous and in fan order): ``angle (k,)`` the angle
    ``delta_j = ang(w_j, v, w_{j+1})`` at the centre; ``prev_angle (k,)`` the previous entry's,
    ``delta_{j-1}``; ``length (k,)`` ``r_j = |w_j - v|``; ``row (k,)`` the row of each entry,
    ``row_start (k,)``, ``row_end (k,)`` its entry range, ``degree (n_rows,)`` (these only for
    ``shape_preserving``); ``n_rows``; ``max_degree`` a bound on the degree that is a power
    of two (:func:`loop_bound`; ``shape_preserving`` only, else ignored).  JAX, traceable.

    **Returns:** ``(k,)`` unnormalized weights: ``uniform`` 1, ``inverse_distance`` ``1 / r_j``,
    ``mean_value`` Floater's ``(tan(delta_{j-1}/2) + tan(delta_j/2)) / r_j`` (2003),
    ``shape_preserving`` :func:`shape_preserving_weights` (rows summing to 1).

    **Where it is not differentiable.**  ``uniform`` and ``inverse_distance`` are smooth
    (away from ``r_j = 0``).  ``mean_value`` is as smooth as its angles: on point fans
    (:func:`fan_weights`) an angle is unsigned and kinks at 0 (two consecutive neighbours on
    one ray from the centre, ``delta = |t| / 2``-like in a displacement ``t`` off the ray), where
    JAX returns the mean of the two one-sided derivatives; at ``delta = pi`` (the centre on
    the segment between two consecutive neighbours) it has a pole, ``tan(pi/2)`` about
    ``1.6e16`` in floating point, with a finite JAX derivative.  ``shape_preserving``: see
    :func:`shape_preserving_weights` (``tests/test_weight_kinks.py`` checks each case).
    """
    if kind == "uniform":
        return jnp.ones_like(length)
    if kind == "inverse_distance":
        return 1.0 / length
    if kind == "mean_value":
        return _mean_value(angle, prev_angle, length)
    if kind == "shape_preserving":
        return shape_preserving_weights(angle, length, row, row_start, row_end, degree,
                                        n_rows=n_rows, max_degree=max_degree)
    raise ValueError(kind)


@functools.cache
def _with_jvp(primal, jvp):
    """``primal`` as a ``jax.custom_jvp`` whose tangent rule is ``jvp`` (built once, on first use)."""
    f = jax.custom_jvp(primal)
    f.defjvp(jvp)
    return f


def _mean_value(angle, prev_angle, length):
    """Floater's mean-value weights ``(tan(delta_{j-1}/2) + tan(delta_j/2)) / r_j``, ``(k,)``
    (a ``jax.custom_jvp``, made on first use so that importing this module loads no JAX)."""
    return _with_jvp(_mean_value_primal, _mean_value_jvp)(angle, prev_angle, length)


def _mean_value_primal(angle, prev_angle, length):
    """Floater's mean-value weights ``(tan(delta_{j-1}/2) + tan(delta_j/2)) / r_j``, ``(k,)``
    from ``angle``, ``prev_angle``, ``length`` ``(k,)`` (:func:`weights_from_angles`)."""
    return (jnp.tan(0.5 * prev_angle) + jnp.tan(0.5 * angle)) / length


def _mean_value_jvp(primals, tangents):
    # d w = (1 + t^2) / (2 r) d delta + (1 + t_prev^2) / (2 r) d delta_prev - w / r d r, with the
    # three coefficients computed next to the primal tangents: JAX's own derivative has XLA fuse
    # tan into the (k, 3) loops of the angles' reverse pass and evaluate it again per
    # coordinate (issue 12: the weights' gradient 8-10 % faster on camelhead, values unchanged).
    angle, prev_angle, length = primals
    da, dp, dr = tangents
    tp, t = jnp.tan(0.5 * prev_angle), jnp.tan(0.5 * angle)
    w = (tp + t) / length
    il = 1.0 / length
    return w, (0.5 * (1.0 + t * t) * il) * da + (0.5 * (1.0 + tp * tp) * il) * dp - (w * il) * dr


#: ``tan(pi / 2)`` in floating point (about 1.6e16): the value of ``tan(delta / 2)`` at a
#: straight angle, the mean-value weights' pole (as ``jnp.tan(jnp.arctan2(0, -1) / 2)`` gives).
TAN_HALF_PI = float(np.tan(np.pi / 2))


def _half_tangent(s, t, ll):
    """``tan(delta / 2)`` of the angle ``delta`` between two vectors from ``s = |u x v|``,
    ``t = u . v`` and ``ll = |u| |v|``: ``s / (ll + t)`` for ``t >= 0`` and ``(ll - t) / s``
    for ``t < 0`` (each well conditioned where it is used: no cancellation), at most
    :data:`TAN_HALF_PI`.  Same shape as its arguments."""
    acute = t >= 0
    near = s / jnp.where(acute, jnp.where(ll + t > 0, ll + t, 1.0), 1.0)
    far = (ll - t) / jnp.where(acute | (s <= 0), 1.0, s)
    return jnp.where(acute, near, jnp.where(s > 0, jnp.minimum(far, TAN_HALF_PI), TAN_HALF_PI))


def _half_tangent_coefficients(u, v, c, s, t, half):
    """``(g, h)``, each shaped like ``u``: ``d tan(delta / 2) = g . du + h . dv`` for the angle
    ``delta`` between ``u`` and ``v`` (``c = u x v``, ``s = |c|``, ``t = u . v``, ``half`` its
    tangent).  With ``n = c / s``: ``d delta = ((t v x n - s v) . du + (t n x u - s u) . dv) /
    (s^2 + t^2)`` and ``d tan(delta / 2) = (1 + tan^2) / 2 d delta``.  At ``s = 0`` (collinear
    vectors, a kink of the unsigned angle) ``n = 0``, so both are 0: the mean of the one-sided
    derivatives at angle 0, as JAX's derivative of ``safe_norm`` gives."""
    has_s = s > 0
    n = c * jnp.where(has_s, 1.0 / jnp.where(has_s, s, 1.0), 0.0)[..., None]
    k = (0.5 * (1.0 + half * half) / jnp.where(has_s | (t != 0), s * s + t * t, 1.0))[..., None]
    g = k * (t[..., None] * jnp.cross(v, n) - s[..., None] * v)
    h = k * (t[..., None] * jnp.cross(n, u) - s[..., None] * u)
    return g, h


def _corner_half_tangents(P):
    """``(half, length)``, ``(m, 3)`` each, of triangles ``P (m, 3, 3)``: ``tan(theta_c / 2)``
    of the angle at corner ``c`` and the length of the half-edge leaving it (``c -> c + 1``)
    (a ``jax.custom_jvp``, made on first use).  Mean-value weights need only these:
    computed from the edge vectors they cost a third of ``arctan2`` and ``tan`` on camelhead."""
    return _with_jvp(_corner_half_tangents_primal, _corner_half_tangents_jvp)(P)


def _corner_half_tangents_parts(P):
    e = jnp.roll(P, -1, axis=1) - P                     # c -> c + 1
    f = jnp.roll(P, 1, axis=1) - P                      # c -> c - 1
    length = safe_norm(e)
    c = jnp.cross(e[:, 0], f[:, 0])                     # the face's normal, twice its area
    s = jnp.broadcast_to(safe_norm(c)[:, None], length.shape)
    t = jnp.sum(e * f, -1)
    half = _half_tangent(s, t, length * jnp.roll(length, 1, axis=1))
    return half, length, (e, f, jnp.broadcast_to(c[:, None, :], e.shape), s, t)


def _corner_half_tangents_primal(P):
    return _corner_half_tangents_parts(P)[:2]


def _corner_half_tangents_jvp(primals, tangents):
    (P,), (dP,) = primals, tangents
    half, length, (e, f, c, s, t) = _corner_half_tangents_parts(P)
    g, h = _half_tangent_coefficients(e, f, c, s, t, half)
    de = jnp.roll(dP, -1, axis=1) - dP
    df = jnp.roll(dP, 1, axis=1) - dP
    d_half = jnp.sum(g * de, -1) + jnp.sum(h * df, -1)
    d_length = jnp.sum(e * de, -1) / jnp.where(length > 0, length, 1.0)
    return (half, length), (d_half, d_length)


def _fan_half_tangents(d, nxt):
    """``(half, length)``, ``(k,)`` each: ``tan(delta_j / 2)`` of the unsigned angle between
    fan directions ``d_j`` and ``d_nxt(j)`` (``d (k, 3)``) and ``|d_j|`` (a ``jax.custom_jvp``,
    made on first use; the kinks are :func:`fan_weights`')."""
    return _with_jvp(_fan_half_tangents_primal, _fan_half_tangents_jvp)(d, nxt)


def _fan_half_tangents_parts(d, nxt):
    b = d.at[nxt].get(unique_indices=True)
    c = jnp.cross(d, b)
    s, t, r = safe_norm(c), jnp.sum(d * b, -1), safe_norm(d)
    return _half_tangent(s, t, r * r.at[nxt].get(unique_indices=True)), r, (b, c, s, t)


def _fan_half_tangents_primal(d, nxt):
    return _fan_half_tangents_parts(d, nxt)[:2]


def _fan_half_tangents_jvp(primals, tangents):
    d, nxt = primals
    dd = tangents[0]
    half, r, (b, c, s, t) = _fan_half_tangents_parts(d, nxt)
    g, h = _half_tangent_coefficients(d, b, c, s, t, half)
    # Reductions, not written-out sums: see _fan_angles_jvp.
    d_half = jnp.sum(g * dd, -1) + jnp.sum(h * dd.at[nxt].get(unique_indices=True), -1)
    d_length = jnp.where(r > 0, jnp.sum(d * dd, -1) / jnp.where(r > 0, r, 1.0), 0.0)
    return (half, r), (d_half, d_length)


def shape_preserving_weights(delta, r, row, row_start, row_end, degree, *, n_rows: int,
                             max_degree: int):
    """Floater's shape-preserving weights (survey §4, eq. (7)), all rows at once.

    **Arguments:** as :func:`weights_from_angles`'s (``delta`` the angles, ``r`` the lengths).

    Step 1, the geodesic polar map: neighbour j goes to ``p_j = r_j (cos phi_j,
    sin phi_j)`` with ``phi`` the accumulated angles scaled by ``rho = 2 pi /
    sum(delta)``.  Step 2: for each k, the ray from ``p = 0`` opposite ``p_k``
    crosses the edge ``[p_l, p_{l+1}]``; the barycentric coordinates of ``p``
    in ``[p_k, p_l, p_{l+1}]`` are averaged over k (eq. (7)).

    **Derivative.**  A ``jax.custom_jvp``: the tangent is written out from the forward's polar
    points, edges and areas (values bitwise the formula's); JAX transposes it for reverse mode,
    so ``jax.grad``, ``jax.jvp`` and ``jax.jacfwd`` all work.  On camelhead's point fans the
    weights' gradient costs about 1.3x their forward, against about 3.3x for JAX's own
    derivative of the formula (issue 12).

    **Kinks (the method is piecewise).**  The weights are continuous but only piecewise
    smooth: the edge ``[p_l, p_{l+1}]`` changes where the ray opposite ``p_k`` passes through
    a neighbour ``p_l`` (``phi_l = phi_k + pi``).  The edge is chosen on stopped-gradient
    angles, so JAX differentiates the branch the search picks: ``phi_l <= phi_k + pi``
    (mod ``2 pi``), i.e. ``l`` for ``k`` but ``k``'s predecessor side for ``l``.  At an exact
    opposite pair the two averaged terms (k's and l's) take the two triangles one each,
    and JAX's derivative is the *mean* of the two one-sided derivatives; when rounding puts
    ``phi_l`` a little off ``phi_k + pi`` it is the derivative of the side it falls on.
    On point fans the unsigned angles add the kinks of :func:`weights_from_angles` (a
    neighbour pair on one ray, angle 0; the centre on a segment, angle ``pi``), and these
    are not mean-valued: at angle ``pi`` JAX returns neither side, and where the ray
    opposite a neighbour passes through two neighbours on one ray the weights *jump* (the
    search takes the later of the two, a displacement to one side the earlier one);
    JAX's derivative there is finite and is that of neither side.  Such fans are
    degenerate (no strict star); ``tests/test_weight_kinks.py`` pins each case.
    """
    return _shape_preserving(int(n_rows), int(max_degree))(delta, r, row, row_start, row_end, degree)


@functools.cache
def _shape_preserving(n_rows: int, max_degree: int):
    """:func:`shape_preserving_weights` for ``n_rows`` rows as a ``jax.custom_jvp`` (made on
    first use, one per size)."""
    f = jax.custom_jvp(functools.partial(_shape_preserving_primal, n_rows=n_rows, max_degree=max_degree))
    f.defjvp(functools.partial(_shape_preserving_jvp, n_rows=n_rows, max_degree=max_degree))
    return f


def _shape_preserving_primal(delta, r, row, row_start, row_end, degree, *, n_rows, max_degree):
    return _shape_preserving_parts(delta, r, row, row_start, row_end, degree, n_rows=n_rows,
                                   max_degree=max_degree)[0]


def _cross2(a, b):
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def _shape_preserving_parts(delta, r, row, row_start, row_end, degree, *, n_rows, max_degree):
    """The weights ``(k,)`` and the intermediate values their tangent reuses."""
    total = jax.ops.segment_sum(delta, row, num_segments=n_rows)
    scale = (2 * jnp.pi / total)[row]
    cum = jnp.cumsum(delta)
    excl = cum - delta                                   # global exclusive cumsum
    x = excl - excl[row_start]                           # per-row exclusive cumsum
    phi = scale * x                                      # phi_0 = 0
    c, s = jnp.cos(phi), jnp.sin(phi)
    p = r[:, None] * jnp.stack([c, s], -1)
    # Locate the edge [p_l, p_{l+1}] opposite each p_k: l is the last neighbour of the row with
    # phi_l <= phi_k + pi (mod 2 pi).  phi increases along each row from phi_0 = 0, so a
    # branchless binary search within the row finds it in log2(max_degree) steps (int32: half
    # the loop's memory traffic).
    target = jax.lax.stop_gradient(jnp.mod(phi + jnp.pi, 2 * jnp.pi))
    phi_c = jax.lax.stop_gradient(phi)

    def bisect(_, state):
        base, size = state              # phi_c[base] <= target; the answer is in [base, base + size)
        half = size >> 1
        up = (half > 0) & (phi_c[base + half] <= target)
        return jnp.where(up, base + half, base), size - half

    steps = max(1, (int(max_degree) - 1).bit_length())
    l, _ = jax.lax.fori_loop(0, steps, bisect, (row_start.astype(jnp.int32),
                                                (row_end - row_start).astype(jnp.int32)))
    m = jnp.where(l + 1 < row_end, l + 1, row_start)
    pk, pl, pm = p, p[l], p[m]
    ak, al, am = _cross2(pl, pm), _cross2(pm, pk), _cross2(pk, pl)
    tot = ak + al + am
    k_idx = jnp.arange(p.shape[0])
    # An angle of pi or more at the centre (a sliver) makes the opposite "triangle" contain p_k
    # itself: then p lies on the edge from p_k to its neighbour, weighted by 1D interpolation.
    on_l, on_m = l == k_idx, m == k_idx
    flat = on_l | on_m | (jnp.abs(tot) <= 1e-300)
    tot = jnp.where(flat, 1.0, tot)
    rk, rl, rm = r, r[l], r[m]
    other = jnp.where(on_l, rm, rl)
    share_k = other / (rk + other)
    bk = jnp.where(flat, share_k, ak / tot)
    bl = jnp.where(on_l, 0.0, jnp.where(on_m, 1.0 - share_k, al / tot))
    bm = jnp.where(on_m, 0.0, jnp.where(on_l, 1.0 - share_k, am / tot))
    idx = jnp.concatenate([k_idx, l, m])
    lam = jax.ops.segment_sum(jnp.concatenate([bk, bl, bm]), idx, num_segments=p.shape[0])
    parts = dict(total=total, scale=scale, x=x, c=c, s=s, p=p, l=l, m=m, pl=pl, pm=pm,
                 tot=tot, flat=flat, on_l=on_l, on_m=on_m, other=other, rk=rk, bk=bk, bl=bl,
                 bm=bm, idx=idx, degree=degree[row])
    return lam / degree[row], parts


def _shape_preserving_jvp(primals, tangents, *, n_rows, max_degree):
    # The tangent of eq. (7) written out from the forward's values (issue 12): every step is a
    # gather, a segment sum or a cumsum, whose transposes are cheap, and the only data-dependent
    # gathers are one packed (k, 3) gather of (dp, dr) at l and one at m.  JAX's own derivative
    # of the forward differentiated every select and recomputed cos/sin; its reverse pass took
    # about 3x the forward on camelhead's point fans.
    delta, r, row, row_start, row_end, degree = primals
    d_delta, d_r = tangents[0], tangents[1]
    lam, q = _shape_preserving_parts(delta, r, row, row_start, row_end, degree, n_rows=n_rows,
                                     max_degree=max_degree)
    d_total = jax.ops.segment_sum(d_delta, row, num_segments=n_rows)
    # d x: the per-row exclusive cumsum of d delta = global exclusive cumsum minus the sum of
    # all earlier rows (a cumsum over rows, gathered by row: no gather at row_start).
    d_excl = jnp.cumsum(d_delta) - d_delta
    d_x = d_excl - (jnp.cumsum(d_total) - d_total)[row]
    d_scale = -(q["scale"] / q["total"][row]) * d_total[row]
    d_phi = d_scale * q["x"] + q["scale"] * d_x
    p, c, s = q["p"], q["c"], q["s"]
    dq = jnp.stack([c * d_r - p[:, 1] * d_phi, s * d_r + p[:, 0] * d_phi, d_r], -1)
    dql, dqm = dq[q["l"]], dq[q["m"]]
    dpk, dpl, dpm = dq[:, :2], dql[:, :2], dqm[:, :2]
    pk, pl, pm = p, q["pl"], q["pm"]
    d_ak = _cross2(dpl, pm) + _cross2(pl, dpm)
    d_al = _cross2(dpm, pk) + _cross2(pm, dpk)
    d_am = _cross2(dpk, pl) + _cross2(pk, dpl)
    tot, flat, on_l, on_m = q["tot"], q["flat"], q["on_l"], q["on_m"]
    d_tot = jnp.where(flat, 0.0, d_ak + d_al + d_am)     # tot is 1 where flat
    rk, other = q["rk"], q["other"]
    d_other = jnp.where(on_l, dqm[:, 2], dql[:, 2])
    d_share = (d_other * rk - other * d_r) / (rk + other) ** 2
    d_bk = jnp.where(flat, d_share, (d_ak - q["bk"] * d_tot) / tot)
    d_bl = jnp.where(on_l, 0.0, jnp.where(on_m, -d_share, (d_al - q["bl"] * d_tot) / tot))
    d_bm = jnp.where(on_m, 0.0, jnp.where(on_l, -d_share, (d_am - q["bm"] * d_tot) / tot))
    d_lam = jax.ops.segment_sum(jnp.concatenate([d_bk, d_bl, d_bm]), q["idx"],
                                num_segments=lam.shape[0])
    return lam, d_lam / q["degree"]


def loop_bound(d: int) -> int:
    """A loop bound ``>= d`` (at least 8) rounded up to a power of two, so that meshes and
    point sets of similar degrees share compiled code (``max_degree`` of
    :func:`shape_preserving_weights`)."""
    return 1 << max(3, (d - 1).bit_length())


def is_concrete(*xs) -> bool:
    """True when none of ``xs`` is a JAX tracer (so a NumPy path may replace a traced one)."""
    return not any(isinstance(x, jax.core.Tracer) for x in xs)


def entry_weights(vertices, topology, kind: str, *, host: bool = False):
    """Unnormalized weights of one kind on the interior one-ring entries.

    **Arguments:** ``vertices: (n, 3)``, ``topology``, ``kind`` one of :data:`KINDS`;
    ``host``: with concrete vertices, compute in NumPy (:func:`host_entry_weights`: no
    tracing, no compilation; equal to the JAX kernel to about 1e-15 relative, not bitwise
    for the kinds with transcendental functions); ignored for traced vertices.
    **Returns:** ``(w, symmetric)``: ``w: (k,)`` in :func:`ring_entries` order and
    whether ``w`` is a symmetric spring weight (``w_vw = w_wv``).
    """
    kind = choose(kind, KINDS, what="weights", where="weights")
    R = ring_entries(topology)
    if R.entry.size == 0:
        raise MeshError("weights: the mesh has no interior vertices; nothing to solve for.")
    if host and is_concrete(vertices):
        return host_entry_weights(vertices, topology, kind), kind in SYMMETRIC_KINDS
    V = jnp.asarray(vertices, dtype=jnp.float64)
    w = _weights_kernel(V, topology.faces, R.wedge, R.prev_wedge, R.row, R.row_start, R.row_end,
                        R.degree, kind=kind, n_rows=R.n_rows,
                        max_degree=loop_bound(int(R.degree.max())) if kind == "shape_preserving" else 0)
    return w, kind in SYMMETRIC_KINDS


#: The last host weights computed, by (topology, kind, digest of the vertices): a report's
#: Theorem 1 check after a map reuses the map's weights (issue 17).
_HOST_MEMO: dict = {}


def host_entry_weights(vertices, topology, kind: str) -> np.ndarray:
    """:func:`entry_weights`' values in NumPy for concrete ``vertices (n, 3)``: ``(k,)``
    float64 in :func:`ring_entries` order (the twin of the JAX kernel, :mod:`jaxparam.host`).
    The last two results are kept, keyed by a digest of the vertices (a fresh copy is
    returned each time)."""
    V = np.ascontiguousarray(vertices, np.float64)
    key = (topology, kind, hashlib.blake2b(V.tobytes(), digest_size=16).digest())
    if key not in _HOST_MEMO:
        if len(_HOST_MEMO) >= 2:
            _HOST_MEMO.pop(next(iter(_HOST_MEMO)))
        _HOST_MEMO[key] = _host_entry_weights(V, topology, kind)
    return _HOST_MEMO[key].copy()


def _host_entry_weights(V: np.ndarray, topology, kind: str) -> np.ndarray:
    R = ring_entries(topology)
    angle, cot, length = _host.corner_geometry(V, topology.faces)
    if kind == "harmonic":
        wg, pw = R.wedge, R.prev_wedge
        nxt_face = wg - wg % 3 + (wg + 2) % 3
        prv_face = pw - pw % 3 + (pw + 1) % 3
        return 0.5 * (cot[nxt_face] + cot[prv_face])
    return _host.weights_from_angles(
        kind, angle[R.wedge], angle[R.prev_wedge], length[R.wedge], R.row, R.row_start,
        R.row_end, R.degree, n_rows=R.n_rows,
        max_degree=loop_bound(int(R.degree.max())) if kind == "shape_preserving" else 0)


def normalize(w, topology):
    """Divide entry weights by their row sums: ``lambda_vw = w_vw / sum_u w_vu`` (survey §5)."""
    R = ring_entries(topology)
    return _normalize(w, R.row, n_rows=R.n_rows)


@functools.partial(jax.jit, static_argnames=("n_rows",))
def _normalize(w, row, *, n_rows):
    s = jax.ops.segment_sum(w, row, num_segments=n_rows)
    return w / s[row]


def convex_weights(mesh, kind: str = "shape_preserving"):
    """The convex-combination coefficients ``lambda`` of eq. (3) for a mesh.

    **Returns:** ``(k,)`` values in :func:`ring_entries` order; each interior
    vertex's values sum to 1 (positive for every kind but ``harmonic``).

    Example::

        lam = jp.weights.convex_weights(mesh, "mean_value")
        R = jp.weights.ring_entries(mesh.topology)   # R.center, R.nbr say which entry is which
    """
    w, _ = entry_weights(mesh.vertices, mesh.topology, kind)
    return normalize(w, mesh.topology)


def edge_values_to_entries(edge_values, topology):
    """Spread per-edge values ``(e,)`` (``topology.edges`` order) onto the interior ring entries."""
    R = ring_entries(topology)
    E = topology.edges
    n = topology.n_vertices
    keys = E[:, 0] * np.int64(n) + E[:, 1]
    lo, hi = np.minimum(R.center, R.nbr), np.maximum(R.center, R.nbr)
    pos = np.searchsorted(keys, lo * np.int64(n) + hi)
    ev = jnp.asarray(edge_values, dtype=jnp.float64)
    if ev.shape != (E.shape[0],):
        raise MeshError(f"weights: edge weights must have shape ({E.shape[0]},), one per edge "
                        f"of mesh.topology.edges, got {tuple(ev.shape)}.")
    return ev[pos]


# ------------------------------------------------------------------------------------------
# Point fans (survey §8)
# ------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class FanEntries:
    """The fan entries of the free points of a neighbour graph, as flat numpy arrays.

    The counterpart of :class:`RingEntries` for unorganized points: a fan is a point's
    neighbours in anticlockwise order (a CSR row of a
    :class:`~jaxparam.points.PointGraph`), cyclic, with no faces.

    **Fields** (``k`` entries, ``n_rows`` free points): ``free (n_rows,)`` the free points in
    increasing order (row ``r`` is point ``free[r]``); ``row (k,)`` the row of each entry's
    centre; ``center``, ``nbr``, ``prev``, ``next`` ``(k,)`` point indices (the centre, the
    neighbour, and the fan neighbours before and after it, cyclically); ``row_start (k,)``,
    ``row_end (k,)`` the entry range of the row; ``degree (n_rows,)``; ``n_rows``.
    """

    free: np.ndarray
    row: np.ndarray
    center: np.ndarray
    nbr: np.ndarray
    prev: np.ndarray
    next: np.ndarray
    row_start: np.ndarray
    row_end: np.ndarray
    degree: np.ndarray
    n_rows: int


def fan_entries(indptr: np.ndarray, indices: np.ndarray, fixed: np.ndarray) -> FanEntries:
    """The entries of the fans ``(indptr (N+1,), indices)`` (CSR rows in fan order, at least
    two entries each) whose centre is not ``fixed (N,) bool``."""
    N = indptr.size - 1
    free = np.flatnonzero(~fixed)
    slot = np.full(N, -1, np.int64)
    slot[free] = np.arange(free.size)
    rows_all = np.repeat(np.arange(N), np.diff(indptr))
    ent = np.flatnonzero(~fixed[rows_all])
    center = rows_all[ent]
    # The entry after / before each one in its (cyclic) fan: the next / previous entry, but
    # the first / last of the row at its ends.
    nxt_all = np.arange(1, indices.size + 1)
    nxt_all[indptr[1:] - 1] = indptr[:-1]
    prv_all = np.arange(-1, indices.size - 1)
    prv_all[indptr[:-1]] = indptr[1:] - 1
    row = slot[center]
    degree = np.bincount(row, minlength=free.size)
    starts = np.zeros(free.size + 1, np.int64)
    np.cumsum(degree, out=starts[1:])
    return FanEntries(free=free, row=row, center=center, nbr=indices[ent],
                      prev=indices[prv_all[ent]], next=indices[nxt_all[ent]],
                      row_start=starts[row], row_end=starts[row + 1], degree=degree,
                      n_rows=int(free.size))


def fan_weights(points, entries: FanEntries, kind: str):
    """Unnormalized weights of one of :data:`FAN_KINDS` on fan entries, from 3D angles and
    lengths (differentiable in ``points (N, 3)``, which may be traced).

    **Returns:** ``(k,)`` in ``entries`` order (rows need not sum to 1).

    **Kinks.**  The angle between neighbour directions is the *unsigned* 3D angle
    ``arctan2(|d_j x d_{j+1}|, d_j . d_{j+1})`` (a point fan has no face normal to sign
    it): it is ``|signed angle|`` near 0 and ``pi - |.|`` near ``pi``, so ``mean_value`` and
    ``shape_preserving`` are not differentiable where two consecutive neighbours are
    collinear with the centre (same ray: angle 0; opposite rays: ``pi``).  There JAX takes
    ``d|x|/dx = 0`` (the norm of the cross product has a zero gradient at 0), so the angle's
    derivative is the mean of its one-sided ones, 0.  What each kind does at such a fan is
    in :func:`weights_from_angles` and :func:`shape_preserving_weights`.
    """
    if kind not in FAN_KINDS:
        raise MeshError(f"weights: unknown fan weights {kind!r}; use one of {FAN_KINDS}.")
    E = entries
    # A fan's entries are contiguous and in fan order, so the next (previous) neighbour of
    # entry e is entry e + 1 (e - 1), cyclically within its row.
    e = np.arange(E.row.size)
    nxt = np.where(e + 1 < E.row_end, e + 1, E.row_start)
    prv = np.where(e > E.row_start, e - 1, E.row_end - 1)
    P = points if isinstance(points, jax.core.Tracer) else jnp.asarray(points, dtype=jnp.float64)
    return _fan_kernel(P, E.center, E.nbr, nxt, prv, E.row, E.row_start, E.row_end, E.degree,
                       kind=kind, n_rows=E.n_rows,
                       max_degree=loop_bound(int(E.degree.max())) if kind == "shape_preserving" else 0)


@functools.partial(jax.jit, static_argnames=("kind", "n_rows", "max_degree"))
def _fan_kernel(P, center, nbr, nxt, prv, row, row_start, row_end, degree, *, kind, n_rows,
                max_degree):
    # Each direction d_j = w_j - v is gathered once and each fan angle computed once (entry j's
    # previous angle is entry j-1's): the reverse pass scatters two 3-vectors per entry into
    # (N, 3) instead of four (issue 12: the meshless mean-value gradient 157 -> 78 ms on
    # camelhead).  Centres are sorted (rows are contiguous), which their scatter is told.
    d = P[nbr] - P.at[center].get(indices_are_sorted=True)
    if kind == "mean_value":
        half, length = _fan_half_tangents(d, nxt)
        return (half.at[prv].get(unique_indices=True) + half) / length
    angle, length = _fan_angles(d, nxt)
    return weights_from_angles(kind, angle, angle.at[prv].get(unique_indices=True), length,
                               row, row_start, row_end, degree, n_rows=n_rows,
                               max_degree=max_degree)


def _fan_angles(d, nxt):
    """``(angle, length)``, ``(k,)`` each: the unsigned angle ``ang(d_j, d_nxt(j))`` and
    ``|d_j|`` of the fan directions ``d (k, 3)`` (a ``jax.custom_jvp``, made on first use)."""
    return _with_jvp(_fan_angles_primal, _fan_angles_jvp)(d, nxt)


def _fan_angles_primal(d, nxt):
    b = d.at[nxt].get(unique_indices=True)
    return jnp.arctan2(safe_norm(jnp.cross(d, b)), geo_dot(d, b)), safe_norm(d)


def _fan_angles_jvp(primals, tangents):
    # With u = d_j, v = d_nxt(j), c = u x v, s = |c|, n = c / s, t = u.v, theta = atan2(s, t):
    # d theta = g.du + h.dv, g = (t v x n - s v) / (s^2 + t^2), h = (t n x u - s u) / (s^2 + t^2),
    # and d|u| = u.du / |u|.  No cross product or norm is differentiated, so the reverse pass is
    # a few fused loops and the one scatter of dv (issue 12: the fan weights' gradient about 2x
    # faster on camelhead).  At s = 0 (two neighbours collinear with the centre, the kink of
    # fan_weights) n = 0, so g = h = 0: the mean of the one-sided derivatives, as JAX's
    # derivative of safe_norm gives.
    d, nxt = primals
    dd = tangents[0]
    b = d.at[nxt].get(unique_indices=True)
    c = jnp.cross(d, b)
    s, t, r = safe_norm(c), geo_dot(d, b), safe_norm(d)
    has_s, has_r = s > 0, r > 0
    n = c * jnp.where(has_s, 1.0 / jnp.where(has_s, s, 1.0), 0.0)[:, None]
    inv_q = 1.0 / (s * s + t * t)
    g = (t[:, None] * jnp.cross(b, n) - s[:, None] * b) * inv_q[:, None]
    h = (t[:, None] * jnp.cross(n, d) - s[:, None] * d) * inv_q[:, None]
    # The tangent's contractions are reductions, not geo_dot's written-out sums: reverse mode
    # transposes a reduction into one broadcast product, a written-out sum into a zero-padded
    # copy per coordinate and their sum (issue 12, session 11: the fan weights' gradient on
    # camelhead, one core, inverse distance 5.97 -> 1.71 ms, mean value 16.7 -> 15.1 ms,
    # shape-preserving 31.6 -> 25.2 ms).
    d_angle = jnp.sum(g * dd, -1) + jnp.sum(h * dd.at[nxt].get(unique_indices=True), -1)
    d_length = jnp.where(has_r, jnp.sum(d * dd, -1) / jnp.where(has_r, r, 1.0), 0.0)
    return (jnp.arctan2(s, t), r), (d_angle, d_length)
