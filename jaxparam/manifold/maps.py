"""MAPS route of :mod:`jaxparam.manifold` (Lee et al. 1998, the survey's ref. [20]): the base
domain and the map onto it, built together during the decimation, so no path is ever blocked.

The decimation runs in *levels*.  Each level picks a set of half-edge collapses ``u -> w``
(quadric error, Garland and Heckbert) whose closed one-rings do not meet, and does them all
at once (vectorized).  Before a collapse, ``u``'s one-ring is flattened conformally
(``z -> z^a``, ``a = 2 pi / Theta_u``, Theta_u the sum of ``u``'s corner angles); the
collapse is allowed only when every new triangle ``(w, r_j, r_{j+1})`` is positive in that
plane, so the new triangles tile the same flat polygon as the old ones.  Every point (an
input vertex) held by a face of the ring, ``u`` itself included, is placed in the flat ring
by its barycentric coordinates and located in the new triangles.  At the end every input
vertex has a base face and barycentric coordinates there: ``phi^{-1}`` of the vertex, a
bijection onto the base domain up to rounding (each step is a bijection of the flat ring).

A collapse keeps its surviving vertex where it is (``V^0 ⊂ V``); the link condition keeps
the genus; while possible a collapse may not tilt a face by more than about 78 degrees,
leave a corner over 150 degrees, or flatten a ring whose exponent ``a`` is off 1 by more
than about 3.5 % (sharply curved vertices, whose flattening distorts the map most, stay in
the base domain: this took bunny's level-4 remesh from 1.7 % to 0.9 % of the diagonal).
The rules are relaxed step by step (the bound on ``|log a|`` doubling each time, so the tips
of thin parts go last), then dropped, when no collapse is left.  Optionally an area cap
(:data:`AREA_CAPS`) bounds the input area a new face may hold, relaxed in doubling steps
before the rules are; :func:`~jaxparam.manifold.manifold_map` decimates with each cap and keeps
the base domain estimated closest.  The levels are kept
(:class:`MapsHistory`) so points of the base domain can be pulled back exactly.  Work per level is proportional to the faces left, and each level removes a
fixed share of the vertices, so the whole decimation costs about linear time.
"""
from __future__ import annotations

import numpy as np

from .. import topology as topo
from ..errors import SolverError
from ..host import face_areas
from ..progress import progress
from .decimate import plane_quadrics
from .noise import NOISE_SMOOTHING_STEPS, decision_positions, noise_dominates

__all__ = ["maps_decimate", "decimate_caps", "MapsHistory", "noise_dominates", "decision_positions",
           "NOISE_SMOOTHING_STEPS"]

#: A ring whose widest wedge in Lee et al.'s flattening reaches this multiple of pi is flattened
#: with angles blended towards equal ones, until the widest is :data:`WEDGE_CAP` pi.
WIDE_WEDGE = 0.9
WEDGE_CAP = 0.8

#: Rules a collapse must pass, strictest first: (cosine bound of a face's tilt, cosine of the
#: largest corner allowed in a new face, largest ``|log a|`` of the ring's flattening exponent
#: ``a``: sharply curved vertices, whose flattening distorts most, stay while others go).  The
#: bound on ``|log a|`` is relaxed in doubling steps, so the most curved vertices (the tips of
#: thin parts) go last and stay in the base domain: a single step from 0.035 to 2 let the thin
#: parts of cow and decimated-knight be squeezed into slivers of base triangles (level 4 at 100 base
#: faces, % of the diagonal: cow 4.6 -> 1.3, decimated-knight 10.2 -> 1.2, bunny 0.86 -> 0.83,
#: 3holes 0.28 -> 0.34, rocker-arm 0.55 -> 0.70).  The last levels of rules keep only what the
#: map needs (positive triangles in the flattened ring) and a face that does not turn over.
#: The fourth number bounds the ring's widest wedge in Lee et al.'s flattening (a multiple of
#: pi, :data:`WIDE_WEDGE` but at the last level): under pi the ring flattens to a star around
#: the vertex, and 0.9 pi keeps a margin.  At the last level any ring goes, the wide ones
#: flattened with blended angles (:class:`_Level`): a mesh scaled along one axis (bunny with
#: z x 20, 3holes with z x 0.05) has rings of needle triangles whose wedges flatten wider than
#: 0.9 pi at every vertex, and its decimation stopped at 3040 (bunny) faces of the 100 asked;
#: bunny itself stopped at 8 of 4.  Allowing Lee et al.'s wedges up to 0.97-0.9999 pi instead
#: reached the counts, but the near-flat wedges put input vertices up to 0.4 % of the diagonal
#: off their own place through the map (session 21).
_RULES = ((0.2, np.cos(np.radians(150.0)), 0.035, WIDE_WEDGE),
          (0.2, np.cos(np.radians(150.0)), 0.07, WIDE_WEDGE),
          *((0.0, np.cos(np.radians(170.0)), b, WIDE_WEDGE) for b in (0.15, 0.3, 0.6, 1.2, 2.0)),
          (-0.999, -2.0, np.inf, WIDE_WEDGE), (-0.999, -2.0, np.inf, np.inf))

