"""jp.atlas.atlas beside xatlas (issue 18) on the meshes of ../shared/data, plus a refined
mesh of about a million faces.

Columns, computed the same way for both tools from what they return (3D positions, UV
faces, UVs):

- charts: connected pieces of the UV faces (faces sharing a UV vertex);
- seam / sqrt(A): 3D length of the mesh edges whose two faces use different UV corners,
  over the square root of the 3D area;
- E_sd: area-weighted symmetric Dirichlet ``(s1^2 + s2^2 + s1^-2 + s2^-2) / 2`` with the UVs
  scaled so their area is the 3D area (isometry = 2; unsigned singular values, so mirrored
  charts count as they look);
- max s1/s2; covered: UV area over the unit square's (xatlas packs into a rectangle of its own
  choosing: where it is not square, also its share of the square of the longer side); mirrored: charts (and their faces)
  whose signed UV area is negative; flips: faces of negative signed UV area inside charts
  of positive total area; overlaps: boundary edges of two charts that cross, plus charts
  lying inside another (:func:`chart_overlaps`, no use of the packer); border: the least
  distance of a UV to the unit square's border, in texels of a 1024 texture (jaxparam
  keeps ``margin_texels`` = 2 there since session 9); seconds: wall time (compilation included for jaxparam); load: the 1-minute load average
  after the run.

Usage::

    python benchmarks/atlas.py                       # every mesh of ../shared/data
    python benchmarks/atlas.py bunny.off cow.off     # some of them
    python benchmarks/atlas.py --big                 # also the ~1M-face refined cow
    python benchmarks/atlas.py --no-xatlas ...       # jaxparam only
    python benchmarks/atlas.py --big --xatlas-cap 600  # stop xatlas after 600 s
    python benchmarks/atlas.py --compact 0 ...        # jaxparam without the chart cuts
    python benchmarks/atlas.py --noise 0.2 cow.off     # vertex noise of 0.2 % of the diagonal
    python benchmarks/atlas.py --thin [--no-strips]    # held-out thin shapes (long charts)

xatlas is a benchmark-only extra (``pip install xatlas``); the engine never imports it.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

# jaxparam is imported where it is used, so the xatlas child process does not load it
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "meshes"


def measure(V, F, uv, T) -> dict:
    """The table's columns for 3D faces ``F (m, 3)`` into ``V`` and UV faces ``T (m, 3)``
    into ``uv``."""
    m = F.shape[0]
    n_uv = uv.shape[0]
    rows = np.repeat(np.arange(m), 3)
    A = sp.csr_matrix((np.ones(3 * m), (rows, T.reshape(-1))), shape=(m, n_uv))
    k, lab = connected_components(A @ A.T, directed=False)
    P = V[F]
    a3 = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    Q = uv[T]
    e1, e2 = Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]
    auv = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    s = np.sqrt(a3.sum() / np.abs(auv).sum())
    # singular values of the map from each 3D triangle (in its own frame) to UV
    x = P[:, 1] - P[:, 0]
    l1 = np.linalg.norm(x, axis=1)
    ex = x / l1[:, None]
    y = P[:, 2] - P[:, 0]
    yx = np.einsum("ij,ij->i", y, ex)
    yy = np.linalg.norm(y - yx[:, None] * ex, axis=1)
    # 3D frame coordinates: (0,0), (l1,0), (yx,yy)
    D = np.stack([np.stack([l1, yx], -1), np.stack([np.zeros(m), yy], -1)], -2)   # columns
    U = np.stack([e1, e2], -1) * s                                                 # (m, 2, 2)
    J = U @ np.linalg.inv(D)
    sv = np.linalg.svd(J, compute_uv=False)
    with np.errstate(divide="ignore"):
        sd = (sv[:, 0] ** 2 + sv[:, 1] ** 2 + sv[:, 0] ** -2.0 + sv[:, 1] ** -2.0) / 2
        aspect = sv[:, 0] / sv[:, 1]
    per_chart = np.bincount(lab, weights=auv, minlength=k)
    mirrored = per_chart < 0
    flips = int(np.sum((auv < 0) & ~mirrored[lab]) + np.sum((auv > 0) & mirrored[lab]))
    # seams: mesh edges whose two faces do not share both UV corners
    he = np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], 1).reshape(-1, 2)
    ht = np.stack([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]], 1).reshape(-1, 2)
    n = V.shape[0]
    key = np.minimum(he[:, 0], he[:, 1]) * n + np.maximum(he[:, 0], he[:, 1])
    order = np.argsort(key, kind="stable")
    ks = key[order]
    pair = np.flatnonzero(ks[1:] == ks[:-1])
    i, j = order[pair], order[pair + 1]
    same = (ht[i, 0] == ht[j, 1]) & (ht[i, 1] == ht[j, 0])
    cut = ~same
    seam = np.linalg.norm(V[he[i[cut], 0]] - V[he[i[cut], 1]], axis=1).sum()
    return {"charts": k, "seam": seam / np.sqrt(a3.sum()), "E_sd": float(np.sum(sd * a3) / a3.sum()),
            "max_aspect": float(np.max(aspect)), "covered": float(np.abs(auv).sum()),
            "mirrored": int(mirrored.sum()), "mirrored_faces": int(np.sum(mirrored[lab])),
            "flips": flips, "overlaps": chart_overlaps(uv, T, lab),
            "border": 1024 * float(min(uv[T].min(), 1 - uv[T].max()))}


def _expand(cnt):
    """``(item, offset)``: each item ``i`` repeated ``cnt[i]`` times, with ``0..cnt[i]-1``."""
    item = np.repeat(np.arange(len(cnt)), cnt)
    return item, np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)


def _grid_cells(bmin, bmax, cell):
    """The grid cells of side ``cell`` that boxes ``[bmin, bmax]`` (``(b, 2)`` each) touch:
    ``(box (c,), cell key (c,))``, sorted by key."""
    lo = np.floor(bmin / cell).astype(np.int64)
    hi = np.floor(bmax / cell).astype(np.int64)
    box, k = _expand((hi - lo + 1).prod(1))
    wx = (hi - lo + 1)[box, 0]
    key = (lo[box, 0] + k % wx) * 1000003 + lo[box, 1] + k // wx
    o = np.argsort(key, kind="stable")
    return box[o], key[o]


def chart_overlaps(uv, T, lab) -> int:
    """Overlaps between charts, checked without the packer: pairs of boundary edges of
    different charts that cross (grid-bucketed segment tests), plus charts one of whose
    vertices lies strictly inside another chart's triangle.  ``uv (n, 2)``, ``T (m, 3)``,
    ``lab (m,)`` the chart of each face."""
    h = np.stack([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]], 1).reshape(-1, 2)
    own = np.repeat(lab, 3)
    n = uv.shape[0]
    key, twin = h[:, 0] * n + h[:, 1], h[:, 1] * n + h[:, 0]
    lone = ~np.isin(twin, key)
    E, oc = h[lone], own[lone]
    A, B = uv[E[:, 0]], uv[E[:, 1]]
    cell = max(float(np.median(np.linalg.norm(B - A, axis=1))) * 2, 1e-9)
    e, ck = _grid_cells(np.minimum(A, B), np.maximum(A, B), cell)
    starts = np.flatnonzero(np.r_[True, ck[1:] != ck[:-1]])
    sizes = np.diff(np.r_[starts, ck.size])
    pairs = []
    for sz in np.unique(sizes[sizes > 1]):
        st = starts[sizes == sz]
        ii, jj = np.triu_indices(sz, 1)
        pairs.append(np.stack([e[st[:, None] + ii], e[st[:, None] + jj]], -1).reshape(-1, 2))
    crossings = 0
    if pairs:
        P = np.unique(np.sort(np.concatenate(pairs), 1), axis=0)
        P = P[oc[P[:, 0]] != oc[P[:, 1]]]
        a, b, c, d = A[P[:, 0]], B[P[:, 0]], A[P[:, 1]], B[P[:, 1]]
        cr = lambda o, p, q: (p[:, 0] - o[:, 0]) * (q[:, 1] - o[:, 1]) - (p[:, 1] - o[:, 1]) * (q[:, 0] - o[:, 0])
        d1, d2, d3, d4 = cr(a, b, c), cr(a, b, d), cr(c, d, a), cr(c, d, b)
        crossings = int(np.sum((d1 * d2 < 0) & (d3 * d4 < 0)))
    # the centroid of one triangle per chart strictly inside a triangle of another chart;
    # the triangles are bucketed on a grid by their bounding boxes (testing every triangle
    # for every chart ran past 15 minutes on xatlas's ~1M-face atlas, session 34)
    first = np.unique(lab, return_index=True)[1]
    Q = uv[T]
    q = Q[first].mean(1)
    tlo, thi = Q.min(1), Q.max(1)
    cell = max(float(np.median((thi - tlo).max(1))) * 2, 1e-9)
    tri, ck = _grid_cells(tlo, thi, cell)
    qc = np.floor(q / cell).astype(np.int64)
    qk = qc[:, 0] * 1000003 + qc[:, 1]
    a0, a1 = np.searchsorted(ck, qk, "left"), np.searchsorted(ck, qk, "right")
    which, at = _expand(a1 - a0)
    cand = tri[a0[which] + at]
    p = q[which]
    s = np.stack([(Q[cand, (t + 1) % 3, 0] - Q[cand, t, 0]) * (p[:, 1] - Q[cand, t, 1])
                  - (Q[cand, (t + 1) % 3, 1] - Q[cand, t, 1]) * (p[:, 0] - Q[cand, t, 0])
                  for t in range(3)], -1)
    hit = (np.all(s > 0, -1) | np.all(s < 0, -1)) & (lab[cand] != lab[first[which]])
    inside = int(np.unique(which[hit]).size)
    return crossings + inside


def noisy(mesh, percent: float, seed: int):
    """``mesh`` with Gaussian vertex noise of RMS ``percent`` % of its bounding-box diagonal."""
    import jaxparam as jp

    V = np.asarray(mesh.vertices, np.float64)
    d = float(np.linalg.norm(V.max(0) - V.min(0)))
    rng = np.random.default_rng(seed)
    return jp.TriMesh(V + rng.normal(scale=percent / 100 * d / np.sqrt(3), size=V.shape), mesh.faces)


def run_jaxparam(mesh, **kw) -> dict:
    from jaxparam.atlas import atlas

    t0 = time.perf_counter()
    a = atlas(mesh, **kw)
    dt = time.perf_counter() - t0
    r = measure(np.asarray(mesh.vertices, np.float64), mesh.faces, a.uv, a.uv_faces)
    r["seconds"] = dt
    return r


def _xatlas_child(src: str, dst: str) -> None:
    """Run xatlas on the mesh in ``src`` (npz: V, F) and save its UVs to ``dst``."""
    import xatlas

    d = np.load(src)
    t0 = time.perf_counter()
    at = xatlas.Atlas()
    at.add_mesh(d["V"].astype(np.float32), d["F"].astype(np.uint32))
    at.generate()
    vmap, idx, uvs = at[0]
    np.savez(dst, uv=uvs.astype(np.float64), idx=idx.astype(np.int64), seconds=time.perf_counter() - t0,
             size=np.array([at.width, at.height]))


def run_xatlas(mesh, cap: float = 900.0) -> dict:
    """xatlas with default options, in a child process stopped after ``cap`` seconds
    (native code cannot be interrupted otherwise); ``{"capped": cap}`` when stopped."""
    import subprocess
    import tempfile

    V = np.asarray(mesh.vertices, np.float64)
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = str(Path(tmp) / "in.npz"), str(Path(tmp) / "out.npz")
        np.savez(src, V=V, F=mesh.faces)
        try:
            subprocess.run([sys.executable, __file__, "--xatlas-child", src, dst], check=True, timeout=cap)
        except subprocess.TimeoutExpired:
            return {"capped": cap}
        d = np.load(dst)
        r = measure(V, mesh.faces, d["uv"], d["idx"])
        r["seconds"] = float(d["seconds"])
        w, h = (int(x) for x in d["size"])
        # xatlas's UVs span its own w x h texels: in a square texture of the longer side
        # (jaxparam packs for a square) the same charts cover this much less
        r["square"] = r["covered"] * min(w, h) / max(w, h, 1)
    return r


def thin_shapes(jp):
    """``(name, make)`` of held-out thin shapes, whose charts are long: a torus of tube radius
    0.06 (96 x 12), a 1 : 0.25 : 0.06 ellipsoid (a subdivided icosahedron, 5,120 faces), a
    capsule 8 long and 0.3 in radius (trimesh's, split to edges of at most 0.25), a tube along
    three turns of a helix (9,568 faces, two boundary loops), whose sides flatten to arcs."""
    def capsule():
        import trimesh
        c = trimesh.creation.capsule(height=8, radius=0.3, count=[24, 24]).subdivide_to_size(0.25)
        return jp.TriMesh(np.asarray(c.vertices, np.float64), np.asarray(c.faces))

    def ellipsoid():
        s = jp.shapes.sphere(4)
        return jp.TriMesh(np.asarray(s.vertices) * [1.0, 0.25, 0.06], s.faces)
    return [("thin torus (r 0.06)", lambda: jp.shapes.torus(96, 12, r=0.06)),
            ("flat ellipsoid", ellipsoid), ("capsule 8 x 0.3", capsule),
            ("helical tube", lambda: jp.shapes.helical_tube(3.0, 300, 16))]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("meshes", nargs="*", help="file names in ../shared/data/meshes (default: all)")
    ap.add_argument("--big", action="store_true", help="also a ~1M-face refined cow")
    ap.add_argument("--no-xatlas", action="store_true")
    ap.add_argument("--xatlas-cap", type=float, default=900.0,
                    help="seconds after which xatlas is stopped (it can take hours at 1M faces)")
    ap.add_argument("--compact", type=float, default=None,
                    help="jp.atlas's compact (default: the library's)")
    ap.add_argument("--noise", type=float, default=0.0,
                    help="Gaussian vertex noise, RMS in %% of the bounding-box diagonal (a scan's)")
    ap.add_argument("--seed", type=int, default=31, help="the noise's seed")
    ap.add_argument("--thin", action="store_true",
                    help="generated thin shapes instead (a thin torus, a flat ellipsoid, a long capsule)")
    ap.add_argument("--no-strips", action="store_true",
                    help="jp.atlas without the long-chart cuts (atlas.build.STRIP_SHARES = ())")
    ap.add_argument("--xatlas-child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.xatlas_child:
        _xatlas_child(*args.xatlas_child)
        return
    import jaxparam as jp

    names = args.meshes or sorted(p.name for p in DATA.iterdir())
    cases = thin_shapes(jp) if args.thin else [(nm, lambda nm=nm: jp.load(DATA / nm)) for nm in names]
    if args.no_strips:
        import importlib
        importlib.import_module("jaxparam.atlas.build").STRIP_SHARES = ()
    if args.noise:
        cases = [(f"{nm} + {args.noise:g} % noise", lambda make=make: noisy(make(), args.noise, args.seed))
                 for nm, make in cases]
    if args.big:
        cases.append(("cow x256 (refined)", lambda: jp.shapes.refine(jp.load(DATA / "cow.off"), 4)))
    print("| mesh | faces | tool | charts | seam/sqrt(A) | E_sd (iso 2) | max s1/s2 | covered | "
          "mirrored charts (faces) | flips | overlaps | border (texels) | seconds | load |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    kw = {} if args.compact is None else {"compact": args.compact}
    for name, make in cases:
        try:
            mesh = make()
        except Exception as exc:       # e.g. a non-manifold file: the library refuses it
            print(f"| {name} | | | not loaded: {type(exc).__name__}: {str(exc)[:120]} |", flush=True)
            continue
        tools = [("jaxparam", lambda m: run_jaxparam(m, **kw))] + ([] if args.no_xatlas else [
            ("xatlas", lambda m: run_xatlas(m, args.xatlas_cap))])
        for tool, fn in tools:
            try:
                r = fn(mesh)
            except Exception as exc:       # report and go on: a benchmark prints a table
                print(f"| {name} | {mesh.n_faces} | {tool} | failed: {type(exc).__name__}: {exc} |")
                continue
            if "capped" in r:
                print(f"| {name} | {mesh.n_faces:,} | {tool} | stopped after {r['capped']:.0f} s "
                      f"| | | | | | | | | > cap | {os.getloadavg()[0]:.1f} |", flush=True)
                continue
            square = f" ({100 * r['square']:.1f} % of a square)" if r.get("square", r["covered"]) < r["covered"] else ""
            print(f"| {name} | {mesh.n_faces:,} | {tool} | {r['charts']} | {r['seam']:.2f} | "
                  f"{r['E_sd']:.4f} | {r['max_aspect']:.2f} | {100 * r['covered']:.1f} %{square} | "
                  f"{r['mirrored']} ({r['mirrored_faces']}) | {r['flips']} | {r['overlaps']} | "
                  f"{r['border']:.1f} | {r['seconds']:.1f} | "
                  f"{os.getloadavg()[0]:.1f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
