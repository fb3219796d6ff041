"""What every picture shares: the figure (no backend forced), saving, robust colour limits,
and the flipped/degenerate count of a UV map."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import metrics, tol
from ..errors import MeshError
from ..io import as_mesh, atomic_write

__all__ = ["DPI", "new_figure", "finish", "RobustLimits", "robust_limits", "FaceStates",
           "face_states"]

#: Default resolution of every picture, in dots per inch.
DPI = 150


def mesh_and_uv(mesh, uv, where: str):
    """``(TriMesh, uv (n, 2) float64)`` of a plotting function's arguments: ``mesh`` anything
    :func:`~jaxparam.io.as_mesh` takes (a ``(V, F)`` pair too); raises :class:`MeshError`
    naming ``where`` when ``uv`` is not one row per vertex (session 21: an ``IndexError``)."""
    mesh = as_mesh(mesh, where)
    U = np.asarray(uv, np.float64)
    if U.shape != (mesh.n_vertices, 2):
        raise MeshError(f"{where}: uv must have shape ({mesh.n_vertices}, 2), one row per vertex, "
                        f"got {U.shape}.")
    return mesh, U


def new_figure(size: tuple[float, float], dpi: int = DPI):
    """A matplotlib Figure of ``size`` inches at ``dpi``, made through pyplot so that
    ``plt.show()`` and Jupyter display it; the backend is whatever matplotlib chose
    (this module never calls ``matplotlib.use``)."""
    import matplotlib.pyplot as plt

    return plt.figure(figsize=size, dpi=dpi)


def finish(fig, path=None, *, dpi: int = DPI):
    """Save ``fig`` to ``path`` when given (the format from its extension, PNG when it has
    none; written all or nothing through :func:`jaxparam.io.atomic_write`), and return
    ``fig``."""
    if path is not None:
        path = Path(path)
        fmt = path.suffix.lstrip(".").lower() or "png"
        atomic_write(path, lambda f: fig.savefig(f, format=fmt, dpi=dpi, bbox_inches="tight",
                                                 pad_inches=0.05), mode="wb")
    return fig


@dataclass(frozen=True)
class RobustLimits:
    """Colour limits set by percentiles, so a few outliers cannot wash the picture out.

    **Fields:** ``vmin``, ``vmax`` the limits; ``below``, ``above`` the share (0..1) of the
    finite values outside them; ``extend`` matplotlib's colorbar ``extend`` for that.
    """

    vmin: float
    vmax: float
    below: float
    above: float

    @property
    def extend(self) -> str:
        lo, hi = self.below > 0, self.above > 0
        return "both" if lo and hi else "min" if lo else "max" if hi else "neither"

    def label(self, text: str) -> str:
        """``text`` with the clipped share said: ``"log2 area ratio (3.1 % of faces beyond
        the scale)"``; ``text`` alone when nothing is clipped."""
        share = self.below + self.above
        return text if share == 0 else f"{text} ({100 * share:.2g} % of faces beyond the scale)"


def robust_limits(values: np.ndarray, *, percentile: float = 98.0,
                  symmetric: bool = False, floor: float | None = None,
                  fence: float = 3.0) -> RobustLimits:
    """Limits from the finite ``values`` that a few outliers cannot stretch.

    The upper limit is the ``percentile`` of the values (of ``|values|`` with
    ``symmetric``), or Tukey's far fence ``q3 + fence * (q3 - q1)`` when that is lower (a
    heavy tail of slivers above the bulk, as a reconstruction has); the lower limit is
    ``floor`` when given, ``-upper`` with ``symmetric``, else the mirrored percentile and
    fence.  The range is at least 1e-3 wide.
    """
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return RobustLimits(0.0, 1.0, 0.0, 0.0)
    w = np.abs(v) if symmetric else v
    q1, q3 = np.percentile(w, [25, 75])
    hi = float(min(np.percentile(w, percentile), q3 + fence * (q3 - q1)))
    if symmetric:
        lo = -hi
    elif floor is not None:
        lo = float(floor)
    else:
        lo = float(max(np.percentile(v, 100 - percentile), q1 - fence * (q3 - q1)))
    hi = max(hi, lo + 1e-3)
    if symmetric:
        lo = -hi
    return RobustLimits(lo, hi, float(np.mean(v < lo)), float(np.mean(v > hi)))


@dataclass(frozen=True)
class FaceStates:
    """Faces of a UV map by state.

    **Fields:** ``flipped: (m,) bool`` UV image clockwise (signed area below minus the
    degeneracy threshold); ``degenerate: (m,) bool`` UV area of magnitude at most
    ``tol.DEGENERATE_AREA_REL`` times the mean face area (or not finite);
    ``area_uv: (m,)`` the signed UV areas.
    """

    flipped: np.ndarray
    degenerate: np.ndarray
    area_uv: np.ndarray

    def caption(self) -> str:
        """``"0 flipped, 2 degenerate"``."""
        return f"{int(self.flipped.sum())} flipped, {int(self.degenerate.sum())} degenerate"


def face_states(mesh, uv) -> FaceStates:
    """Count the flipped and the degenerate faces of ``uv: (n, 2)`` apart: a zero-area face
    (three boundary vertices on one side of a square, say) is degenerate, not flipped."""
    a = np.asarray(metrics.face_distortion(mesh, uv)["area_uv"], np.float64)
    finite = np.isfinite(a)
    scale = np.mean(np.abs(a[finite])) if finite.any() else 0.0
    degenerate = ~finite | (np.abs(a) <= tol.DEGENERATE_AREA_REL * scale)
    return FaceStates(flipped=finite & ~degenerate & (a < 0), degenerate=degenerate, area_uv=a)