#: The levels of :data:`_RULES` tried with the area cap on (all but the last): when the last
#: of them passes no collapse the cap goes, and only then the wide rings (so a decimation that
#: never needed them makes the same collapses as before they were added).
_CAPPED_RULES = len(_RULES) - 1


#: Weight of the ring-area term of a collapse's cost against the (normalized) quadric error
#: (MAPS's priority; 0: off, measured worse on bunny: 1.7 % -> 2.2-4.3 % at level 4).
AREA_WEIGHT = 0.0

#: The area caps :func:`maps_decimate` can balance the base domain with, ``(factor, doublings,
#: reset)``: a collapse may not leave a new face holding more than ``factor * 2**k`` times the
#: mean base face's share of the input's area (the held area of the flattened ring, spread
#: evenly over it); ``k`` starts at 0, grows by one when no collapse passes (at most
#: ``doublings`` times) before the shape and curvature rules are relaxed, and is set back to at
#: most ``reset`` when they are.  Without a cap, quadric collapses let flat parts grow without
#: bound (cow: one base face held 4.5x the mean share at 1,122 faces, 13.4x at the end).
#: ``None``: no cap.  The fourth, ``(1.5, 1, 0)``, added in session 25: the choice keeps it
#: where it is estimated closest, and the level-4 remesh at 100 base faces (grid 1/8, % of the
#: diagonal) went decimated-knight 0.572 -> 0.459, a CAD torus 0.232 -> 0.190, a sheared
#: bunny 0.431 -> 0.427, no mesh farther (benchmarks/README.md); a fifth, ``(1.2, 3, 1)``,
#: chose worse on bunny (0.370 -> 0.438).
AREA_CAPS = (None, (1.5, 3, 1), (1.5, 2, 0), (1.5, 1, 0))

#: Luby rounds per level (each adds collapses whose rings miss the ones already taken).
ROUNDS = 4

#: A decimation that stalls (``STALL_LEVELS`` levels in a row each collapsing under
#: ``STALL_SHARE`` of the faces left, with over ``STALL_FAR`` times the base faces left) lets
#: collapses share a ring vertex of degree ``HUB_DEGREE`` or more from then on (their faces
#: stay disjoint).  A capsule of 2000 x 3 sliver quads (12,000 faces) had every vertex next
#: to a pole of valence 2000 and collapsed 2 a level for 3,918 levels (121 s); no shared or
#: held-out mesh has a stall longer than 18 levels, so their decimations are unchanged.
STALL_LEVELS, STALL_SHARE, STALL_FAR, HUB_DEGREE = 32, 0.005, 8, 16

#: A decimation that has no collapse left under its rules first tries the *tiny* rings, those
#: holding under ``TINY_RING`` times the level's mean face area, with the shape rules dropped
#: (a face's tilt, its largest corner, the widest wedge; the curvature bound, the link condition
#: and the flattened ring's positive triangles kept), before it relaxes the area cap or the
#: rules for every ring.  A dense input made of flat pieces (cow refined twice by midpoint
#: splits, 88k faces) kept clusters of tiny faces at its creases and tips, where no collapse
#: passes the shape rules, until the last levels: 70 of its 100 base faces held under 1 % of
#: the mean base face's area, each of them 4^j remesh faces, and the level-4 remesh lay 2.6 %
#: of the diagonal off (0.64 % with the tiny rings let go; benchmarks/README.md, session 29).
TINY_RING = 0.1


def _segment_ids(ptr: np.ndarray) -> np.ndarray:
    return np.repeat(np.arange(ptr.size - 1), np.diff(ptr))


