"""``make demo``: flatten meshes the project generates and write results to ``out/``.

Runs every convex-combination weight on the survey's graph surface, Example 5
and a cylinder patch, minimizes symmetric Dirichlet with a free boundary,
remeshes the graph surface with subdivision connectivity and compresses it
with wavelets to 2 % of its coefficients, parameterizes a torus over a
decimated base domain and remeshes it, and writes OBJ files with UVs, JSON
reports and PNG pictures.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import jaxparam as jp
from jaxparam.cli.pipeline import report_dict, write_json
from jaxparam.plot import plot_checkerboard, plot_remesh, plot_uv


def picture(draw, *args) -> None:
    """Draw and save one picture (``draw(*args)``), then close its figure."""
    import matplotlib.pyplot as plt

    plt.close(draw(*args))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="out")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = []
    meshes = {"graph_surface": jp.shapes.graph_surface(40), "example5": jp.shapes.example5(30),
              "cylinder_patch": jp.shapes.cylinder_patch(40, 16)}
    for name, mesh in meshes.items():
        for w in jp.weights.KINDS:
            t = time.perf_counter()
            uv = np.asarray(jp.convex_map(mesh, weights=w, boundary="circle"))
            sec = time.perf_counter() - t
            rep = report_dict(mesh, uv, weights=w, seconds={"convex_map": sec})
            stem = f"{name}_{w}"
            jp.save(out / f"{stem}.obj", mesh, uv)
            write_json(out / f"{stem}.json", rep)
            if w == "shape_preserving":
                picture(plot_uv, mesh, uv, out / f"{stem}_uv.png")
                picture(plot_checkerboard, mesh, uv, out / f"{stem}_checker.png")
            summary.append((stem, rep["flips"], rep["max_aspect"], rep["sym_dirichlet"], sec))
        if hasattr(jp, "minimize"):
            t = time.perf_counter()
            res = jp.minimize(mesh, "symmetric_dirichlet", free_boundary=True)
            sec = time.perf_counter() - t
            rep = report_dict(mesh, res.uv, seconds={"minimize": sec},
                              extra={"energy": res.energy, "iterations": res.iterations})
            stem = f"{name}_symmetric_dirichlet_free"
            jp.save(out / f"{stem}.obj", mesh, res.uv)
            write_json(out / f"{stem}.json", rep)
            picture(plot_uv, mesh, res.uv, out / f"{stem}_uv.png")
            picture(plot_checkerboard, mesh, res.uv, out / f"{stem}_checker.png")
            summary.append((stem, rep["flips"], rep["max_aspect"], rep["sym_dirichlet"], sec))
    # Survey §7: remesh the graph surface with subdivision connectivity, compress it.
    mesh = meshes["graph_surface"]
    t = time.perf_counter()
    semi = jp.remesh(mesh, jp.convex_map(mesh, boundary="circle"), levels=5)
    sec = time.perf_counter() - t
    jp.save(out / "graph_surface_remesh.obj", semi.mesh, semi.uv)
    picture(plot_remesh, semi, out / "graph_surface_remesh.png")
    small = jp.wavelets.compress(semi, 0.02)
    jp.save(out / "graph_surface_remesh_2pc.obj", small.mesh, semi.uv)
    rep = report_dict(semi.mesh, semi.uv, seconds={"remesh": sec})
    summary.append(("graph_surface_remesh (levels 5)", rep["flips"], rep["max_aspect"],
                    rep["sym_dirichlet"], sec))
    # Survey §9: a closed genus-1 mesh over a decimated base domain, remeshed.
    t = time.perf_counter()
    base, param = jp.manifold_map(jp.shapes.torus(40, 20), base_faces=40)
    closed = param.remesh(3)
    sec = time.perf_counter() - t
    jp.save(out / "torus_remesh.obj", closed.mesh)
    picture(plot_remesh, closed, out / "torus_remesh.png")
    print(f"torus (genus 1): base domain {base.n_faces} faces, remesh {closed.mesh.n_faces} faces, "
          f"genus {closed.mesh.topology.genus}, {sec:.2f} s")
    print(f"{'result':48s} {'flips':>5s} {'max σ1/σ2':>10s} {'sym.Dir.':>9s} {'seconds':>8s}")
    for stem, fl, asp, sd, sec in summary:
        print(f"{stem:48s} {fl:5d} {asp:10.3f} {sd:9.3f} {sec:8.3f}")
    (out / "summary.json").write_text(json.dumps(
        [dict(zip(["result", "flips", "max_aspect", "sym_dirichlet", "seconds"], s)) for s in summary],
        indent=1))
    print(f"wrote {len(summary)} results to {out}/ (OBJ with vt, JSON reports, PNG pictures)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
