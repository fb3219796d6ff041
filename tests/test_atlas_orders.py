"""The last packing's extra orders of placement (``pack.reorder``, issue 18)."""
from __future__ import annotations

import numpy as np

from jaxparam.atlas import pack


def _triangles(k: int, seed: int):
    """``k`` random triangles (counter-clockwise, seeded) as one-face charts:
    ``(uv, uv_faces, chart, uv_chart, area)``.  Ragged shapes, for which a greedy fill
    depends on its order."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(0, 1, (k, 3, 2)) * rng.uniform(0.3, 1.0, (k, 1, 1))
    d = (P[:, 1, 0] - P[:, 0, 0]) * (P[:, 2, 1] - P[:, 0, 1]) - (P[:, 2, 0] - P[:, 0, 0]) * (P[:, 1, 1] - P[:, 0, 1])
    P[d < 0] = P[d < 0][:, [0, 2, 1]]
    return (P.reshape(-1, 2), np.arange(3 * k).reshape(k, 3), np.arange(k),
            np.repeat(np.arange(k), 3), float(0.5 * np.abs(d).sum()))


def _segment_distance(a0, a1, b0, b1):
    """The distance between segments ``[a0, a1]`` and ``[b0, b1]`` (each ``(..., 2)``), 0 where they cross."""
    def point_segment(p, s0, s1):
        d = s1 - s0
        t = np.clip(np.sum((p - s0) * d, -1) / np.sum(d * d, -1), 0, 1)
        return np.linalg.norm(p - (s0 + t[..., None] * d), axis=-1)

    def side(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    cross = (side(a0, a1, b0) != side(a0, a1, b1)) & (side(b0, b1, a0) != side(b0, b1, a1))
    d = np.minimum.reduce([point_segment(a0, b0, b1), point_segment(a1, b0, b1),
                           point_segment(b0, a0, a1), point_segment(b1, a0, a1)])
    return np.where(cross, 0.0, d)


def _assert_triangles_apart(out, k: int, margin: float):
    """No packed triangle lies inside another, and their outlines keep ``margin`` (to a cell's rounding)."""
    T = out.reshape(k, 3, 2)
    E0, E1 = T, np.roll(T, -1, axis=1)                       # (k, 3, 2) edges
    i, j = np.triu_indices(k, 1)
    d = _segment_distance(E0[i][:, :, None], E1[i][:, :, None], E0[j][:, None], E1[j][:, None])
    assert d.min() >= 0.9 * margin
    # a vertex of one inside another: its distance to the other's outline alone would not say it
    def left(u, v, w):
        return (v[:, 0] - u[:, 0]) * (w[:, 1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (w[:, 0] - u[:, 0]) > 0

    c = T.mean(1)
    for a, b in ((i, j), (j, i)):
        p, q, r, x = T[b, 0], T[b, 1], T[b, 2], c[a]
        assert not np.any(left(p, q, x) & left(q, r, x) & left(r, p, x))


def test_jittered_orders_are_fixed_permutations_near_largest_first():
    masks = [np.ones((s, s), bool) for s in (3, 9, 5, 8, 2, 7)]
    orders = list(pack.jittered_orders(masks, 8))
    assert len(orders) == 8
    assert all(sorted(o) == list(range(6)) for o in orders)
    assert [list(o) for o in orders] == [list(o) for o in pack.jittered_orders(masks, 8)]
    assert any(list(o) != [1, 3, 5, 2, 0, 4] for o in orders)      # not all largest first
    # a chart at least (1 + j) / (1 - j) times another's area always goes first
    for o in orders:
        assert list(o).index(1) < list(o).index(0) and list(o).index(3) < list(o).index(4)


def test_reorder_never_covers_less_and_keeps_the_charts_apart():
    gains = []
    for seed in range(4):
        uv, uf, chart, uvc, area = _triangles(20, seed)
        plain = pack.pack_charts(uv, uf, chart, uvc, area, texture_size=128, margin_texels=2)
        more = pack.reorder(uv, uf, chart, uvc, plain, 8)
        assert more.scale >= plain.scale
        assert (more.texture_size, more.margin_texels) == (128, 2)
        gains.append(more.scale / plain.scale)
        out = more.apply(uv, uvc)
        assert out.min() >= 2 / 128 - 1e-12 and out.max() <= 1 - 2 / 128 + 1e-12
        assert np.all(np.linalg.det(more.rotation) > 0.999)
        _assert_triangles_apart(out, 20, 2 / 128)
    assert max(gains) > 1.005        # on some of these sets an order other than largest first fits more