class _Level:
    """The rings of the current mesh (one :func:`topology.build` per level) and the flattened
    one-ring of every vertex."""

    def __init__(self, V, F, alive_faces, n):
        self.slots = alive_faces                              # global face slot of each row
        t = topo.build(F[alive_faces], n, where="manifold_map")
        self.t = t
        self.ptr, self.nbr, self.row = t.ring_ptr, t.ring_idx, t.ring_row
        self.deg = np.diff(self.ptr)
        self.pos = np.arange(self.nbr.size) - self.ptr[self.row]     # place in its ring
        self.nxt = self.ptr[self.row] + (self.pos + 1) % np.maximum(self.deg[self.row], 1)
        # The face of wedge j (u, r_j, r_{j+1}) and the corner of u in it (global slots).
        wedge = t.ring_wedge
        self.face = alive_faces[wedge // 3]
        self.corner = wedge % 3
        # Conformal flattening of each ring (Lee et al. eq. (1)): angles at u, scaled to 2 pi.
        e = V[self.nbr] - V[self.row]
        en = e[self.nxt - 0]
        d0 = np.linalg.norm(e, axis=1)
        cosang = np.einsum("ij,ij->i", e, en) / np.maximum(d0 * d0[self.nxt], 1e-300)
        theta = np.arccos(np.clip(cosang, -1.0, 1.0))
        total = np.bincount(self.row, weights=theta, minlength=n)
        a = 2.0 * np.pi / np.maximum(total, 1e-300)
        # A ring flattens to a star around u only when every scaled wedge is under pi.
        self.widest = np.zeros(n)
        np.maximum.at(self.widest, self.row, a[self.row] * theta)
        # A ring whose widest scaled wedge reaches WIDE_WEDGE pi (needle triangles) has its
        # wedge angles blended towards equal ones until the widest is WEDGE_CAP pi, and its
        # radii unscaled: still a piecewise-linear flattening, wedge by wedge, no longer
        # conformal (the rules take such rings only at the last level; the others keep Lee et
        # al.'s).  On bunny with z x 20 the map then runs back to the input vertices within
        # 6e-4 of the diagonal (1.8e-2 with the radii scaled, r ** a; 1e-12 on well-shaped
        # meshes).
        d = np.maximum(self.deg, 1)
        t = np.where(self.widest >= WIDE_WEDGE * np.pi,
                     (self.widest - WEDGE_CAP * np.pi) / np.maximum(self.widest - 2.0 * np.pi / d, 1e-300), 0.0)
        t = np.clip(t, 0.0, 1.0)[self.row]
        scaled = (1.0 - t) * a[self.row] * theta + t * (2.0 * np.pi / d[self.row])
        start = np.cumsum(scaled) - scaled
        phi = start - start[self.ptr[self.row]]
        rho = np.maximum(d0, 1e-300) ** np.where(t > 0, 1.0, a[self.row])
        self.z = np.stack([rho * np.cos(phi), rho * np.sin(phi)], 1)   # (nnz, 2)
        self.log_a = np.abs(np.log(np.maximum(a, 1e-300)))
        wedge_area = 0.5 * np.linalg.norm(np.cross(e, en), axis=1)
        self.ring_area = np.bincount(self.row, weights=wedge_area, minlength=n)


def _orient(p, q, r):
    return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])


