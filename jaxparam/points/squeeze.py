"""Whether the meshless map squeezed most of the surface into nothing: what a disk map does to
a point set that samples a closed surface, or an open one whose boundary the detector found
only in part (a short loop around a sharp spot, a slit whose two sides touch).  Numpy on
concrete arrays."""
from __future__ import annotations

import numpy as np

from ..host import face_areas

__all__ = ["SqueezedMapWarning", "squeezed_share", "SQUEEZE", "SQUEEZED_SHARE", "squeeze_message"]

#: A face is squeezed when its share of the parameter domain's area is below this fraction
#: of its share of the 3D area.
SQUEEZE = 1e-3
#: The share of squeezed faces above which :func:`~jaxparam.reconstruct_surface` refuses the
#: map it made from a detected boundary (and warns about one made from the user's
#: ``boundary_indices``).  Measured on the first Delaunay faces (session 18, issue 14): open
#: scans of the shared disk meshes (camelhead, lilium, snail, bump-domain; 8k and 20k points,
#: noise, eightfold density, outliers) 0-0.12, camelhead.xyz 0.09 (its head, far from the neck's
#: boundary, is compressed); samples of closed meshes (bunny, cow, decimated-knight,
#: rocker-arm, bumpy, a torus) and of camel_b (a camel cut open along a slit whose sides touch)
#: 0.30-0.99.  Session 27, held out: 8k samples of camelhead, lilium and camel_b, clean, with
#: noise 0.1-0.5 %, tenfold density, 1-3 % outliers, scaled 1e-4, moved 1e6: camelhead
#: 0.066-0.097, lilium 0; camel_b 0.83-0.91 (returned with a warning until then: 1,000-2,000 of
#: its points dropped as "outliers" of a map that had squeezed them); strips of 5:1 to 40:1, a
#: hemisphere, a sphere with a small hole 0; points on a sphere 0.31, on 3holes 0.52.
SQUEEZED_SHARE = 0.2


class SqueezedMapWarning(UserWarning):
    """The meshless map squeezed most faces to nothing: the points are not a disk it can map
    (raised as a warning only for a map from the user's ``boundary_indices``; a detected
    boundary's is refused with :class:`~jaxparam.PointCloudError`)."""


def squeezed_share(F: np.ndarray, P: np.ndarray, U: np.ndarray, squeeze: float = SQUEEZE,
                   most: int = 200_000) -> float:
    """The share of the faces ``F (m, 3)`` whose parameter area ``U (n, 2)``, as a share of
    the total, is below ``squeeze`` times their 3D area ``P (n, 3)`` as a share of its total
    (0 for no faces or no area).  Above ``most`` faces, measured on every ``ceil(m / most)``-th
    (at 1M points the whole measure took 1.7 s; the estimate is within a few tenths of a
    percent of the share, far finer than the warning's threshold)."""
    F = np.asarray(F)
    if F.shape[0] == 0:
        return 0.0
    F = F[::-(-F.shape[0] // most)]
    a2, a3 = face_areas(U, F), face_areas(P, F)
    if not (a2.sum() > 0 and a3.sum() > 0):
        return 0.0
    return float(np.mean(a2 / a2.sum() < squeeze * a3 / a3.sum()))


def squeeze_message(share: float, boundary_size: int, n_points: int, *, detected: bool = False) -> str:
    """The text of the refusal (``detected``: the boundary was detected) or of the warning
    (the user's boundary): what was measured, the likely cause and what to do."""
    where = ("The points seem to sample a closed surface (or one cut open along a slit whose "
             "sides touch), or the boundary was found only in part" if detected else
             "The boundary_indices given may not go around the whole surface, or the points "
             "sample a closed surface")
    then = ("; no mesh is made. " if detected else
            ": the UVs are unusable there and faces may bridge across the surface. ")
    return (f"reconstruct_surface: the map squeezed {100 * share:.0f} % of the triangles to less "
            f"than 1/{1 / SQUEEZE:.0f} of their share of the area (the boundary it used has "
            f"{boundary_size} of the {n_points} points). {where}{then}"
            "A meshless map needs a disk-like point set: cut the surface open, or pass "
            "boundary_indices (a closed loop around the whole surface) yourself.")
