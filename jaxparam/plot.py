"""Pictures: the UV layout coloured by distortion, and a checkerboard on the surface.

Matplotlib with the Agg backend (no screen needed).  Each function writes a
PNG and returns the path.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import metrics

__all__ = ["plot_uv", "plot_checkerboard", "plot_isocurves", "plot_remesh"]


def _figure(size=(6, 6)):
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt, plt.figure(figsize=size, dpi=110)


def _equal_axes_3d(ax, P) -> None:
    """Equal scales on the three axes of a 3D plot around the points ``P: (k, 3)``."""
    if P.size:
        mid, r = (P.max(0) + P.min(0)) / 2, (P.max(0) - P.min(0)).max() / 2
        ax.set_xlim(mid[0] - r, mid[0] + r)
        ax.set_ylim(mid[1] - r, mid[1] + r)
        ax.set_zlim(mid[2] - r, mid[2] + r)


def _shade(P: np.ndarray) -> np.ndarray:
    """``(m,)`` brightness in [0.55, 1] of triangles ``P (m, 3, 3)`` under one fixed light."""
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return 0.55 + 0.45 * np.abs(n @ np.array([0.3, -0.4, 0.85]) / np.linalg.norm([0.3, -0.4, 0.85]))


def _save(plt, fig, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_uv(mesh, uv, path, *, title: str | None = None, quantity: str = "aspect"):
    """Draw the UV triangulation coloured per face and save it as PNG.

    **Arguments:** ``quantity``: ``"aspect"`` (``log2(s1/s2)``, 0 for a
    conformal face) or ``"area"`` (``log2`` of the UV/3D area ratio, rescaled
    to equal totals).  Flipped faces are drawn in red, boundary loops in black.
    """
    import matplotlib.tri as mtri

    U = np.asarray(uv, np.float64)
    F = mesh.faces
    fd = metrics.face_distortion(mesh, U)
    s1, s2 = np.asarray(fd["s1"]), np.asarray(fd["s2"])
    a3, auv = np.asarray(fd["area3d"]), np.asarray(fd["area_uv"])
    with np.errstate(divide="ignore", invalid="ignore"):
        if quantity == "area":
            val = np.log2(np.abs(auv) / a3 * a3.sum() / np.abs(auv).sum())
            label = "log2 area ratio"
        else:
            val = np.log2(s1 / np.abs(s2))
            label = "log2(σ1/σ2)"
    val = np.where(np.isfinite(val), val, np.nan)
    plt, fig = _figure()
    ax = fig.add_subplot(111)
    ok = np.all(np.isfinite(U[F]).reshape(len(F), -1), axis=1)
    tri = mtri.Triangulation(U[:, 0], U[:, 1], F[ok])
    vmax = np.nanpercentile(np.abs(val[ok]), 99) if np.any(ok) else 1.0
    coll = ax.tripcolor(tri, facecolors=np.nan_to_num(val[ok]), cmap="viridis",
                        vmin=0 if quantity == "aspect" else -vmax, vmax=max(vmax, 1e-3),
                        edgecolors="k" if len(F) < 3000 else "none", linewidth=0.1)
    fig.colorbar(coll, ax=ax, shrink=0.8, label=label)
    flipped = np.flatnonzero(auv <= 0)
    if flipped.size:
        ft = mtri.Triangulation(U[:, 0], U[:, 1], F[flipped])
        ax.tripcolor(ft, facecolors=np.ones(flipped.size), cmap="Reds", vmin=0, vmax=1)
    for loop in mesh.topology.boundary_loops:
        L = np.append(loop, loop[0])
        ax.plot(U[L, 0], U[L, 1], "k-", lw=0.8)
    ax.set_aspect("equal")
    ax.set_title(title or f"{mesh.name or 'mesh'}: {len(F)} faces, {flipped.size} flipped")
    ax.set_axis_off()
    return _save(plt, fig, path)


def plot_checkerboard(mesh, uv, path, *, squares: int = 8, title: str | None = None,
                      elev: float = 30, azim: float = -60):
    """Render the surface with a checkerboard texture through ``uv`` (faces coloured by
    the checker cell of their UV centroid) and save it as PNG."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    U = np.asarray(uv, np.float64)
    V = np.asarray(mesh.vertices, np.float64)
    F = mesh.faces
    lo, hi = np.nanmin(U, 0), np.nanmax(U, 0)
    c = (U[F].mean(1) - lo) / np.max(hi - lo) * squares
    check = (np.floor(c[:, 0]) + np.floor(c[:, 1])) % 2
    P = V[F]
    light = _shade(P)
    base = np.where(check[:, None] > 0, np.array([[0.95, 0.6, 0.1]]), np.array([[0.15, 0.3, 0.7]]))
    colors = np.clip(base * light[:, None], 0, 1)
    plt, fig = _figure()
    ax = fig.add_subplot(111, projection="3d")
    ax.add_collection3d(Poly3DCollection(P, facecolors=colors, edgecolors="none"))
    _equal_axes_3d(ax, V)
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()
    ax.set_title(title or f"{mesh.name or 'mesh'}: checkerboard through the UV map")
    return _save(plt, fig, path)