def _pairs(L: _Level, heads: np.ndarray):
    """For half-edges ``heads`` (ring entries u -> w = r_k), every wedge j of u's ring that
    survives the collapse (j not k - 1, k).  **Returns** ``(h, j)`` entry indices."""
    u = L.row[heads]
    cnt = L.deg[u]
    h = np.repeat(heads, cnt)
    j = L.ptr[np.repeat(u, cnt)] + (np.arange(h.size) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    k = L.pos[h]
    pj = L.pos[j]
    du = L.deg[L.row[h]]
    keep = (pj != k) & (pj != (k - 1) % du)
    return h[keep], j[keep]


def _candidates(L: _Level, V, Q, rules, scale2, top=1, area=None):
    """The valid half-edge collapses and their costs ``(heads, cost)``, among each vertex's
    ``top`` cheapest targets (all of them when ``top`` is None); ``area`` ``None`` or
    ``(ring_held (n,), most)``, the area cap (see :func:`maps_decimate`)."""
    return _Candidates(L, V, Q, rules, scale2, top).under(area)


class _Candidates:
    """:func:`_candidates` in two steps, so decimations with different area caps share the
    first: the collapses and their surviving wedges that pass every test but the cap (made
    here), then :meth:`under` an area cap (a test of each wedge, and-ed with the others: the
    same result as testing it among them).  ``only`` ``None`` or ``(n,)`` bool: the vertices
    whose collapses are tried (all when ``None``)."""

    def __init__(self, L: _Level, V, Q, rules, scale2, top=1, only=None):
        n = L.deg.size
        u, w = L.row, L.nbr
        deg = L.deg
        apex1 = L.nbr[L.nxt]                                      # r_{k+1}
        prev = L.ptr[u] + (L.pos - 1) % np.maximum(deg[u], 1)
        apex0 = L.nbr[prev]                                       # r_{k-1}
        ok = (L.widest[u] < rules[3] * np.pi) & (L.log_a[u] <= rules[2]) & (deg[u] + deg[w] - 4 >= 3) & (deg[apex0] >= 4) & (deg[apex1] >= 4)
        if only is not None:
            ok &= only[u]
        heads = np.flatnonzero(ok)
        x = np.concatenate([V[w[heads]], np.ones((heads.size, 1))], 1)
        Qs = Q[u[heads]] + Q[w[heads]]
        cost = np.maximum(np.einsum("ki,kij,kj->k", x, Qs, x), 0.0)
        # A small length term, so flat regions still collapse their shortest edges first.
        d = V[w[heads]] - V[u[heads]]
        cost = cost + 1e-3 * np.einsum("ij,ij->i", d, d) ** 2
        if top is not None:                    # only each vertex's `top` cheapest targets
            order = np.lexsort((cost, u[heads]))
            heads, cost = heads[order], cost[order]
            r = u[heads]
            start = np.concatenate([[0], np.flatnonzero(r[1:] != r[:-1]) + 1]) if r.size else r
            rank = np.arange(r.size) - np.repeat(start, np.diff(np.append(start, r.size)))
            heads, cost = heads[rank < top], cost[rank < top]
        # Link condition: u and w share exactly their two apexes (count the x in N(u) with
        # edge (x, w), by sorted edge keys).
        ekey = u.astype(np.int64) * n + w                          # sorted: CSR rows, then...
        eorder = np.argsort(ekey, kind="stable")
        eks = ekey[eorder]
        hu = L.row[heads]
        cnt = deg[hu]
        hh = np.repeat(np.arange(heads.size), cnt)
        xs = L.nbr[L.ptr[np.repeat(hu, cnt)] + (np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt))]
        q = xs.astype(np.int64) * n + L.nbr[heads][hh]
        at = np.clip(np.searchsorted(eks, q), 0, max(eks.size - 1, 0))
        common = np.bincount(hh, weights=eks[at] == q, minlength=heads.size)
        keep = common == 2
        heads, cost = heads[keep], cost[keep]
        # Geometry: every surviving wedge (u, r_j, r_j+1) -> (w, r_j, r_j+1).
        h, j = _pairs(L, heads)
        uu, ww = L.row[h], L.nbr[h]
        a, b = L.nbr[j], L.nbr[L.nxt[j]]
        zh, z0, z1 = L.z[h], L.z[j], L.z[L.nxt[j]]
        flat = _orient(zh, z0, z1)
        zs = np.abs(zh).sum(1) + np.abs(z0).sum(1) + np.abs(z1).sum(1)
        good = flat > 1e-12 * zs * zs
        Vu, Vw, Va, Vb = V[uu], V[ww], V[a], V[b]
        old = np.cross(Va - Vu, Vb - Vu)
        new = np.cross(Va - Vw, Vb - Vw)
        lo, ln = np.sqrt(np.einsum("ij,ij->i", old, old)), np.sqrt(np.einsum("ij,ij->i", new, new))
        tilt, corner = rules[:2]
        good &= ln > 1e-14 * scale2
        good &= np.einsum("ij,ij->i", old, new) > tilt * lo * ln
        if corner > -1.5:
            e0, e1, e2 = Va - Vw, Vb - Va, Vw - Vb
            l0, l1, l2 = (np.sqrt(np.einsum("ij,ij->i", e, e)) + 1e-300 for e in (e0, e1, e2))
            c0 = -np.einsum("ij,ij->i", e2, e0) / (l2 * l0)
            c1 = -np.einsum("ij,ij->i", e0, e1) / (l0 * l1)
            c2 = -np.einsum("ij,ij->i", e1, e2) / (l1 * l2)
            good &= np.minimum(np.minimum(c0, c1), c2) >= corner
        self.L, self.heads, self.cost, self.h, self.uu, self.flat, self.good = L, heads, cost, h, uu, flat, good
        self._old_flat = None

    def under(self, area=None):
        """``(heads, cost)`` of the collapses that pass every test, and the area cap ``area``
        (``None`` or ``(ring_held (n,), most)``: the input area each new face would hold, the
        ring's held area spread evenly over the flattened ring, at most ``most``)."""
        L, good = self.L, self.good
        if area is not None:
            ring_held, most = area
            if self._old_flat is None:
                self._old_flat = np.bincount(L.row, weights=_orient(np.zeros_like(L.z), L.z, L.z[L.nxt]),
                                             minlength=L.deg.size)
            good = good & (ring_held[self.uu] * self.flat <= most * np.maximum(self._old_flat[self.uu], 1e-300))
        bad = np.bincount(self.h[~good], minlength=L.row.size)
        keep = bad[self.heads] == 0
        return self.heads[keep], self.cost[keep]


