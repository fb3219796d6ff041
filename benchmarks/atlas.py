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
- max s1/s2; covered: UV area over the unit square's; mirrored: charts (and their faces)
  whose signed UV area is negative; flips: faces of negative signed UV area inside charts
  of positive total area; seconds: wall time (compilation included for jaxparam).

Usage::

    python benchmarks/atlas.py                       # every mesh of ../shared/data
    python benchmarks/atlas.py bunny.off cow.off     # some of them
    python benchmarks/atlas.py --big                 # also the ~1M-face refined cow
    python benchmarks/atlas.py --no-xatlas ...       # jaxparam only

xatlas is a benchmark-only extra (``pip install xatlas``); the engine never imports it.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

import jaxparam as jp
from jaxparam.atlas import atlas

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
            "flips": flips}


def run_jaxparam(mesh) -> dict:
    t0 = time.perf_counter()
    a = atlas(mesh)
    dt = time.perf_counter() - t0
    r = measure(np.asarray(mesh.vertices, np.float64), mesh.faces, a.uv, a.uv_faces)
    r["seconds"] = dt
    return r


def run_xatlas(mesh) -> dict:
    import xatlas

    V = np.asarray(mesh.vertices, np.float64)
    t0 = time.perf_counter()
    at = xatlas.Atlas()
    at.add_mesh(V.astype(np.float32), mesh.faces.astype(np.uint32))
    at.generate()
    vmap, idx, uvs = at[0]
    dt = time.perf_counter() - t0
    r = measure(V, mesh.faces, uvs.astype(np.float64), idx.astype(np.int64))
    r["seconds"] = dt
    return r


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("meshes", nargs="*", help="file names in ../shared/data/meshes (default: all)")
    ap.add_argument("--big", action="store_true", help="also a ~1M-face refined cow")
    ap.add_argument("--no-xatlas", action="store_true")
    args = ap.parse_args(argv)
    names = args.meshes or sorted(p.name for p in DATA.iterdir())
    cases = [(nm, lambda nm=nm: jp.load(DATA / nm)) for nm in names]
    if args.big:
        cases.append(("cow x256 (refined)", lambda: jp.shapes.refine(jp.load(DATA / "cow.off"), 4)))
    print("| mesh | faces | tool | charts | seam/sqrt(A) | E_sd (iso 2) | max s1/s2 | covered | "
          "mirrored charts (faces) | flips | seconds |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, make in cases:
        mesh = make()
        tools = [("jaxparam", run_jaxparam)] + ([] if args.no_xatlas else [("xatlas", run_xatlas)])
        for tool, fn in tools:
            try:
                r = fn(mesh)
            except Exception as exc:       # report and go on: a benchmark prints a table
                print(f"| {name} | {mesh.n_faces} | {tool} | failed: {type(exc).__name__}: {exc} |")
                continue
            print(f"| {name} | {mesh.n_faces:,} | {tool} | {r['charts']} | {r['seam']:.2f} | "
                  f"{r['E_sd']:.4f} | {r['max_aspect']:.2f} | {100 * r['covered']:.1f} % | "
                  f"{r['mirrored']} ({r['mirrored_faces']}) | {r['flips']} | {r['seconds']:.1f} |",
                  flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
