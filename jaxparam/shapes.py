"""Meshes the project generates: the survey's examples, spheres and tori.

All are deterministic (a ``seed`` only where randomness is asked for) and
come back as :class:`~jaxparam.mesh.TriMesh` with counter-clockwise faces.
"""
from __future__ import annotations

import numpy as np

from .mesh import TriMesh, grid_faces
from .subdivision import midpoint_refine

__all__ = ["grid_faces", "plane_grid", "graph_surface", "cylinder_patch", "example5",
           "disk", "sphere", "torus", "revolution", "helical_tube", "refine"]


def _grid_uv(nu: int, nv: int, jitter: float = 0.0, seed: int = 0) -> np.ndarray:
    u, v = np.meshgrid(np.linspace(0, 1, nu), np.linspace(0, 1, nv), indexing="ij")
    uv = np.stack([u.ravel(), v.ravel()], 1)
    if jitter:
        rng = np.random.default_rng(seed)
        inner = (uv > 0).all(1) & (uv < 1).all(1)
        h = 1.0 / (max(nu, nv) - 1)
        uv[inner] += rng.uniform(-jitter, jitter, (inner.sum(), 2)) * h
    return uv


def plane_grid(nu: int = 10, nv: int = 10, *, jitter: float = 0.0, seed: int = 0,
               tilt: bool = False) -> TriMesh:
    """A planar grid over ``[0, 1]^2`` (optionally jittered, optionally tilted into 3D)."""
    uv = _grid_uv(nu, nv, jitter, seed)
    V = np.column_stack([uv, np.zeros(len(uv))])
    if tilt:
        c, s = np.cos(0.7), np.sin(0.7)
        V = V @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]]) @ np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])
    return TriMesh(V, grid_faces(nu, nv), name="plane_grid")


def graph_surface(n: int = 20, *, jitter: float = 0.0, seed: int = 0) -> TriMesh:
    """The graph of ``z = 0.4 sin(2 pi x) cos(2 pi y) + 0.3 x^2`` over ``[0, 1]^2`` (survey Fig. 5 style)."""
    uv = _grid_uv(n, n, jitter, seed)
    x, y = uv[:, 0], uv[:, 1]
    z = 0.4 * np.sin(2 * np.pi * x) * np.cos(2 * np.pi * y) * 0.5 + 0.3 * x ** 2
    return TriMesh(np.column_stack([x, y, z]), grid_faces(n, n), name="graph_surface")


def cylinder_patch(nu: int = 20, nv: int = 10, *, angle: float = 1.5 * np.pi) -> TriMesh:
    """A patch of the unit cylinder (survey Example 6): ``(cos u, sin u, v)``, ``u in [0, angle]``."""
    uv = _grid_uv(nu, nv)
    u, v = uv[:, 0] * angle, uv[:, 1] * 1.5
    V = np.column_stack([np.cos(u), np.sin(u), v])
    # (u, v) increasing is counter-clockwise seen from outside the cylinder.
    return TriMesh(V, grid_faces(nu, nv), name="cylinder_patch")


def example5(n: int = 20) -> TriMesh:
    """The survey's Example 5 surface ``f(u, v) = (4u^3 + 1, 3u^3 + 3v, v - 2)`` over ``[-1, 1]^2``.

    It is developable (isometric to the plane), so a good map has no distortion.
    """
    uv = _grid_uv(n, n) * 2 - 1
    u, v = uv[:, 0], uv[:, 1]
    V = np.column_stack([4 * u ** 3 + 1, 3 * u ** 3 + 3 * v, v - 2])
    return TriMesh(V, grid_faces(n, n), name="example5")


def disk(rings: int = 8, *, seed: int | None = None, height: float = 0.0) -> TriMesh:
    """A triangulated unit disk made of concentric rings (``6 r`` vertices on ring ``r``),
    optionally lifted by ``z = height * (x^2 - y^2)``; ``seed`` jitters the interior."""
    pts = [np.zeros((1, 2))]
    for r in range(1, rings + 1):
        t = 2 * np.pi * np.arange(6 * r) / (6 * r)
        pts.append(r / rings * np.column_stack([np.cos(t), np.sin(t)]))
    P = np.concatenate(pts)
    if seed is not None:
        rng = np.random.default_rng(seed)
        inner = np.linalg.norm(P, axis=1) < 1 - 1e-9
        P[inner] += rng.uniform(-0.25, 0.25, (inner.sum(), 2)) / rings
    from scipy.spatial import Delaunay
    F = Delaunay(P).simplices.astype(np.int64)
    a = P[F[:, 1]] - P[F[:, 0]]
    b = P[F[:, 2]] - P[F[:, 0]]
    neg = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] < 0
    F[neg] = F[neg][:, [0, 2, 1]]
    V = np.column_stack([P, height * (P[:, 0] ** 2 - P[:, 1] ** 2)])
    return TriMesh(V, F, name="disk")