def _independent(L: _Level, heads, cost, limit: int, hubs=None):
    """Collapses among the candidates whose closed one-rings are pairwise disjoint, cheapest
    first (Luby rounds: a collapse is taken when it is the cheapest in every closed ring of
    its closed ring), at most ``limit`` of them; with ``hubs (n,)`` (bool), the rings may
    share hub vertices, which no collapse removes or targets.  **Returns** ring entries."""
    n = L.deg.size
    # Best target per vertex.
    order = np.lexsort((cost, L.row[heads]))
    hs, cs = heads[order], cost[order]
    first = np.concatenate([[True], L.row[hs][1:] != L.row[hs][:-1]]) if hs.size else np.zeros(0, bool)
    hs, cs = hs[first], cs[first]
    if hubs is not None:
        keep = ~hubs[L.row[hs]] & ~hubs[L.nbr[hs]]
        hs, cs = hs[keep], cs[keep]
    rank = np.empty(hs.size, np.int64)
    rank[np.argsort(cs, kind="stable")] = np.arange(hs.size)
    cand_u = L.row[hs]
    key = np.full(n, np.iinfo(np.int64).max)
    key[cand_u] = rank
    claimed = np.zeros(n, bool)
    chosen = []
    live = np.ones(hs.size, bool)
    for _ in range(ROUNDS):
        idx = np.flatnonzero(live)
        if not idx.size:
            break
        uu = cand_u[idx]
        cnt = L.deg[uu]
        ent = L.ptr[np.repeat(uu, cnt)] + (np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt))
        owner = np.repeat(idx, cnt)
        xs = np.concatenate([L.nbr[ent], uu])
        os_ = np.concatenate([owner, idx])
        if hubs is not None:
            xs, os_ = xs[~hubs[xs]], os_[~hubs[xs]]
        # Rings touching a claimed vertex are out for good.
        hit = np.bincount(os_, weights=claimed[xs], minlength=hs.size) > 0
        live &= ~hit
        m = live[os_]
        xs, os_ = xs[m], os_[m]
        best = np.full(n, np.iinfo(np.int64).max)
        np.minimum.at(best, xs, rank[os_])
        lose = np.bincount(os_, weights=best[xs] != rank[os_], minlength=hs.size) > 0
        win = np.flatnonzero(live & ~lose)
        if not win.size:
            break
        chosen.append(win)
        live[win] = False
        claimed[xs[np.isin(os_, win)]] = True
    if not chosen:
        return hs[:0]
    win = np.concatenate(chosen)
    win = win[np.argsort(rank[win])][:limit]
    return hs[win]


