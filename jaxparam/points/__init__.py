"""Unorganized points (survey §8): meshless parameterization, boundary detection, reconstruction.

Pipeline (numpy for the combinatorics, JAX for what depends on coordinates):

1. :func:`knn_graph`: the ``k`` nearest neighbours of every point (cKDTree),
   made symmetric by default (``w`` is ``v``'s neighbour when either lists the
   other).  Directed kNN graphs are often singular in practice: a cluster whose
   neighbours only point at each other never reaches the boundary (the
   solvability condition at the end of §8).
2. Tangent planes by a weighted, once-reweighted PCA of each point's 24 nearest
   neighbours (:func:`robust_frames`: holds under scanner noise); neighbours sorted by
   angle around the point in that plane (a star-shaped fan, so the point lies in the
   fan's kernel): :func:`point_graph`.  :func:`reconstruct_surface` first takes out the
   outliers, points far above the plane of their neighbours or isolated beyond it
   (:func:`find_outliers`), and can smooth the rest (``smooth="mls"``).
3. :func:`detect_boundary`: a point is a boundary candidate when the largest
   angular gap between its 24 nearest neighbours, projected, exceeds ``gap``
   (default ``0.7 pi``).  The candidates are ordered into one closed polygon by the
   longest path of their minimum spanning tree (a loop of points has a nearly
   path-shaped spanning tree; points on short branches are left interior).
   The survey leaves this step to [13]; users can pass ``boundary`` indices.
4. Weights on the fans (:func:`jaxparam.weights.fan_weights`): ``uniform`` and
   ``inverse_distance`` (spring weights, symmetric: a Cholesky solve), ``mean_value`` and
   ``shape_preserving`` (Floater's, on the fan of triangles ``(v, w_j, w_{j+1})``, 3D
   angles and lengths, so that everything is differentiable in the points).
5. The boundary on a circle or square (chord length), the interior by eq. (4) as for
   meshes (:mod:`jaxparam.combination`, the differentiable sparse solve):
   :func:`meshless_map`.

Step 2 also orients the normals consistently (signs propagated along a minimum spanning
tree of the neighbour graph, :mod:`.orientation`) and drops neighbour pairs that leave a
tangent plane steeply or join opposed normals (they join the two sides of parts thinner
than the spacing).  Large clouds are
processed in Morton (Z-curve) order and in blocks of points, for memory
locality; results come back in the input's order.

:func:`reconstruct_surface` triangulates the parameter points (Delaunay),
lifts the triangles to 3D, flips edges towards 3D Delaunay where the
parameter plane allows, peels off the hull triangles that bridge concave
parts of the boundary and the ears over boundary points the detector missed;
it returns a :class:`Reconstruction`.

Modules: :mod:`.defaults` (the default settings), :mod:`.graph` (neighbourhoods, robust
frames, fans, Morton order), :mod:`.orientation` (consistent normal signs),
:mod:`.outliers` (outlier test, dropping points from neighbour lists), :mod:`.smoothing`
(MLS / plane projection), :mod:`.boundary` (detection), :mod:`.meshless` (checks and the
map), :mod:`.triangulation` (Delaunay, flips, peeling of bridges, lone points, the largest
disk), :mod:`.reconstruct`.
"""
from __future__ import annotations

from ..io.points import load_points
from .boundary import detect_boundary
from .graph import Frames, PointGraph, knn_graph, point_graph, robust_frames
from .meshless import WEIGHTS, check_points, meshless_map
from .outliers import find_outliers
from .reconstruct import Reconstruction, reconstruct_surface
from .smoothing import SMOOTHING, smooth_points

__all__ = ["load_points", "check_points", "knn_graph", "PointGraph", "point_graph",
           "detect_boundary", "meshless_map", "reconstruct_surface", "Reconstruction", "WEIGHTS",
           "Frames", "robust_frames", "find_outliers", "SMOOTHING", "smooth_points"]
