"""The default settings of the point pipeline, each named once.

:func:`~jaxparam.points.point_graph`, :func:`~jaxparam.points.detect_boundary`,
:func:`~jaxparam.points.meshless_map` and :func:`~jaxparam.points.reconstruct_surface` take
their defaults from here, so that changing one changes it everywhere.
"""
from __future__ import annotations

import math

__all__ = ["K", "K_DETECT", "K_FRAME", "GAP", "MAX_SLOPE", "MIN_NORMAL_DOT", "BRIDGE_FACTOR",
           "HOLE_SHARE", "HOLE_INRADIUS", "HOLE_FACES", "HOLE_REFERENCE_POINTS", "FLIP_ROUNDS",
           "OUTLIER_SCALE", "OUTLIER_HEIGHT", "OUTLIER_ISOLATION",
           "OUTLIER_ROUNDS", "OUTLIER_MIN_NEIGHBOURS", "EAR_MAX_BASE",
           "CHORD_TOL", "CHORD_ROUNDS"]

#: Nearest neighbours per point in the map's fans (survey §8's ``k``).
K = 10

#: Nearest neighbours whose angular gap decides whether a point is on the boundary: more than
#: the map's ``K``, since random samplings leave wide gaps in small neighbourhoods.
K_DETECT = 24

#: Nearest neighbours of the weighted (robust) PCA that gives every point its tangent frame: more
#: than the fans' ``K``, so that noise of a fraction of the spacing barely tilts the planes.
K_FRAME = 24

#: Angular gap (radians) above which a point is a boundary candidate: ``0.7 pi``.
GAP = 0.7 * math.pi

#: Largest ``|n . d| / |d|`` of a neighbour pair ``d`` against either point's normal ``n``
#: (about 37 degrees): steeper pairs join the two sides of parts thinner than the spacing.
MAX_SLOPE = 0.6

#: Smallest ``n_v . n_w`` of a neighbour pair's consistently oriented normals: pairs with
#: opposed normals (more than 90 degrees apart) cross between two sheets and leave the graph.
MIN_NORMAL_DOT = 0.0

#: A hull face of the reconstruction whose longest 3D edge exceeds this many local point
#: spacings bridges a concave part of the boundary and is peeled off.
BRIDGE_FACTOR = 3.0

#: A group of too-long faces inside the reconstruction opens a hole when it has at least
#: ``HOLE_FACES`` faces, at least ``HOLE_SHARE`` of its vertices see an angular gap (the edge
#: of a hole in the scan), and its fattest face's inradius is at least ``HOLE_INRADIUS``
#: local spacings (an empty disk, not a sliver) times ``sqrt(ln N / ln HOLE_REFERENCE_POINTS)``
#: for ``N`` points above ``HOLE_REFERENCE_POINTS`` (the largest empty disk of a random sample
#: grows so, in spacings).  Measured at 8k and 20k points (session 21, ``benchmarks/
#: points.py --holes`` sets): the sampled holes' groups have 4-20 faces, shares 0.6-1.0 and
#: inradii 0.81-2.5; the groups of sets without holes, shares of 0.5 or more only with inradii
#: of 0.06-0.65 (slivers by outliers and sparse patches), or 2 faces (0.75, 0.83: a gap in a
#: clean sample).  At 1M uniform random points two gaps passed 3 faces, share 0.5 and 0.75
#: spacings ((4 faces, 0.5, 0.90), (3, 0.6, 0.76)): hence 4 faces, 0.55 and the scaling (0.93
#: at 1M).
HOLE_SHARE = 0.55
HOLE_INRADIUS = 0.75
HOLE_FACES = 4
HOLE_REFERENCE_POINTS = 8000

#: Most rounds of independent 3D Delaunay edge flips in the reconstruction.
FLIP_ROUNDS = 100

#: A point is an outlier when its height above the plane of its ``K_FRAME`` nearest neighbours
#: exceeds this many robust noise scales of those neighbours (1.48 times their median height) ...
OUTLIER_SCALE = 6.0

#: ... and this fraction of their RMS distance from it within that plane (so that a clean,
#: curved surface keeps every point) ...
OUTLIER_HEIGHT = 0.5

#: ... or when the mean distance to its 4 nearest neighbours exceeds this many times the median
#: of the same over its neighbours (a point isolated off the surface, near its tangent plane).
OUTLIER_ISOLATION = 2.5

#: Rounds of the outlier test at most (each on the points the previous one kept: outliers close
#: to each other inflate each other's neighbourhoods in the first; the rounds stop at the first
#: that finds none).  A cluster of three planted outliers within 2 % of the diagonal of each
#: other took three rounds on two 50k-point scans (camelhead, snail: found 494 + 7 + 1 and
#: 490 + 33 + 1); with two the last one stayed a vertex, 3-5 % off the surface.
OUTLIER_ROUNDS = 4

#: Fewest neighbours per point the outlier test needs (a point set of fewer than this many plus
#: one points has none): a plane fits three points exactly, so with a handful of neighbours their
#: robust noise scale is rounding and every point of a curved or random set stood "far above" it
#: (4 points: heights of 1e11 noise scales).  Random 4-8-point sets lost most of their points
#: that way, leaving too few for the map.
OUTLIER_MIN_NEIGHBOURS = 8

#: An ear (a boundary face over a notch whose apex the detection missed) is peeled only when
#: its boundary edge is at most this many of the apex's spacings: longer, the boundary is
#: sparse there and the face covers the surface.
EAR_MAX_BASE = 1.1

#: An interior point of the map lies on a chord of the boundary polygon when its distance from
#: the chord is at most this fraction of the chord's length: Delaunay gives it a face of zero
#: area there (:func:`~jaxparam.points.triangulation.onto_chords` puts it on the boundary).
CHORD_TOL = 1e-9

#: Most times the map is solved again with such points put on the boundary.
CHORD_ROUNDS = 4

#: The least median spread of the points' neighbourhoods (second over first singular value of
#: each one's k nearest neighbours, :func:`~jaxparam.points.meshless.neighbourhood_spread`)
#: that a surface sample has.  Points along a curve were mapped with exit 0 to a few
#: zero-area faces (the held-out sweep, session 26).  With k = 10: a circle of 300 points
#: 0.029, a helix of 2,000 random points 0.013; the same circle with 1 % noise 0.165 (a band);
#: camelhead.xyz 0.80, bump-domain-half.xyz 0.75, a uniform planar sample 0.70, a sphere's
#: noisy vertices 0.81.
MIN_SPREAD = 0.1
