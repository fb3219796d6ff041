"""Pictures of surfaces in 3D, rasterized per pixel (:mod:`.raster`): the checkerboard
through a UV map, a remesh coloured by base triangle, iso-parameter curves of a fitted
surface.  Orthographic views with one scale on both screen axes (a sphere is round); the
surface fills the frame."""
from __future__ import annotations

import numpy as np

from ..errors import MeshError
from ..options import is_integer
from .common import DPI, finish, mesh_and_uv, new_figure
from .raster import downsample, rasterize, shading, vertex_normals, wire

__all__ = ["CHECKER_COLORS", "checker_image", "plot_checkerboard", "plot_remesh",
           "plot_isocurves", "image_figure"]

#: The two colours of the checkerboard (RGB in [0, 1]).
CHECKER_COLORS = np.array([[0.15, 0.3, 0.7], [0.95, 0.6, 0.1]])

#: Supersampling factor (per side) of the rasterized pictures: their anti-aliasing.
SUPERSAMPLE = 2

_PALETTE = np.array([[0.95, 0.6, 0.1], [0.15, 0.3, 0.7], [0.3, 0.65, 0.3], [0.8, 0.25, 0.3],
                     [0.55, 0.4, 0.75], [0.2, 0.6, 0.7]])


def image_figure(rgba: np.ndarray, title: str, *, dpi: int = DPI, extra_width: float = 0.0):
    """A figure showing ``rgba: (h, w, 4)`` at one image pixel per figure pixel, with
    ``title`` above it; returns ``(fig, ax)``."""
    h, w = rgba.shape[:2]
    band = 0.35                                               # inches for the title
    fig = new_figure((w / dpi + extra_width, h / dpi + band), dpi)
    H = h / dpi + band
    ax = fig.add_axes([0, 0, (w / dpi) / (w / dpi + extra_width), (h / dpi) / H])
    ax.imshow(rgba, interpolation="antialiased")
    ax.set_axis_off()
    fig.suptitle(title, y=1 - 0.08 * band / H, va="top", fontsize=10)
    return fig, ax