def _collapse(L: _Level, V, F, alive_f, Q, dead, pf, pb, chosen, face_ptr, face_pts, record=None):
    """Do the collapses ``chosen`` (ring entries u -> w) at once: faces, quadrics and the
    points held by the rings' faces (relocated through the flattened rings).  Appends the
    level's flattened rings to ``record`` (for :func:`pull_back`)."""
    u, w = L.row[chosen], L.nbr[chosen]
    du = L.deg[u]
    # All wedges of each u: entry index j, its face slot, u's corner there.
    cnt = du
    j = L.ptr[np.repeat(u, cnt)] + (np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    which = np.repeat(np.arange(u.size), cnt)
    f = L.face[j]
    c = L.corner[j]
    pj = L.pos[j]
    k = L.pos[chosen][which]
    survive = (pj != k) & (pj != (k - 1) % du[which])
    # 2D corners of each old wedge face, in the face's own corner order.
    zu = np.zeros((j.size, 2))
    P_old = np.zeros((j.size, 3, 2))
    ar = np.arange(j.size)
    P_old[ar, c] = zu
    P_old[ar, (c + 1) % 3] = L.z[j]
    P_old[ar, (c + 2) % 3] = L.z[L.nxt[j]]
    P_new = P_old.copy()
    P_new[ar, c] = L.z[chosen][which]
    # Points held by the ring faces.
    npt = face_ptr[f + 1] - face_ptr[f]
    src = np.repeat(ar, npt)
    pts = face_pts[np.repeat(face_ptr[f], npt) + (np.arange(npt.sum()) - np.repeat(np.cumsum(npt) - npt, npt))]
    q = np.einsum("kc,kcd->kd", pb[pts], P_old[src])
    # Candidate new faces: the surviving wedges of the same ring.
    grp = which[src]
    sv = np.flatnonzero(survive)
    sv_ptr = np.zeros(u.size + 1, np.int64)
    np.cumsum(np.bincount(which[sv], minlength=u.size), out=sv_ptr[1:])
    nc = sv_ptr[grp + 1] - sv_ptr[grp]
    pi = np.repeat(np.arange(pts.size), nc)
    cj = sv[np.repeat(sv_ptr[grp], nc) + (np.arange(nc.sum()) - np.repeat(np.cumsum(nc) - nc, nc))]
    T = P_new[cj]
    qq = q[pi]
    det = _orient(T[:, 0], T[:, 1], T[:, 2])
    l0 = _orient(qq, T[:, 1], T[:, 2]) / det
    l1 = _orient(T[:, 0], qq, T[:, 2]) / det
    bary = np.stack([l0, l1, 1.0 - l0 - l1], 1)
    depth = bary.min(1)
    best = np.lexsort((-depth, pi))
    head = best[np.concatenate([[True], pi[best][1:] != pi[best][:-1]])]
    b = np.clip(bary[head], 0.0, None)
    b /= b.sum(1, keepdims=True)
    pf[pts[pi[head]]] = f[cj[head]]
    pb[pts[pi[head]]] = b
    if record is not None:
        record.append((f, which, survive, P_old, P_new))
    # Faces: the two wedges at edge u-w die, the rest get w for u.
    alive_f[f[~survive]] = False
    F[f[survive], c[survive]] = w[which[survive]]
    Q[w] += Q[u]
    dead[u] = True


def maps_decimate(V: np.ndarray, F: np.ndarray, base_faces: int, *, area_cap=None, verbose=None):
    """Decimate a closed manifold mesh to ``base_faces`` faces and map its vertices onto the
    result (MAPS).

    **Arguments:** ``V (n, 3)`` positions, ``F (m, 3)`` faces of a closed, oriented,
    connected mesh; ``base_faces`` the faces wanted (even, at least the fewest its genus
    allows); ``area_cap`` ``None`` or ``(factor, doublings, reset)``, a bound on the input
    area a base face may hold (see :data:`AREA_CAPS`); ``verbose`` the progress bar (default:
    the library's switch).

    **Returns:** ``(kept (n0,), base_faces (base_faces, 3), vertex_face (n,), vertex_bary
    (n, 3), history)``: the surviving vertices (increasing indices into ``V``), the base
    faces over them (indices into ``kept``, the mesh's orientation), for every input vertex
    its base face and barycentric coordinates in that face's corner order, and the
    :class:`MapsHistory` that runs the map backwards.
    """
    out = decimate_caps(V, F, base_faces, (area_cap,), verbose=verbose)[0]
    if isinstance(out, SolverError):
        raise out
    return out


class _Run:
    """The state of one or more decimations that have made the same collapses so far (the
    mesh, quadrics, the points' faces and coordinates, the recorded levels), and of each of
    them (``members``: ``[which cap, factor, doublings, reset, cap step, rules level]``)."""

    def __init__(self, F, alive_f, Q, dead, pf, pb, levels, faces_left, members):
        self.F, self.alive_f, self.Q, self.dead, self.pf, self.pb = F, alive_f, Q, dead, pf, pb
        self.levels, self.faces_left, self.members = levels, faces_left, members

    def split(self, members) -> "_Run":
        """A copy of the state for ``members`` (before this level's collapses)."""
        return _Run(self.F.copy(), self.alive_f.copy(), self.Q.copy(), self.dead.copy(),
                    self.pf.copy(), self.pb.copy(), list(self.levels), self.faces_left, members)


def decimate_caps(V: np.ndarray, F: np.ndarray, base_faces: int, caps, *, verbose=None) -> list:
    """:func:`maps_decimate` once per area cap of ``caps``, each the same as alone, sharing
    the work while they make the same collapses (issue 13).

    A cap binds only once faces get large, late in the decimation (bunny, 100 base faces:
    the first 35 of 92 levels, 6,966 -> 674 faces, are the same for every cap of
    :data:`AREA_CAPS`).  So the decimations run together, level by level: the level's rings
    are made once, each decimation picks its collapses (the candidates' tests but the cap
    shared), and those that pick the same ones (or none: only their rules change) stay
    together; the others go on from a copy of the state.

    **Returns:** one entry per cap, :func:`maps_decimate`'s result or the
    :class:`SolverError` it would raise."""
    V = np.asarray(V, np.float64)
    # Quadric costs x^T Q x hold the planes' offsets: far from the origin they cancel (a mesh
    # moved by 1e3 of its size decimated otherwise).  Centred, the decimation depends on the
    # shape alone, up to the rounding of the positions given.
    V = V - 0.5 * (V.min(0) + V.max(0))
    F = np.array(F, np.int64)
    n, m = V.shape[0], F.shape[0]
    scale2 = float(np.sum(np.ptp(V, axis=0) ** 2))
    Q = plane_quadrics(V, F)
    pf = np.empty(n, np.int64)
    pf[F.ravel()] = np.repeat(np.arange(m), 3)
    pb = np.zeros((n, 3))
    cidx = np.empty(n, np.int64)
    cidx[F.ravel()] = np.tile(np.arange(3), m)
    pb[np.arange(n), cidx] = 1.0
    members = []
    for i, cap in enumerate(caps):
        factor, doublings, reset = cap if cap is not None else (np.inf, 0, -1)
        members.append([i, factor, doublings, reset, 0 if cap is not None else -1, 0, 0])
    if any(cap is not None for cap in caps):       # input area per vertex; mean base face's
        A = face_areas(V, F)
        va = np.bincount(F.ravel(), np.repeat(A / 3, 3), minlength=n)
        target = va.sum() / base_faces
    results: list = [None] * len(caps)
    runs = [_Run(F, np.ones(m, bool), Q, np.zeros(n, bool), pf, pb, [], m, members)]
    with progress(total=len(caps) * ((m - base_faces) // 2), desc="decimation", unit="collapse",
                  verbose=verbose) as bar:
        while runs:
            run = runs.pop()
            if run.faces_left <= base_faces or not run.members:
                _finish(run, m, results)
                continue
            L = _Level(V, run.F, np.flatnonzero(run.alive_f), n)
            ring_held, shared = None, {}
            picks: dict = {}                       # chosen collapses (bytes) -> members
            for mb in run.members:
                _, factor, doublings, reset, cap_step, level_rules, stall = mb
                area = None
                if cap_step >= 0:                  # input area held by each vertex's ring
                    if ring_held is None:
                        held = np.bincount(run.pf, va, minlength=m)
                        ring_held = np.bincount(L.row, weights=held[L.face], minlength=n)
                    area = (ring_held, factor * 2.0 ** cap_step * target)
                for top in (1, None):
                    if (level_rules, top) not in shared:
                        shared[level_rules, top] = _Candidates(L, V, run.Q, _RULES[level_rules], scale2, top)
                    heads, cost = shared[level_rules, top].under(area)
                    if heads.size:
                        break
                if not heads.size and level_rules < len(_RULES) - 1:
                    # Before the cap or the rules are relaxed for every ring: the tiny rings,
                    # with the shape rules dropped (see TINY_RING).
                    if ("tiny", level_rules) not in shared:
                        tiny = L.ring_area < TINY_RING * L.ring_area.sum() / (3 * L.slots.size)
                        rules = (-0.999, -2.0, _RULES[level_rules][2], np.inf)
                        shared["tiny", level_rules] = _Candidates(L, V, run.Q, rules, scale2, None, tiny)
                    heads, cost = shared["tiny", level_rules].under(area)
                chosen = heads[:0]
                if heads.size:                     # (hubs, when shared, may leave none)
                    hubs = L.deg >= HUB_DEGREE if stall < 0 else None
                    chosen = _independent(L, heads, cost, (run.faces_left - base_faces) // 2, hubs)
                if not chosen.size:                # no collapse: relax the cap, or the rules
                    if 0 <= cap_step < doublings:
                        mb[4] += 1
                    elif level_rules + 1 < _CAPPED_RULES:
                        mb[5] += 1
                        mb[4] = min(cap_step, reset)
                    elif cap_step >= 0:            # the cap goes, before the wedge bound
                        mb[4] = -1
                    elif level_rules + 1 < len(_RULES):
                        mb[5] += 1
                    else:
                        results[mb[0]] = SolverError(
                            f"manifold_map: decimation stopped at {run.faces_left} faces: no "
                            "collapse keeps the topology and a one-to-one map; ask for more "
                            f"than {run.faces_left} base faces.", stage="decimate")
                        continue
                    picks.setdefault(None, (None, []))[1].append(mb)
                    continue
                if stall >= 0:                     # -1: stalled before, hubs shared since
                    slow = (2 * chosen.size < STALL_SHARE * run.faces_left
                            and run.faces_left > STALL_FAR * base_faces)
                    stall = stall + 1 if slow else 0
                    mb[6] = -1 if stall >= STALL_LEVELS else stall
                picks.setdefault(chosen.tobytes(), (chosen, []))[1].append(mb)
            groups = list(picks.values())
            if not groups:                         # every one of them failed
                continue
            # Copies first (the state before this level), then each group's collapses.
            branches = [run] + [run.split(mbs) for _, mbs in groups[1:]]
            for br, (chosen, mbs) in zip(branches, groups):
                br.members = mbs
                if chosen is not None:
                    order = np.argsort(br.pf, kind="stable")
                    face_ptr = np.zeros(m + 1, np.int64)
                    np.cumsum(np.bincount(br.pf, minlength=m), out=face_ptr[1:])
                    _collapse(L, V, br.F, br.alive_f, br.Q, br.dead, br.pf, br.pb, chosen, face_ptr, order,
                              br.levels)
                    br.faces_left -= 2 * chosen.size
                    bar.update(int(chosen.size) * len(mbs))
            runs.extend(branches)
    return results


def _finish(run: _Run, m: int, results: list) -> None:
    """The results of the decimations of ``run`` (done), each its own arrays."""
    for k, mb in enumerate(run.members):
        kept = np.flatnonzero(~run.dead)
        slots = np.flatnonzero(run.alive_f)
        new_of_slot = np.full(m, -1, np.int64)
        new_of_slot[slots] = np.arange(slots.size)
        results[mb[0]] = (kept, np.searchsorted(kept, run.F[slots]), new_of_slot[run.pf],
                          run.pb if k == 0 else run.pb.copy(), MapsHistory(tuple(run.levels), slots))


class MapsHistory:
    """The flattened rings of every level of a MAPS decimation, to run the map backwards.

    ``levels``: per level ``(slot (k,), ring (k,), survive (k,), before (k, 3, 2), after (k,
    3, 2))`` for the ``k`` wedges of the level's collapsed rings: the face slot, which ring,
    whether the face survives, and its corners (in the face's corner order) in the ring's
    flat plane before and after the collapse; ``base_slots (m0,)`` the face slot of each base
    face."""

    def __init__(self, levels: tuple, base_slots: np.ndarray):
        self.levels, self.base_slots = levels, base_slots
        # What every pull-back needs of each level, made once (issue 13: the remesh pulls
        # points back about a dozen times): the surviving faces' slots and wedges, where each
        # ring's wedges start, and the old wedges' corners, coordinate by coordinate, with
        # their doubled signed areas (the same arithmetic as computing them per point).
        self._levels = []
        for f, which, survive, before, after in levels:
            ptr = np.zeros(int(which.max()) + 2, np.int64)
            np.cumsum(np.bincount(which, minlength=int(which.max()) + 1), out=ptr[1:])
            T = [np.ascontiguousarray(before[:, c, d]) for c in range(3) for d in range(2)]
            det = (T[2] - T[0]) * (T[5] - T[1]) - (T[3] - T[1]) * (T[4] - T[0])
            self._levels.append((f, which, f[survive], np.flatnonzero(survive), after, ptr, T, det))
        self._m = int(max(base_slots.max(), max((lv[0].max() for lv in levels), default=0))) + 1

    def pull_back(self, region: np.ndarray, bary: np.ndarray, *, verbose=None):
        """The input mesh face ``(k,)`` and barycentric coordinates ``(k, 3)`` of points of
        the base domain, given by base faces ``region (k,)`` and barycentric coordinates
        ``bary (k, 3)`` there: the exact inverse of the decimation's map (each level's
        piecewise-linear map of the flattened rings run backwards)."""
        slot = self.base_slots[np.asarray(region, np.int64)].copy()
        b = np.array(bary, np.float64)
        entry = np.full(self._m, -1, np.int64)           # reset after each level (not refilled)
        for f, which, live, live_at, after, ptr, T, det in progress(
                reversed(self._levels), total=len(self._levels), desc="pull back", unit="level",
                verbose=verbose):
            entry[live] = live_at
            e = entry[slot]
            entry[live] = -1
            hit = np.flatnonzero(e >= 0)
            if not hit.size:
                continue
            eh = e[hit]
            q = np.einsum("kc,kcd->kd", b[hit], after[eh])
            # Candidates: every old wedge of the same ring.
            grp = which[eh]
            cnt = ptr[grp + 1] - ptr[grp]
            starts = np.cumsum(cnt) - cnt
            pi = np.repeat(np.arange(hit.size), cnt)
            cj = np.repeat(ptr[grp], cnt) + (np.arange(cnt.sum()) - np.repeat(starts, cnt))
            x0, y0, x1, y1, x2, y2 = (t[cj] for t in T)
            qx, qy = q[:, 0][pi], q[:, 1][pi]
            dj = det[cj]
            l0 = ((x1 - qx) * (y2 - qy) - (y1 - qy) * (x2 - qx)) / dj
            l1 = ((qx - x0) * (y2 - y0) - (qy - y0) * (x2 - x0)) / dj
            l2 = 1.0 - l0 - l1
            depth = np.minimum(np.minimum(l0, l1), l2)
            # Each point's deepest old wedge (the first of equals; the first where all are nan),
            # per segment without sorting (a lexsort here was half the pull-back's time).
            top = np.fmax.reduceat(depth, starts)
            at = np.flatnonzero(depth == top[pi])
            head = starts.copy()
            first = np.concatenate([[True], pi[at][1:] != pi[at][:-1]])
            head[pi[at[first]]] = at[first]
            nb = np.clip(np.stack([l0[head], l1[head], l2[head]], 1), 0.0, None)
            slot[hit] = f[cj[head]]
            b[hit] = nb / nb.sum(1, keepdims=True)
        return slot, b
