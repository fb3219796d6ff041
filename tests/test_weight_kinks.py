"""Where the fan weights are not differentiable, and what JAX returns there (issue 12, item 6).

The point-fan weights (:func:`jaxparam.weights.fan_weights`, used by ``jp.meshless_map``) take
the *unsigned* 3D angle ``arctan2(|d_j x d_{j+1}|, d_j . d_{j+1})`` between consecutive
neighbour directions; it is ``|signed angle|`` near 0 and ``pi - |.|`` near pi, so it kinks
where two consecutive neighbours are collinear with the centre.  Floater's shape-preserving
weights are moreover piecewise by construction: which polar-map triangle holds the centre
changes where the ray opposite one neighbour passes through another.

Each test moves one neighbour of a small hand-built fan by ``t`` perpendicular to the line
through the centre, and compares the one-sided differences ``(w(h) - w(0)) / h``,
``(w(0) - w(-h)) / h`` with JAX's derivative at ``t = 0`` (``jax.jvp``): the two sides
differ (the kink is real), and JAX's value is finite and is the one stated.
"""
import jax
import jax.numpy as jnp
import numpy as np

import jaxparam as jp  # noqa: F401  (float64)
from jaxparam import weights as W

H = 1e-6


def fan(nbrs):
    """Point 0 at the origin with the neighbours ``nbrs`` (anticlockwise) as its fan; the
    neighbours are fixed (their own rows are placeholders, skipped by fan_entries)."""
    n = len(nbrs)
    P = np.vstack([np.zeros(3), np.asarray(nbrs, float)])
    rows = [list(range(1, n + 1))] + [[0, 2 if i == 1 else 1] for i in range(1, n + 1)]
    indptr = np.concatenate([[0], np.cumsum([len(r) for r in rows])])
    fixed = np.ones(n + 1, bool)
    fixed[0] = False
    return P, W.fan_entries(indptr, np.concatenate(rows), fixed)


def sides(nbrs, moved, direction, kind, h=H):
    """``(w(0), right, left, jax)`` of the fan weights of centre 0, as neighbour ``moved``
    (a point index) moves by ``t * direction``."""
    P0, E = fan(nbrs)
    D = np.zeros_like(P0)
    D[moved] = direction
    w = lambda t: W.fan_weights(jnp.asarray(P0) + t * D, E, kind)  # noqa: E731
    w0 = np.asarray(w(0.0))
    right = (np.asarray(w(h)) - w0) / h
    left = (w0 - np.asarray(w(-h))) / h
    _, jv = jax.jvp(w, (0.0,), (1.0,))
    return w0, right, left, np.asarray(jv)


# Neighbours 1 and 2 on the same ray from the centre: the angle between them is 0.
SAME_RAY = [[1, 0, 0], [2, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]]
# A planar fan whose neighbour 3 lies exactly opposite neighbour 1 (all angles pi/2, so the
# polar angles 0, pi/2, pi, 3pi/2 are exact in floating point).
OPPOSITE = [[1, 0, 0], [0, 1, 0], [-1.5, 0, 0], [0, -1, 0]]


def test_mean_value_kink_at_a_zero_angle_jax_returns_the_mean():
    # Moving neighbour 2 off the ray by t: delta_0 = |t| / 2 + O(t^2), a V; tan(delta/2) keeps it.
    _, right, left, jv = sides(SAME_RAY, 2, [0, 1, 0], "mean_value")
    assert np.all(np.isfinite(jv))
    assert np.abs(right - left).max() > 0.1                     # the kink is real
    # The entries of neighbours 1 and 2 (the two that share the angle) kink; JAX returns the
    # mean of the two sides: d|x|/dx = 0 at 0 through safe_norm of the cross product.
    assert np.abs(right[:2] - left[:2]).min() > 0.1
    np.testing.assert_allclose(jv, 0.5 * (right + left), atol=1e-5)
    np.testing.assert_allclose(jv[:2], [0.0, -0.25], atol=1e-5)


def test_unsigned_angle_kink_jax_returns_zero():
    # The angle itself, through the mean-value weight of neighbour 1 minus its smooth part: the
    # angle 0 kink is |t| / 2, whose JAX derivative is 0 (the mean of -1/2 and +1/2).
    P0, E = fan(SAME_RAY)
    D = np.zeros_like(P0)
    D[2] = [0, 1, 0]
    # Entry 0 (neighbour 1) uses delta_{-1} (fixed, pi/2) and delta_0 = ang(d_1, d_2).
    delta0 = lambda t: 2 * jnp.arctan(                           # noqa: E731
        W.fan_weights(jnp.asarray(P0) + t * D, E, "mean_value")[0] * 1.0 - 1.0)
    right = (float(delta0(H)) - float(delta0(0.0))) / H
    left = (float(delta0(0.0)) - float(delta0(-H))) / H
    d = float(jax.grad(delta0)(0.0))
    np.testing.assert_allclose([right, left], [0.5, -0.5], atol=1e-5)
    assert np.isfinite(d) and d == 0.0