def _render(V, F, color_fn, *, elev, azim, pixels, edges: float = 0.0):
    """Rasterize ``V[F]`` with ``SUPERSAMPLE``; ``color_fn(raster) -> (H, W, 3)`` gives the
    base colour per pixel; returns ``(rgba (h, w, 4), raster)`` shaded and anti-aliased,
    with edges darkened when ``edges > 0`` (their width in output pixels)."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    r = rasterize(V, F, elev=elev, azim=azim, pixels=pixels * SUPERSAMPLE)
    rgb = color_fn(r) * shading(r, F, vertex_normals(V, F))[..., None]
    if edges > 0:
        rgb *= 1 - 0.75 * wire(r, F, edges * SUPERSAMPLE)[..., None]
    a = r.mask.astype(np.float64)
    rgba = np.concatenate([rgb * a[..., None], a[..., None]], axis=-1)
    rgba = downsample(rgba, SUPERSAMPLE)
    alpha = rgba[..., 3:]
    rgba[..., :3] = np.where(alpha > 0, rgba[..., :3] / np.maximum(alpha, 1e-12), 1.0)
    return np.clip(rgba, 0, 1), r


def checker_image(uv_pixels: np.ndarray, squares: int, lo, span: float) -> np.ndarray:
    """``(..., 3)`` checker colours of UVs ``uv_pixels: (..., 2)``: ``squares`` squares
    along the longer side of the UV box (corner ``lo``, side ``span``); grey where the UV
    is not finite."""
    c = (uv_pixels - np.asarray(lo)) / span * squares
    with np.errstate(invalid="ignore"):
        check = (np.floor(c[..., 0]) + np.floor(c[..., 1])) % 2
    rgb = CHECKER_COLORS[np.nan_to_num(check).astype(int) % 2]
    return np.where(np.isfinite(check)[..., None], rgb, 0.6)


def plot_checkerboard(mesh, uv, path=None, *, squares: int = 8, title: str | None = None,
                      elev: float = 30, azim: float = -60, dpi: int = DPI, size: float = 6.0):
    """The surface with a checkerboard textured through ``uv: (n, 2)``, per pixel: the UV
    of every pixel is interpolated in its face and coloured by its checker square, so the
    squares are straight wherever the map is linear.

    **Arguments:** ``mesh`` a :class:`~jaxparam.TriMesh` (or a ``(V, F)`` pair); ``path``
    save the picture here (PNG, or the extension's format) when given; ``squares`` along the longer side of the
    UV box; ``elev``, ``azim`` the view in degrees (orthographic); ``dpi``; ``size`` the
    longer side in inches.

    **Returns:** the matplotlib Figure.  Faces with a non-finite UV are grey.

    Example::

        fig = jp.plot.plot_checkerboard(mesh, uv, "checker.png")
    """
    mesh, U = mesh_and_uv(mesh, uv, "plot_checkerboard")
    if not is_integer(squares) or squares < 1:
        raise MeshError(f"plot_checkerboard: squares must be an integer >= 1, got {squares!r}.")
    F = mesh.faces
    fin = np.all(np.isfinite(U), 1)
    lo = U[fin].min(0) if fin.any() else np.zeros(2)
    span = float(np.max(U[fin].max(0) - lo)) if fin.any() else 1.0
    span = span if span > 0 else 1.0

    def colors(r):
        with np.errstate(invalid="ignore"):
            return checker_image(r.interpolate(F, U), squares, lo, span)

    rgba, _ = _render(mesh.vertices, F, colors, elev=elev, azim=azim, pixels=int(size * dpi))
    fig, _ = image_figure(rgba, title or f"{mesh.name or 'mesh'}: checkerboard through the UV map",
                          dpi=dpi)
    return finish(fig, path, dpi=dpi)


def plot_remesh(semi, path=None, *, title: str | None = None, elev: float = 30,
                azim: float = -60, dpi: int = DPI, size: float = 6.0):
    """Two panels: the remesh on the surface, its faces shaded and coloured by the base
    triangle they come from, with edges drawn; and its parameter domain ``semi.uv`` (the
    refined base domain ``T^j``; left out for closed remeshes, which have none).

    **Arguments:** ``semi`` a :class:`jaxparam.remesh.Remesh` (from :func:`jaxparam.remesh`
    or ``ManifoldParameterization.remesh``), or a sequence of closed ones (the components of
    a mesh, :func:`jaxparam.manifold.manifold_map_each`: drawn together, one surface panel);
    ``path``, ``elev``, ``azim``, ``dpi``,
    ``size`` as for :func:`plot_checkerboard`.  **Returns:** the Figure.
    """
    from matplotlib.collections import PolyCollection

    parts = tuple(semi) if isinstance(semi, (list, tuple)) else (semi,)
    starts = np.cumsum([0] + [p.mesh.n_vertices for p in parts])
    V = np.concatenate([np.asarray(p.mesh.vertices, np.float64) for p in parts])
    F = np.concatenate([np.asarray(p.mesh.faces) + s0 for p, s0 in zip(parts, starts)])
    # children follow their parent: a face's base triangle, numbered on across the parts
    base_of = np.concatenate([np.arange(p.mesh.n_faces) // (4 ** p.hierarchy.levels) for p in parts])
    base_of += np.repeat(np.cumsum([0] + [p.mesh.n_faces // 4 ** p.hierarchy.levels for p in parts])[:-1],
                         [p.mesh.n_faces for p in parts])
    face_rgb = _PALETTE[base_of % len(_PALETTE)]
    semi = parts[0]

    def colors(r):
        return face_rgb[np.where(r.face >= 0, r.face, 0)]

    edge_px = 0.6 if F.shape[0] < 20000 else 0.0
    rgba, _ = _render(V, F, colors, elev=elev, azim=azim, pixels=int(size * dpi), edges=edge_px)
    U = None if semi.uv is None or len(parts) > 1 else np.asarray(semi.uv, np.float64)
    t = title or (f"remesh: {F.shape[0]} faces, subdivision connectivity of order "
                  f"{semi.hierarchy.levels}" + (f", {len(parts)} components" if len(parts) > 1 else ""))
    h, w = rgba.shape[:2]
    fig, ax = image_figure(rgba, t, dpi=dpi, extra_width=0.0 if U is None else h / dpi)
    if U is None:                       # a closed remesh (jaxparam.manifold): no plane picture
        return finish(fig, path, dpi=dpi)
    W = fig.get_figwidth()
    ax2 = fig.add_axes([w / dpi / W + 0.01, 0.02, (h / dpi) / W - 0.02, ax.get_position().height - 0.04])
    ax2.add_collection(PolyCollection(U[F], facecolors=face_rgb,
                                      edgecolors="k", linewidths=0.1 if F.shape[0] < 20000 else 0))
    ax2.set_xlim(U[:, 0].min(), U[:, 0].max())
    ax2.set_ylim(U[:, 1].min(), U[:, 1].max())
    ax2.set_aspect("equal")
    ax2.set_axis_off()
    ax2.set_title("parameter domain: the refined base domain", fontsize=9)
    return finish(fig, path, dpi=dpi)


def plot_isocurves(surface, path=None, *, domain=None, lines: int = 12, samples: int = 200,
                   title: str | None = None, elev: float = 30, azim: float = -60,
                   resolution: int = 120, dpi: int = DPI, size: float = 6.0):
    """Iso-parameter curves ``u = const`` (blue) and ``v = const`` (red) of a fitted
    surface drawn on the shaded surface, hidden parts left out (the survey's Figs. 6, 8).

    **Arguments:** ``surface`` a :class:`jaxparam.fitting.Surface`; ``domain`` ``(k, 2)``
    the parameter domain's boundary polygon (e.g. ``uv[mesh.topology.boundary_loops[0]]``):
    surface and curves are drawn inside it only (a spline is defined on the whole bounding
    box, and far from its data it is not worth drawing); ``lines`` curves per direction;
    ``samples`` points per curve; ``resolution`` of the grid sampled for the shaded
    surface; the rest as for :func:`plot_checkerboard`.  **Returns:** the Figure.
    """
    from matplotlib.path import Path as Polygon

    inside = (lambda q: np.ones(len(q), bool)) if domain is None else \
        Polygon(np.asarray(domain, np.float64)).contains_points
    (u0, u1), (v0, v1) = surface.bbox
    grid = surface.sample(resolution)
    G = np.asarray(grid.vertices, np.float64)
    gF = np.asarray(grid.faces)
    ok = np.all(np.isfinite(G[gF]).reshape(len(gF), -1), axis=1)
    ok &= inside(np.asarray(grid.uv)[gF].mean(1))
    grey = np.array([0.85, 0.85, 0.85])
    rgba, r = _render(np.nan_to_num(G), gF[ok], lambda r: np.broadcast_to(grey, r.mask.shape + (3,)),
                      elev=elev, azim=azim, pixels=int(size * dpi))
    fig, ax = image_figure(rgba, title or f"iso-parameter curves of the {surface.kind} surface",
                           dpi=dpi)
    t = np.linspace(0, 1, samples)
    Hs, Ws = r.depth.shape
    finite = np.isfinite(r.depth)
    tolerance = 0.01 * float(np.ptp(r.depth[finite])) if finite.any() else 0.0
    for c in np.linspace(0, 1, lines):
        for uvs, color in (((u0 + c * (u1 - u0)) * np.ones_like(t), v0 + t * (v1 - v0)), "tab:blue"), \
                          ((u0 + t * (u1 - u0), (v0 + c * (v1 - v0)) * np.ones_like(t)), "tab:red"):
            q = np.column_stack(uvs)
            X = np.asarray(surface.evaluate(q), np.float64)
            S, z = r.project(X)
            good = np.all(np.isfinite(S), 1) & inside(q)
            ix = np.clip(np.nan_to_num(S[:, 0]).astype(int), 0, Ws - 1)
            iy = np.clip(np.nan_to_num(S[:, 1]).astype(int), 0, Hs - 1)
            seen = good & (z >= r.depth[iy, ix] - tolerance)
            S = np.where(seen[:, None], S / SUPERSAMPLE - 0.5, np.nan)   # imshow's pixel centres
            ax.plot(S[:, 0], S[:, 1], color=color, lw=0.9)
    h, w = rgba.shape[:2]
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    return finish(fig, path, dpi=dpi)
