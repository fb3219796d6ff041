"""Property tests on random disk meshes: Theorem 1 and determinism."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial import Delaunay

import jaxparam as jp

N_INNER, N_RIM = 60, 24   # fixed sizes: every example reuses the compiled kernels


def random_disk(seed: int, amp: float, freq: float) -> jp.TriMesh:
    rng = np.random.default_rng(seed)
    r = np.sqrt(rng.uniform(0, 0.9 ** 2, N_INNER))
    t = rng.uniform(0, 2 * np.pi, N_INNER)
    rim = np.sort(rng.uniform(0, 2 * np.pi, N_RIM))
    P = np.vstack([np.column_stack([r * np.cos(t), r * np.sin(t)]),
                   np.column_stack([np.cos(rim), np.sin(rim)])])
    F = Delaunay(P).simplices
    a, b = P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]]
    F[a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] < 0] = F[a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] < 0][:, [0, 2, 1]]
    area = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    F = F[area > 1e-9]
    z = amp * np.sin(freq * P[:, 0] + seed) * np.cos(freq * P[:, 1])
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    return jp.TriMesh(np.column_stack([P, z]) @ Q.T, F)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10_000), amp=st.floats(0, 0.8), freq=st.floats(0.5, 4.0),
       kind=st.sampled_from(["uniform", "inverse_distance", "shape_preserving", "mean_value"]),
       boundary=st.sampled_from(["circle", "square"]))
def test_theorem1_positive_weights_convex_boundary_no_flips(seed, amp, freq, kind, boundary):
    mesh = random_disk(seed, amp, freq)
    if not mesh.topology.is_disk:
        return
    uv = jp.convex_map(mesh, weights=kind, boundary=boundary)
    rep = jp.distortion(mesh, uv, weights=kind)
    assert rep.theorem1.positive_weights and rep.theorem1.convex_boundary
    if rep.theorem1.holds:
        assert rep.flips == 0
    if boundary == "circle":
        assert rep.theorem1.holds and rep.flips == 0


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10_000), kind=st.sampled_from(["shape_preserving", "harmonic"]))
def test_same_input_same_output(seed, kind):
    mesh = random_disk(seed, 0.4, 2.0)
    a = np.asarray(jp.convex_map(mesh, weights=kind))
    b = np.asarray(jp.convex_map(jp.TriMesh(np.asarray(mesh.vertices).copy(), mesh.faces.copy()), weights=kind))
    np.testing.assert_array_equal(a, b)
