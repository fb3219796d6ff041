"""A small z-buffered software rasterizer for surface pictures (numpy, vectorized).

An orthographic camera looks at the mesh from elevation ``elev`` and azimuth ``azim``
(degrees, as matplotlib's 3D axes take them); every pixel centre gets the nearest face
that covers it and its barycentric coordinates in that face.  Because the projection is
orthographic and both screen axes share one scale, a sphere is drawn round, and values
interpolated with the barycentric coordinates are exact per pixel (a texture through the
UVs has straight squares, not the staircase of per-face colours).

The faces are processed in chunks of candidate (face, pixel) pairs, so memory stays
bounded for meshes of any size.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..host import vertex_normals  # noqa: F401 - part of this module's interface

__all__ = ["Raster", "camera", "vertex_normals", "rasterize", "shading", "wire", "downsample"]

#: Candidate (face, pixel) pairs examined at once.
CHUNK_PAIRS = 4_000_000


@dataclass(frozen=True)
class Raster:
    """The visible face of every pixel of an ``(h, w)`` image.

    **Fields:** ``face: (h, w) int`` the visible face (-1: background); ``bary: (h, w, 3)``
    its barycentric coordinates at the pixel centre (0 on the background); ``depth: (h, w)`` the distance towards the camera
    (-inf on the background); ``screen:
    (n, 2)`` the vertices in pixel coordinates (x to the right, y down); ``view``
    ``(elev, azim)`` in degrees; ``frame`` ``(lo, scale, offset, h)`` of
    :func:`to_screen`.
    """

    face: np.ndarray
    bary: np.ndarray
    depth: np.ndarray
    screen: np.ndarray
    view: tuple
    frame: tuple

    @property
    def mask(self) -> np.ndarray:
        """``(h, w) bool``: pixels covered by the mesh."""
        return self.face >= 0

    def project(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(screen (k, 2), depth (k,))`` of 3D points ``X: (k, 3)`` in this picture."""
        P = np.asarray(X, np.float64) @ camera(*self.view).T
        return to_screen(P[:, :2], *self.frame), P[:, 2]

    def interpolate(self, F: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Per-vertex ``values: (n, k)`` interpolated at every pixel: ``(h, w, k)``
        (0 on the background)."""
        values = np.asarray(values, np.float64)
        idx = np.flatnonzero(self.mask)
        f = self.face.reshape(-1)[idx]
        b = self.bary.reshape(-1, 3)[idx]
        out = np.zeros((self.face.size, values.shape[1]))
        out[idx] = sum(b[:, c, None] * values[F[f, c]] for c in range(3))
        return out.reshape(*self.face.shape, values.shape[1])


def camera(elev: float, azim: float) -> np.ndarray:
    """``(3, 3)`` rows: screen right, screen up, towards the camera, for a view from
    elevation ``elev`` and azimuth ``azim`` in degrees (matplotlib's convention)."""
    e, a = np.radians(elev), np.radians(azim)
    toward = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    right = np.array([-np.sin(a), np.cos(a), 0.0])
    up = np.cross(toward, right)
    return np.stack([right, up, toward])


def _frame(S: np.ndarray, pixels: int, margin: float):
    """Scale and offset that fit the projected points ``S: (k, 2)`` into an image whose
    longer side has ``pixels`` pixels, with ``margin`` (a fraction) around; and its size."""
    lo, hi = S.min(0), S.max(0)
    span = np.maximum(hi - lo, 1e-300)
    scale = (pixels * (1 - 2 * margin)) / span.max()
    size = np.maximum(np.ceil(span * scale / (1 - 2 * margin)).astype(int), 1)
    offset = (size - span * scale) / 2
    return lo, scale, offset, (int(size[1]), int(size[0]))


def to_screen(S: np.ndarray, lo, scale: float, offset, h: int) -> np.ndarray:
    """Pixel coordinates ``(k, 2)`` (x right, y down) of projected points ``S: (k, 2)``."""
    return np.column_stack([(S[:, 0] - lo[0]) * scale + offset[0],
                            h - ((S[:, 1] - lo[1]) * scale + offset[1])])


def rasterize(V: np.ndarray, F: np.ndarray, *, elev: float = 30, azim: float = -60,
              pixels: int = 900, margin: float = 0.02) -> Raster:
    """Rasterize the triangles ``V[F]`` (``V: (n, 3)``, ``F: (m, 3)``) seen from
    (``elev``, ``azim``) into an image whose longer side has ``pixels`` pixels; the mesh
    fills it up to ``margin`` (a fraction of the side) on its longer extent.

    **Returns:** a :class:`Raster`.  Faces are two-sided (an open surface shows its back);
    faces with non-finite vertices are skipped.
    """
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    R = camera(elev, azim)
    P = V @ R.T                                   # (n, 3): right, up, toward the camera
    good = np.all(np.isfinite(P[F]).reshape(len(F), -1), axis=1)
    used = np.unique(F[good])
    if used.size == 0:
        return Raster(-np.ones((1, 1), int), np.zeros((1, 1, 3)), np.full((1, 1), -np.inf),
                      np.zeros((len(V), 2)), (elev, azim),
                      (np.zeros(2), 1.0, np.zeros(2), 1))
    lo, scale, offset, (h, w) = _frame(P[used, :2], pixels, margin)
    screen = to_screen(P[:, :2], lo, scale, offset, h)
    depth = np.full(h * w, -np.inf)
    face = np.full(h * w, -1, np.int64)
    bary = np.zeros((h * w, 3))
    faces = np.flatnonzero(good)
    T = screen[F[faces]]                          # (m', 3, 2)
    coef = _affine(T, P[F[faces], 2])             # (m', 3, 3): l1, l2, z as a x + b y + c
    x0 = np.clip(np.ceil(T[..., 0].min(1) - 0.5), 0, w).astype(np.int64)
    x1 = np.clip(np.floor(T[..., 0].max(1) - 0.5), -1, w - 1).astype(np.int64)
    y0 = np.clip(np.ceil(T[..., 1].min(1) - 0.5), 0, h).astype(np.int64)
    y1 = np.clip(np.floor(T[..., 1].max(1) - 0.5), -1, h - 1).astype(np.int64)
    bw, bh = np.maximum(x1 - x0 + 1, 0), np.maximum(y1 - y0 + 1, 0)
    count = bw * bh
    keep = (count > 0) & np.all(np.isfinite(coef).reshape(len(faces), -1), axis=1)
    faces, coef, x0, y0, bw, bh, count = (a[keep] for a in (faces, coef, x0, y0, bw, bh, count))
    ends = np.cumsum(count)
    start = 0
    while start < len(faces):
        stop = int(np.searchsorted(ends, (ends[start - 1] if start else 0) + CHUNK_PAIRS,
                                   side="right"))
        stop = max(stop, start + 1)
        s = slice(start, stop)
        _chunk(faces[s], coef[s], x0[s], y0[s], bw[s], bh[s], w, depth, face, bary)
        start = stop
    return Raster(face.reshape(h, w), bary.reshape(h, w, 3), depth.reshape(h, w), screen,
                  (elev, azim), (lo, scale, offset, h))


def _affine(T: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """``(m, 3, 3)``: for each triangle ``T: (m, 3, 2)`` with depths ``Z: (m, 3)``, the
    coefficients ``(a, b, c)`` of the barycentric coordinates 1 and 2 and of the depth
    as affine functions ``a x + b y + c`` of the pixel position (inf for a triangle of
    zero screen area)."""
    ax, ay = T[:, 0, 0], T[:, 0, 1]
    ux, uy = T[:, 1, 0] - ax, T[:, 1, 1] - ay
    vx, vy = T[:, 2, 0] - ax, T[:, 2, 1] - ay
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / (ux * vy - vx * uy)
        # l1 = ((x-ax) vy - (y-ay) vx) / den ; l2 = ((y-ay) ux - (x-ax) uy) / den
        l1 = np.stack([vy * inv, -vx * inv, (-ax * vy + ay * vx) * inv], 1)
        l2 = np.stack([-uy * inv, ux * inv, (-ay * ux + ax * uy) * inv], 1)
        dz1, dz2 = Z[:, 1] - Z[:, 0], Z[:, 2] - Z[:, 0]
        z = dz1[:, None] * l1 + dz2[:, None] * l2
        z[:, 2] += Z[:, 0]
    return np.stack([l1, l2, z], 1)


def _chunk(faces, coef, x0, y0, bw, bh, w, depth, face, bary) -> None:
    """Rasterize ``faces`` (their affine ``coef`` and pixel boxes) into the flat buffers
    ``depth``, ``face``, ``bary``: the nearest face wins each pixel."""
    rows = np.repeat(np.arange(faces.size), bh)               # one entry per box row
    row_y = y0[rows] + (np.arange(rows.size) - np.repeat(np.cumsum(bh) - bh, bh))
    k = np.repeat(rows, bw[rows])                             # local face of each pair
    width = bw[rows]
    px = np.arange(k.size) - np.repeat(np.cumsum(width) - width, width) + np.repeat(x0[rows], width)
    py = np.repeat(row_y, width)
    x, y = px + 0.5, py + 0.5
    c = [np.ascontiguousarray(coef[:, i // 3, i % 3])[k] for i in range(6)]
    l1 = c[0] * x + c[1] * y + c[2]
    l2 = c[3] * x + c[4] * y + c[5]
    l0 = 1 - l1 - l2
    eps = -1e-9
    inside = np.flatnonzero((l0 >= eps) & (l1 >= eps) & (l2 >= eps))
    k, l0, l1, l2 = k[inside], l0[inside], l1[inside], l2[inside]
    x, y = x[inside], y[inside]
    z = coef[k, 2, 0] * x + coef[k, 2, 1] * y + coef[k, 2, 2]
    pix = (py[inside] * w + px[inside])
    np.maximum.at(depth, pix, z)                              # the nearest depth per pixel
    win = np.flatnonzero(z == depth[pix])                     # (an exact tie: either face)
    pix = pix[win]
    face[pix] = faces[k[win]]
    bary[pix] = np.column_stack([l0[win], l1[win], l2[win]])


def shading(raster: Raster, F: np.ndarray, normals: np.ndarray, *,
            light=(0.35, 0.45, 0.82), ambient: float = 0.3) -> np.ndarray:
    """``(h, w)`` brightness in [ambient, 1]: two-sided Lambert shading of the per-pixel
    interpolated vertex ``normals: (n, 3)`` under a light fixed to the camera (``light``
    in screen coordinates: right, up, towards the camera), plus a little specular."""
    n = raster.interpolate(F, normals)
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    R = camera(*raster.view)
    L = np.asarray(light, np.float64) @ R
    L /= np.linalg.norm(L)
    ndl = np.abs(n @ L)
    half = L + R[2]
    half /= np.linalg.norm(half)
    spec = np.abs(n @ half) ** 40
    return np.clip(ambient + (1 - ambient) * ndl + 0.15 * spec, 0, 1.0)


def wire(raster: Raster, F: np.ndarray, width: float = 1.0) -> np.ndarray:
    """``(h, w)`` in [0, 1]: how much each pixel lies on a visible edge of its face (1 on
    the edge, fading to 0 at ``width`` pixels from it)."""
    f = np.where(raster.face >= 0, raster.face, 0)
    T = raster.screen[F[f]]                                   # (h, w, 3, 2)
    e = np.roll(T, -1, axis=2) - np.roll(T, 1, axis=2)        # edge opposite each corner
    d1, d2 = T[..., 1, :] - T[..., 0, :], T[..., 2, :] - T[..., 0, :]
    area2 = np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
    alt = area2[..., None] / np.maximum(np.linalg.norm(e, axis=-1), 1e-300)
    d = np.min(raster.bary * alt, axis=-1)                    # pixels to the nearest edge
    return np.where(raster.mask, np.clip(1 - d / width, 0, 1), 0.0)


def downsample(img: np.ndarray, factor: int) -> np.ndarray:
    """Average ``factor x factor`` blocks of ``img: (h, w, ...)`` (anti-aliasing of a
    supersampled picture); the size is cropped to a multiple of ``factor``."""
    if factor == 1:
        return img
    h, w = img.shape[0] // factor * factor, img.shape[1] // factor * factor
    img = img[:h, :w]
    return img.reshape(h // factor, factor, w // factor, factor, *img.shape[2:]).mean((1, 3))