def sphere(subdivisions: int = 2) -> TriMesh:
    """An icosphere of radius 1 (closed, genus 0)."""
    t = (1 + 5 ** 0.5) / 2
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    for _ in range(subdivisions):
        V, F = _split(V, F)
    V = V / np.linalg.norm(V, axis=1, keepdims=True)
    return TriMesh(V, F, name="sphere")


def torus(nu: int = 24, nv: int = 12, *, R: float = 1.0, r: float = 0.35) -> TriMesh:
    """A closed torus of genus 1."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    u, v = 2 * np.pi * i.ravel() / nu, 2 * np.pi * j.ravel() / nv
    V = np.column_stack([(R + r * np.cos(v)) * np.cos(u), (R + r * np.cos(v)) * np.sin(u), r * np.sin(v)])
    a = (i * nv + j).ravel()
    b = (((i + 1) % nu) * nv + j).ravel()
    c = (((i + 1) % nu) * nv + (j + 1) % nv).ravel()
    d = (i * nv + (j + 1) % nv).ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return TriMesh(V, F, name="torus")


def helical_tube(turns: float = 3.0, along: int = 300, around: int = 16, *, r: float = 0.08) -> TriMesh:
    """An open tube of radius ``r`` along ``turns`` turns of a helix (radius 1, rising 0.15 per
    radian): ``along`` rings of ``around`` vertices, two boundary loops (the ends).  Its side
    strips wind past a full turn, so a chart of them flattens into a spiral that crosses itself
    (the atlas's hard case for long, curved charts)."""
    t = np.linspace(0, 2 * np.pi * turns, along)
    path = np.stack([np.cos(t), np.sin(t), 0.15 * t], 1)
    T = np.gradient(path, axis=0)
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    N = np.cross(T, [0.0, 0.0, 1.0])
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    B = np.cross(T, N)
    th = np.linspace(0, 2 * np.pi, around, endpoint=False)
    V = (path[:, None] + r * (np.cos(th)[None, :, None] * N[:, None]
                              + np.sin(th)[None, :, None] * B[:, None])).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(along - 1), np.arange(around), indexing="ij")
    a0, a1 = i * around + j, i * around + (j + 1) % around
    F = np.concatenate([np.stack([a0, a1, a0 + around], -1).reshape(-1, 3),
                        np.stack([a1, a1 + around, a0 + around], -1).reshape(-1, 3)])
    return TriMesh(V, F, name="helical_tube")


def revolution(around: int = 64, along: int = 8, *, height: float = 10.0) -> TriMesh:
    """An open tube of revolution (radius ``1 + 0.3 sin z``, ``0 <= z <= height``) cut into
    ``along`` rings of ``around`` quads, two triangles each: the slivers of a CAD export when
    ``around`` is large and ``along`` small (aspect about ``height around / (2 pi along)``).
    Two boundary loops (the ends); vertices ring by ring."""
    t = np.linspace(0, 2 * np.pi, around, endpoint=False)
    z = np.linspace(0, height, along + 1)
    r = 1 + 0.3 * np.sin(z)
    V = np.stack([np.outer(r, np.cos(t)), np.outer(r, np.sin(t)), np.repeat(z[:, None], around, 1)], -1)
    i = np.arange(around)
    a = (np.arange(along)[:, None] * around + i).ravel()
    b = (np.arange(along)[:, None] * around + (i + 1) % around).ravel()
    F = np.concatenate([np.stack([a, b, b + around], 1), np.stack([a, b + around, a + around], 1)])
    return TriMesh(V.reshape(-1, 3), F, name="revolution")


def _split(V: np.ndarray, F: np.ndarray):
    """One 1-to-4 midpoint split (:func:`jaxparam.subdivision.midpoint_refine`); new vertices
    follow the old ones.  The faces keep this module's own order, child by child (the corner
    children of ``a``, ``b``, ``c``, then the middle ones, each block over all faces, rotated
    to start at ``a``, ``b``, ``c``, ``ab``), so the generated meshes stay as they always were."""
    V1, F1 = midpoint_refine(V, F)
    C = F1.reshape(-1, 4, 3)                        # (a, ab, ca), (ab, b, bc), (ca, bc, c), (bc, ca, ab)
    return V1, np.concatenate([C[:, 0], C[:, 1][:, [1, 2, 0]], C[:, 2][:, [2, 0, 1]],
                               C[:, 3][:, [2, 0, 1]]])


def refine(mesh: TriMesh, times: int = 1) -> TriMesh:
    """Split every face 1-to-4 ``times`` times (new vertices at edge midpoints)."""
    V, F = np.asarray(mesh.vertices), mesh.faces
    for _ in range(times):
        V, F = _split(V, F)
    return TriMesh(V, F, validate=False, name=(mesh.name or "mesh") + f"_x{4 ** times}")
