"""camelhead.xyz reconstructed and scored against camelhead.off, and how far any local rule
could go towards recovering that mesh's edges.

The points are the vertices of camelhead.off (shuffled); each point is matched to its vertex
by a nearest-neighbour query.  Printed:

* the reconstruction with default options: seconds, points used, disk, flips, boundary
  precision / recall, distance of points sampled on the new faces to camelhead.off (max and
  RMS, % of the bounding-box diagonal; needs libigl), share of camelhead.off's edges recovered;
* the source mesh against local rules: for each interior edge of camelhead.off, whether each
  of six standard rules (3D Delaunay, shorter diagonal, smaller dihedral angle, max-min angle,
  min-max angle, smaller area) prefers it to the other diagonal of its quad, and the share of
  edges that every rule rejects;
* the source mesh flipped towards 3D Delaunay (inside its own harmonic map, as the
  reconstruction flips): share of its edges kept;
* the share of interior vertices of valence 6, source and reconstruction.

Usage::

    python benchmarks/camelhead_points.py [--samples 8]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from jaxparam.topology import half_edge_twins

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data"


def edge_set(F: np.ndarray) -> set:
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    return set(map(tuple, np.unique(E, axis=0).tolist()))


def interior_quads(F: np.ndarray) -> np.ndarray:
    """``(q, 4)`` rows ``(a, b, c, d)``: interior edge ``a-b`` with faces ``(a, b, c)`` and
    ``(b, a, d)``."""
    twin = half_edge_twins(F, int(F.max()) + 1)
    h = np.flatnonzero(twin > np.arange(twin.size))
    nxt = lambda x: x - x % 3 + (x + 1) % 3          # noqa: E731
    prv = lambda x: x - x % 3 + (x + 2) % 3          # noqa: E731
    Ff = F.reshape(-1)
    return np.stack([Ff[h], Ff[nxt(h)], Ff[prv(h)], Ff[prv(twin[h])]], axis=1)


def local_rules(V: np.ndarray, Q: np.ndarray) -> dict:
    """For each quad, whether each rule prefers the existing diagonal ``a-b`` to ``c-d``."""
    a, b, c, d = Q.T

    def ang(p, q, r):
        u, v = V[q] - V[p], V[r] - V[p]
        return np.arctan2(np.linalg.norm(np.cross(u, v), axis=1), np.sum(u * v, 1))

    def unit_normal(p, q, r):
        n = np.cross(V[q] - V[p], V[r] - V[p])
        return n / np.linalg.norm(n, axis=1)[:, None]

    def area(p, q, r):
        return 0.5 * np.linalg.norm(np.cross(V[q] - V[p], V[r] - V[p]), axis=1)

    def corner_angles(p, q, r):
        return np.stack([ang(p, q, r), ang(q, r, p), ang(r, p, q)], 1)

    now = (corner_angles(a, b, c), corner_angles(b, a, d))
    alt = (corner_angles(a, d, c), corner_angles(d, b, c))
    dihedral = lambda n1, n2: np.arccos(np.clip(np.sum(n1 * n2, 1), -1, 1))   # noqa: E731
    L = lambda x, y: np.linalg.norm(V[x] - V[y], axis=1)                        # noqa: E731
    return {
        "3D Delaunay": ang(c, a, b) + ang(d, a, b) < ang(a, c, d) + ang(b, c, d),
        "shorter diagonal": L(a, b) < L(c, d),
        "smaller dihedral": dihedral(unit_normal(a, b, c), unit_normal(b, a, d))
        < dihedral(unit_normal(a, d, c), unit_normal(d, b, c)),
        "max-min angle": np.minimum(now[0].min(1), now[1].min(1)) > np.minimum(alt[0].min(1), alt[1].min(1)),
        "min-max angle": np.maximum(now[0].max(1), now[1].max(1)) < np.maximum(alt[0].max(1), alt[1].max(1)),
        "smaller area": area(a, b, c) + area(b, a, d) < area(a, d, c) + area(d, b, c),
    }


def valence6_share(F: np.ndarray, n: int) -> float:
    import jaxparam as jp

    t = jp.TriMesh(np.zeros((n, 3)), F, validate=False).topology
    deg = np.bincount(F.ravel(), minlength=n)          # faces per vertex = valence inside
    inside = np.ones(n, bool)
    inside[t.boundary] = False
    inside &= deg > 0
    return float(np.mean(deg[inside] == 6))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--samples", type=int, default=8, help="random samples per face (plus the centroid)")
    args = ap.parse_args()
    import jaxparam as jp
    from jaxparam.points.triangulation import flip_towards_3d_delaunay

    P = jp.load_points(DATA / "points" / "camelhead.xyz")
    src = jp.load(DATA / "meshes" / "camelhead.off")
    V, SF = np.asarray(src.vertices), np.asarray(src.faces)
    _, point_of = cKDTree(P).query(V)                  # source vertex -> point index
    SFp = point_of[SF]
    source_edges = edge_set(SFp)

    rec = jp.reconstruct_surface(P)                    # compiles
    t = time.perf_counter()
    rec = jp.reconstruct_surface(P)
    seconds = time.perf_counter() - t
    F = np.asarray(rec.mesh.faces)
    print(f"reconstruction: {seconds:.2f} s, {len(F)} faces, points used "
          f"{rec.points_used.size / len(P):.4f}, disk {rec.mesh.topology.is_disk}, "
          f"flips {jp.metrics.flips(rec.mesh, rec.uv)}")
    true_b = set(point_of[src.topology.boundary].tolist())
    found = set(rec.boundary.tolist())
    print(f"boundary detection: precision {len(found & true_b) / len(found):.2f}, "
          f"recall {len(found & true_b) / len(true_b):.2f}")
    try:
        import igl
    except ImportError:
        igl = None
    if igl is not None:
        rng = np.random.default_rng(0)
        X = P[F]
        bary = rng.dirichlet(np.ones(3), size=(len(F), args.samples))
        S = np.concatenate([np.einsum("fsk,fkd->fsd", bary, X).reshape(-1, 3), X.mean(1)])
        d = np.sqrt(igl.point_mesh_squared_distance(S, V, SF)[0])
        diag = np.linalg.norm(np.ptp(V, axis=0))
        print(f"distance of face samples to camelhead.off: max {100 * d.max() / diag:.3f} %, "
              f"RMS {100 * np.sqrt(np.mean(d ** 2)) / diag:.3f} % of the diagonal")
    else:
        print("distance: needs libigl (pip install libigl)")
    print(f"edges of camelhead.off recovered: {100 * len(edge_set(F) & source_edges) / len(source_edges):.1f} %")

    Q = interior_quads(SF)
    rules = local_rules(V, Q)
    print(f"\ncamelhead.off, {len(Q)} interior edges: share each local rule keeps")
    for name, keep in rules.items():
        print(f"  {name:18s} {100 * keep.mean():5.1f} %")
    none = ~np.any(np.stack(list(rules.values())), axis=0)
    print(f"  rejected by all six: {100 * none.mean():.1f} % of the interior edges")
    U = np.asarray(jp.convex_map(src, weights="harmonic"))
    flipped = flip_towards_3d_delaunay(SF, V, U, 1000)
    kept = edge_set(flipped) & edge_set(SF)
    print(f"camelhead.off flipped towards 3D Delaunay in its harmonic map keeps "
          f"{100 * len(kept) / len(edge_set(SF)):.1f} % of its edges")
    print(f"interior vertices of valence 6: camelhead.off {100 * valence6_share(SF, len(V)):.1f} %, "
          f"reconstruction {100 * valence6_share(F, len(P)):.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
