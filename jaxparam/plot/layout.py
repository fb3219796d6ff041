"""The UV layout in the plane, coloured per face by distortion (robust colour limits;
flipped and degenerate faces marked and counted apart)."""
from __future__ import annotations

import numpy as np

from .. import metrics
from .common import DPI, face_states, finish, mesh_and_uv, new_figure, robust_limits

__all__ = ["QUANTITIES", "plot_uv"]

#: What :func:`plot_uv` can colour by.
QUANTITIES = ("aspect", "area")


def plot_uv(mesh, uv, path=None, *, title: str | None = None, quantity: str = "aspect",
            percentile: float = 98.0, dpi: int = DPI, size: float = 6.0):
    """Draw the UV triangulation coloured per face, with its boundary loops in black.

    **Arguments:** ``mesh`` a :class:`~jaxparam.TriMesh` (or a ``(V, F)`` pair); ``uv:
    (n, 2)``; ``path`` save here when given; ``quantity`` ``"aspect"`` (``log2(σ1/σ2)``, 0
    for a conformal face) or ``"area"`` (``log2`` of the UV/3D area ratio, rescaled to equal totals);
    ``percentile`` sets the colour limits (``[0, p98]`` for the aspect, ``±p98`` of
    ``|log2|`` for the area, or Tukey's far fence when lower: :func:`.robust_limits`), so a
    few outliers cannot wash the picture out; the colorbar says which share of the faces
    lies beyond; ``dpi``; ``size`` the height in inches.

    Flipped faces (clockwise in the plane) are drawn red and degenerate faces (zero UV
    area, e.g. three boundary vertices on one side of a square) black; the title counts
    them apart.

    **Returns:** the matplotlib Figure.

    Example::

        fig = jp.plot.plot_uv(mesh, uv, "uv.png", quantity="area")
    """
    import matplotlib.tri as mtri

    from ..options import choose

    quantity = choose(quantity, QUANTITIES, what="quantity", where="plot_uv")
    mesh, U = mesh_and_uv(mesh, uv, "plot_uv")
    F = np.asarray(mesh.faces)
    fd = metrics.face_distortion(mesh, U)
    s1, s2 = np.asarray(fd["s1"]), np.asarray(fd["s2"])
    a3 = np.asarray(fd["area3d"])
    states = face_states(mesh, U)
    auv = states.area_uv
    good = ~states.flipped & ~states.degenerate
    with np.errstate(divide="ignore", invalid="ignore"):
        if quantity == "area":
            val = np.log2(np.abs(auv) / a3 * a3[good].sum() / np.abs(auv[good]).sum())
            label, lim = "log2 area ratio", robust_limits(val[good], percentile=percentile,
                                                           symmetric=True)
            cmap = "coolwarm"
        else:
            val = np.log2(s1 / np.abs(s2))
            label, lim = "log2(σ1/σ2)", robust_limits(val[good], percentile=percentile, floor=0)
            cmap = "viridis"
    ok = np.all(np.isfinite(U[F]).reshape(len(F), -1), axis=1)
    box = U[np.unique(F[ok])] if ok.any() else np.zeros((1, 2))
    lo, hi = box.min(0), box.max(0)
    ar = float((hi[0] - lo[0]) / max(hi[1] - lo[1], 1e-300)) if ok.any() else 1.0
    ar = min(max(ar, 0.3), 3.0)
    fig = new_figure((size * ar + 1.3, size + 0.4), dpi)
    ax = fig.add_axes([0.01, 0.01, (size * ar) / (size * ar + 1.3) - 0.01, size / (size + 0.4)])
    edges = dict(edgecolors="k", linewidth=0.1) if len(F) < 1500 else dict(edgecolors="none")
    sel = ok & good
    if sel.any():
        tri = mtri.Triangulation(U[:, 0], U[:, 1], F[sel])
        coll = ax.tripcolor(tri, facecolors=np.nan_to_num(val[sel], nan=lim.vmax), cmap=cmap,
                            vmin=lim.vmin, vmax=lim.vmax, **edges)
        cax = fig.add_axes([(size * ar) / (size * ar + 1.3) + 0.01, 0.1, 0.25 / (size * ar + 1.3),
                            0.75 * size / (size + 0.4)])
        fig.colorbar(coll, cax=cax, label=lim.label(label), extend=lim.extend)
    for mask, color in ((ok & states.flipped, "red"), (ok & states.degenerate, "black")):
        if mask.any():
            t = mtri.Triangulation(U[:, 0], U[:, 1], F[mask])
            ax.tripcolor(t, facecolors=np.zeros(mask.sum()), cmap="gray" if color == "black"
                         else "Reds_r", vmin=0, vmax=1, edgecolors=color, linewidth=0.6)
    for loop in mesh.topology.boundary_loops:
        L = np.append(loop, loop[0])
        ax.plot(U[L, 0], U[L, 1], "k-", lw=0.8)
    pad = 0.01 * max(float(np.max(hi - lo)), 1e-300)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_axis_off()
    fig.suptitle(title or f"{mesh.name or 'mesh'}: {len(F)} faces, {states.caption()}",
                 fontsize=10)
    return finish(fig, path, dpi=dpi)
