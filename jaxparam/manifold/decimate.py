"""Step 1 of :mod:`jaxparam.manifold`: the base domain ``T^0`` by quadric-error half-edge collapses.

A collapse ``u -> w`` keeps the surviving vertex where it is, so ``V^0 ⊂ V``; the link
condition keeps the genus, collapses that would turn a face over (or, while possible, leave
a base triangle with an angle over 140 degrees) are refused.  A Python loop over collapses
with a heap of costs; per-vertex quadrics are numpy.
"""
from __future__ import annotations

import heapq

import numpy as np

from ..errors import SolverError
from ..mesh import TriMesh

__all__ = ["decimate", "plane_quadrics"]


def plane_quadrics(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)``: the sum over each vertex's faces of the area-weighted plane quadrics."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    area2 = np.linalg.norm(n, axis=1)
    unit = n / np.maximum(area2, 1e-300)[:, None]
    p = np.concatenate([unit, -np.sum(unit * V[F[:, 0]], 1, keepdims=True)], axis=1)
    K = 0.5 * area2[:, None, None] * p[:, :, None] * p[:, None, :]
    Q = np.zeros((V.shape[0], 4, 4))
    for c in range(3):
        np.add.at(Q, F[:, c], K)
    return Q


def decimate(mesh: TriMesh, base_faces: int):
    """Quadric-error half-edge collapses down to ``base_faces`` faces (step 1).

    **Arguments:** ``mesh`` a closed manifold mesh; ``base_faces`` the faces wanted (even;
    at least the fewest a surface of the mesh's genus needs).

    **Returns:** ``(kept (n0,) int, faces (base_faces, 3) int)``: the surviving vertices
    (indices into ``mesh``'s vertices, increasing) and the base faces over them (indices
    into ``kept``), oriented as the mesh.
    """
    t = mesh.topology
    V = np.asarray(mesh.vertices, np.float64)
    V = V - 0.5 * (V.min(0) + V.max(0))        # quadrics far from the origin cancel (maps.py)
    F = np.array(t.faces, np.int64)
    n, m = V.shape[0], F.shape[0]
    scale = float(np.linalg.norm(np.ptp(V, axis=0)))
    Q = plane_quadrics(V, F)
    vf = [set() for _ in range(n)]
    for f, (a, b, c) in enumerate(F.tolist()):
        vf[a].add(f)
        vf[b].add(f)
        vf[c].add(f)
    dead = np.zeros(n, bool)
    version = np.zeros(n, np.int64)
    heap: list = []
    Vh = np.concatenate([V, np.ones((n, 1))], axis=1)

    def nbrs(v):
        out = set()
        for f in vf[v]:
            out.update(F[f].tolist())
        out.discard(v)
        return out

    def cost(u, w):
        x = Vh[w]
        return max(0.0, float(x @ (Q[u] + Q[w]) @ x))      # >= 0 but for rounding

    def push(u):
        version[u] += 1
        for w in nbrs(u):
            heapq.heappush(heap, (cost(u, w), int(version[u]), u, w))

    def valid(u, w) -> bool:
        Nu, Nw = nbrs(u), nbrs(w)
        common = Nu & Nw
        shared = vf[u] & vf[w]
        if len(common) != 2 or len(shared) != 2:            # link condition (closed manifold)
            return False
        if len(Nu | Nw) - 2 < 3 or any(len(nbrs(x)) - 1 < 3 for x in common):
            return False
        for f in vf[u] - shared:
            a, b, c = F[f]
            P = V[[a, b, c]]
            old = np.cross(P[1] - P[0], P[2] - P[0])
            P[[a, b, c].index(u)] = V[w]
            new = np.cross(P[1] - P[0], P[2] - P[0])
            ln = np.linalg.norm(new)
            if ln <= 1e-12 * scale * scale or old @ new <= 0.2 * np.linalg.norm(old) * ln:
                return False
            if strict:
                # No base triangle with an angle over 140 degrees: a base vertex almost on
                # the segment between two others leaves no room for the surface edges.
                e = P[[1, 2, 0]] - P
                cosines = -np.sum(e * e[[2, 0, 1]], 1) / (np.linalg.norm(e, axis=1)
                                                          * np.linalg.norm(e[[2, 0, 1]], axis=1))
                if cosines.min() < np.cos(np.radians(140)):
                    return False
        return True

    for v in range(n):
        push(v)
    faces_left = m
    strict = True
    while faces_left > base_faces:
        if not heap:
            if not strict:
                break
            strict = False                 # stuck on the shape rule: finish without it
            for v in np.flatnonzero(~dead):
                push(int(v))
            continue
        c, ver, u, w = heapq.heappop(heap)
        if dead[u] or dead[w] or ver != version[u] or not (vf[u] & vf[w]):
            continue
        c2 = cost(u, w)
        if c2 > c + 1e-9 * abs(c) + 1e-300:                # stale: its quadrics grew
            heapq.heappush(heap, (c2, ver, u, w))
            continue
        if not valid(u, w):
            continue
        shared = vf[u] & vf[w]
        for f in shared:
            for x in F[f].tolist():
                vf[x].discard(f)
        for f in list(vf[u]):
            F[f][F[f] == u] = w
            vf[w].add(f)
        vf[u].clear()
        dead[u] = True
        Q[w] += Q[u]
        faces_left -= 2
        touched = nbrs(w) | {w}
        for x in touched:
            push(x)
    if faces_left > base_faces:
        raise SolverError(f"manifold_map: decimation stopped at {faces_left} faces (no collapse "
                          f"keeps the topology and the faces' orientation); ask for more than "
                          f"{faces_left} base faces.", stage="decimate")
    alive = sorted(set().union(*[vf[v] for v in range(n) if not dead[v]]))
    Fb = F[alive]
    kept = np.flatnonzero(~dead)
    return kept, np.searchsorted(kept, Fb)
