"""Record (or check) the convex, least-squares and minimize results on ../shared/data's disk meshes.

The redesign (issue 11) must leave convex_map and least_squares_map bitwise unchanged and
minimize within 1e-9.  ``python tests/baseline/record.py`` writes ``uv_hashes.json`` (sha256 of
every map's UV bytes) and ``minimize.npz``; ``tests/test_behaviour_unchanged.py`` checks them.
"""
from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parents[2] / "shared" / "data" / "meshes"
DISKS = ["camelhead.off", "camel_b.obj", "bump-domain.obj", "lilium.obj", "snail.obj", "grid.off",
         "planexy.off", "halftunnel.off"]
WEIGHTS = ("uniform", "inverse_distance", "shape_preserving", "mean_value", "harmonic")
BOUNDARIES = ("circle", "square", "plane")
MINIMIZE = [("snail.obj", "symmetric_dirichlet", False), ("snail.obj", "mips", True),
            ("camel_b.obj", "symmetric_dirichlet", True), ("grid.off", "arap", True)]


def digest(uv) -> str:
    a = np.ascontiguousarray(np.asarray(uv, np.float64))
    return hashlib.sha256(a.tobytes()).hexdigest()


def maps(jp):
    """Yield ``(key, uv)`` for every disk mesh, weight and boundary, and the spring map."""
    for name in DISKS:
        mesh = jp.load(DATA / name)
        for w in WEIGHTS:
            for b in BOUNDARIES:
                try:
                    uv = jp.convex_map(mesh, weights=w, boundary=b)
                except jp.JaxparamError as e:      # record refusals too
                    uv = type(e).__name__
                yield f"{name}/convex/{w}/{b}", uv
        for b in BOUNDARIES:
            try:
                uv = jp.least_squares_map(mesh, boundary=b)
            except jp.JaxparamError as e:
                uv = type(e).__name__
            yield f"{name}/least_squares/{b}", uv


def minimized(jp):
    for name, energy, free in MINIMIZE:
        mesh = jp.load(DATA / name)
        res = jp.minimize(mesh, energy, free_boundary=free, verbose=False)
        yield f"{name}/{energy}/{'free' if free else 'fixed'}", np.asarray(res.uv)


if __name__ == "__main__":
    import jaxparam as jp

    hashes = {k: (v if isinstance(v, str) else digest(v)) for k, v in maps(jp)}
    (HERE / "uv_hashes.json").write_text(json.dumps(hashes, indent=0, sort_keys=True))
    np.savez_compressed(HERE / "minimize.npz", **dict(minimized(jp)))
    print(len(hashes), "maps recorded", file=sys.stderr)