def plot_isocurves(surface: Surface, path, *, lines: int = 12, samples: int = 200,
                   title: str | None = None):
    """Draw iso-parameter curves ``u = const`` and ``v = const`` of the surface (Figs. 6, 8)."""
    (u0, u1), (v0, v1) = surface.bbox
    plt, fig = _figure()
    ax = fig.add_subplot(111, projection="3d")
    t = np.linspace(0, 1, samples)
    pts = []
    for c in np.linspace(0, 1, lines):
        for uv, color in (((u0 + c * (u1 - u0)) * np.ones_like(t), v0 + t * (v1 - v0)), "tab:blue"), \
                         ((u0 + t * (u1 - u0), (v0 + c * (v1 - v0)) * np.ones_like(t)), "tab:red"):
            X = surface.evaluate(np.column_stack(uv))
            ax.plot(X[:, 0], X[:, 1], X[:, 2], color=color, lw=0.8)
            pts.append(X[np.all(np.isfinite(X), 1)])
    _equal_axes_3d(ax, np.concatenate(pts))
    ax.set_axis_off()
    ax.set_title(title or f"iso-parameter curves of the {surface.kind} surface")
    return _save(plt, fig, path)


def plot_remesh(semi, path, *, title: str | None = None, elev: float = 30, azim: float = -60):
    """Two panels: the remesh on the surface, its faces shaded and coloured by the base
    triangle they come from, with edges drawn; and its parameter domain ``semi.uv``
    (the refined base domain ``T^j``; left out for closed remeshes, which have none).
    ``semi`` is a :class:`jaxparam.remesh.Remesh` (from :func:`jaxparam.remesh` or
    ``ManifoldParameterization.remesh``)."""
    from matplotlib.collections import PolyCollection
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    V = np.asarray(semi.mesh.vertices, np.float64)
    U = None if semi.uv is None else np.asarray(semi.uv, np.float64)
    F = semi.mesh.faces
    base_of = np.arange(F.shape[0]) // (4 ** semi.hierarchy.levels)   # children follow their parent
    P = V[F]
    light = _shade(P)
    palette = np.array([[0.95, 0.6, 0.1], [0.15, 0.3, 0.7], [0.3, 0.65, 0.3], [0.8, 0.25, 0.3],
                        [0.55, 0.4, 0.75], [0.2, 0.6, 0.7]])
    colors = np.clip(palette[base_of % len(palette)] * light[:, None], 0, 1)
    plt, fig = _figure((12, 6) if U is not None else (7, 6))
    ax = fig.add_subplot(121 if U is not None else 111, projection="3d")
    ax.add_collection3d(Poly3DCollection(P, facecolors=colors, edgecolors="k", linewidths=0.1))
    _equal_axes_3d(ax, V)
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()
    ax.set_title(title or f"remesh: {F.shape[0]} faces, subdivision connectivity of order "
                 f"{semi.hierarchy.levels}")
    if U is None:                       # a closed remesh (jaxparam.manifold): no plane picture
        return _save(plt, fig, path)
    ax2 = fig.add_subplot(122)
    ax2.add_collection(PolyCollection(U[F], facecolors=palette[base_of % len(palette)],
                                      edgecolors="k", linewidths=0.1))
    ax2.set_xlim(U[:, 0].min(), U[:, 0].max())
    ax2.set_ylim(U[:, 1].min(), U[:, 1].max())
    ax2.set_aspect("equal")
    ax2.set_title("parameter domain: the refined base domain")
    return _save(plt, fig, path)