def test_mean_value_pole_at_a_straight_angle():
    # Not a kink but a pole: the centre on the segment between neighbours 1 and 2 (angle pi)
    # makes tan(delta/2) = tan(pi/2), about 1.6e16 in floating point; JAX's derivative there
    # is finite (the |cross| in the angle has a zero derivative at 0).
    w0, right, left, jv = sides([[1, 0, 0], [-1, 0, 0], [0, -1, 0]], 2, [0, 1, 0], "mean_value")
    assert w0[:2].min() > 1e15
    assert np.all(np.isfinite(jv))
    assert right[0] * left[0] < 0 and abs(right[0]) > 1e20     # +-inf slopes on the two sides


def test_shape_preserving_kink_at_an_opposite_pair_jax_returns_the_mean():
    # Neighbour 3 moved by t: for t > 0 the ray opposite neighbour 1 crosses [p_3, p_4], for
    # t < 0 it crosses [p_2, p_3] (and the ray opposite neighbour 3 the other way round).  At
    # t = 0 the search picks [p_3, p_4] for k = 1 (the t > 0 side) and [p_1, p_2] for k = 3
    # (the t < 0 side): the same two triangles, one each, so JAX returns the mean of the sides.
    w0, right, left, jv = sides(OPPOSITE, 3, [0, 1, 0], "shape_preserving")
    np.testing.assert_allclose(w0, [0.3, 0.25, 0.2, 0.25], atol=1e-12)
    assert np.all(np.isfinite(jv))
    assert np.abs(right - left).max() > 0.1                     # the kink is real
    np.testing.assert_allclose(jv, 0.5 * (right + left), atol=1e-5)
    np.testing.assert_allclose(jv, [0.0, -0.1, 0.0, 0.1], atol=1e-5)
    # mean-value weights of the same fan are smooth there (no angle is 0 or pi)
    _, r2, l2, j2 = sides(OPPOSITE, 3, [0, 1, 0], "mean_value")
    np.testing.assert_allclose(r2, l2, atol=1e-5)
    np.testing.assert_allclose(j2, r2, atol=1e-5)


def test_shape_preserving_jumps_at_a_zero_angle_opposite_a_neighbour():
    # Neighbours 1 and 2 on one ray and neighbour 4 opposite them: at t = 0 the ray opposite
    # p_4 passes through both p_1 and p_2 and the search picks p_2 (the later entry); for any
    # t > 0 it passes between p_5 and p_1.  The centre interpolates (p_4, p_2) at t = 0 and
    # (p_4, p_1) for t > 0: the weights jump (p_1's share in that one of the 5 averaged terms
    # goes from 0 to 1/2: +0.1).  JAX's
    # derivative is finite and is that of neither side.
    w0, right, left, jv = sides(SAME_RAY, 2, [0, 1, 0], "shape_preserving")
    jump = right * H
    assert np.abs(jump).max() > 0.05                            # a jump, not a kink
    np.testing.assert_allclose(jump[0], 0.1, atol=1e-4)
    assert np.abs(left).max() < 0.1                             # continuous from t < 0
    assert np.all(np.isfinite(jv))
    assert np.abs(jv - left).max() > 1e-3 and np.abs(jv - right).max() > 1e-3
    np.testing.assert_allclose(w0.sum(), 1.0, atol=1e-12)


def test_shape_preserving_kink_at_a_straight_angle_jax_returns_neither_side():
    # The centre on the segment between neighbours 1 and 2 (angle pi), neighbour 2 moved off
    # the line: for t > 0 the fan stays a star and the weights move, for t < 0 the unsigned
    # angle folds back (pi - |t|) and they stay put to first order.  JAX's derivative is finite
    # and neither side's (here a third of the t > 0 side's: one of the three averaged terms
    # takes that side's branch).
    w0, right, left, jv = sides([[1, 0, 0], [-1, 0, 0], [0, -1, 0]], 2, [0, 1, 0],
                                "shape_preserving")
    np.testing.assert_allclose(w0, [0.5, 0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(right, [-0.25, -0.25, 0.5], atol=1e-5)
    np.testing.assert_allclose(left, 0.0, atol=1e-5)
    assert np.all(np.isfinite(jv))
    np.testing.assert_allclose(jv, right / 3, atol=1e-5)
