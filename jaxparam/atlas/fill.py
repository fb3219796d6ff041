"""Fixed-square fills of the packing raster (:func:`fill_square`: bottom-left;
:func:`fill_contact`: most contact) and the orders they place charts in
(:func:`jittered_orders`), for :func:`~jaxparam.atlas.pack.pack_charts`'s bisection on the
scale.
"""
from __future__ import annotations

import numpy as np

from .raster import correlations, lowest_inside, paint, proper_turns

__all__ = ["fill_square", "fill_contact", "jittered_orders", "ORDER_JITTER"]

#: How far :func:`jittered_orders` moves each chart's area (a factor in ``1 -+ ORDER_JITTER``).
ORDER_JITTER = 0.15


def _lowest_free(turns, occb, size):
    """The lowest, then leftmost free position of the mask over its turns inside the
    ``size x size`` square, all positions tested by an FFT correlation with ``occb``.
    **Returns:** ``(key, turn, i, j, mask)`` or ``None``."""
    from scipy import fft

    shape = (fft.next_fast_len(size, True),) * 2
    F_occ = fft.rfft2(occb[:size, :size].astype(np.float32), shape)
    best = None
    masks = [None if M.shape[0] > size or M.shape[1] > size or not M.any() else M
             for M, _, _ in turns]
    for t, ov in enumerate(correlations(F_occ, masks, shape)):
        if ov is None:
            continue
        M = masks[t]
        h, w = M.shape
        free = ov[:size - h + 1, :size - w + 1] < 0.5
        if free.any():
            j, i = np.unravel_index(int(np.argmax(free)), free.shape)
            key = (int(j) << 12) + int(i)
            if best is None or key < best[0]:
                best = (key, t, int(i), int(j), M)
    return best



def fill_square(masks, size: int, margin: int, order: np.ndarray | None = None):
    """Place masks (largest first) in a fixed ``size x size`` raster, each at its lowest,
    then leftmost free position over its four proper turns (bottom-left fill), at least
    ``margin`` cells apart.  **Returns:** ``None`` if one does not fit, else
    ``(positions (c, 2) cells [u, v], turn (c,) int, size)``."""
    return _fill(masks, size, margin, order, _lowest)



def _lowest(turns, occb, size):
    """:func:`fill_square`'s placement: the lowest, then leftmost free position."""
    best = lowest_inside(turns, occb, size, size)
    return best if best is not None else _lowest_free(turns, occb, size)



def _fill(masks, size: int, margin: int, order, place):
    """The placement loop of :func:`fill_square` and :func:`fill_contact`: masks in ``order``
    (default largest first), each where ``place(turns, occupied, size)`` puts it (``(key,
    turn, i, j, mask)`` or ``None``), then painted with its margin."""
    occb = np.zeros((size, size), bool)
    pos = np.zeros((len(masks), 2), np.int64)
    turn = np.zeros(len(masks), np.int64)
    if order is None:
        order = np.argsort([-m.sum() for m in masks], kind="stable")
    for c in order:
        if min(masks[c].shape) > size:
            return None
        best = place(proper_turns(masks[c]), occb, size)
        if best is None:
            return None
        _, t, i, j, M = best
        paint(occb, M, i, j, margin)
        pos[c] = (i, j)
        turn[c] = t
    return pos, turn, size



def _most_contact(turns, occb, size, keep: int = 8):
    """The free position of the mask, over its turns, inside the ``size x size`` square whose
    ring (the cells next to the mask) meets the most occupied cells or the square's outside;
    ties go to the lowest, then leftmost position.  Occupancy and contact at every position
    come from FFT correlations (float32); the ``keep`` best of each turn are checked exactly
    against ``occb``, in order.  **Returns:** ``(key, turn, i, j, mask)`` or ``None``."""
    from scipy import fft, ndimage

    O = np.ones((size + 2, size + 2), np.float32)          # the outside counts as contact
    O[1:-1, 1:-1] = occb[:size, :size]
    shape = (fft.next_fast_len(size + 2, True),) * 2
    F_occ = fft.rfft2(O, shape)
    cands = []
    # at (j, i) in O: M at (j, i) in occb; the ring of a turn is the turned ring
    fits = [M.shape[0] <= size and M.shape[1] <= size and M.any() for M, _, _ in turns]
    pads = [np.pad(M, 1) if ok else None for (M, _, _), ok in zip(turns, fits)]
    ovs = correlations(F_occ, pads, shape)
    rings = [None] * 4
    for t, ov in enumerate(ovs):
        if ov is None:
            continue
        M = turns[t][0]
        h, w = M.shape
        fj, fi = np.nonzero(ov[:size - h + 1, :size - w + 1] < 0.5)
        if fj.size == 0:
            continue
        rings[t] = (fj, fi, ndimage.binary_dilation(pads[t], np.ones((3, 3), bool)) & ~pads[t])
    cts = correlations(F_occ, [r[2] if r is not None else None for r in rings], shape)
    for t, ct in enumerate(cts):
        if ct is None:
            continue
        fj, fi, _ = rings[t]
        M = turns[t][0]
        key = -np.rint(ct[fj, fi]).astype(np.int64) * (1 << 24) + (fj << 12) + fi
        for b in np.argsort(key, kind="stable")[:keep]:
            cands.append((int(key[b]), t, int(fi[b]), int(fj[b]), M))
    cands.sort(key=lambda c: c[0])
    for c in cands:
        _, _, i, j, M = c
        if not np.any(occb[j:j + M.shape[0], i:i + M.shape[1]] & M):
            return c
    return None



def fill_contact(masks, size: int, margin: int, order: np.ndarray | None = None,
                 lead: int | None = None):
    """Place masks (largest first) in a fixed ``size x size`` raster, each at the free
    position (over its four proper turns) where it touches the most placed masks' margins
    and the square's border (:func:`_most_contact`), at least ``margin`` cells apart;
    with ``lead``, only the first ``lead`` masks so, the rest as :func:`fill_square` places
    them (lowest, then leftmost).
    Tighter than :func:`fill_square` on some sets of ragged charts, looser on others
    (session 10, same charts, with both tried at each scale: bunny 66.0 -> 70.3 %,
    decimated-knight 70.3 -> 71.3 %, 3holes 69.5 -> 70.0 %).  **Returns:** ``None`` if one
    does not fit, else ``(positions (c, 2) cells [u, v], turn (c,) int, size)``."""
    if lead is None or lead >= len(masks):
        return _fill(masks, size, margin, order, _most_contact)
    placed = [0]

    def place(turns, occb, size):
        placed[0] += 1
        return (_most_contact if placed[0] <= lead else _lowest)(turns, occb, size)

    return _fill(masks, size, margin, order, place)



def jittered_orders(masks, tries: int):
    """``tries`` placement orders of ``masks``, each largest first by the masks' areas times a
    factor drawn in ``[1 - ORDER_JITTER, 1 + ORDER_JITTER]`` (seeds ``0 .. tries - 1``: the
    same orders on every run).  A greedy fill is sensitive to its order: where largest first
    leaves a gap no later chart fits, a nearby order often does not (session 36)."""
    area = np.array([M.sum() for M in masks], float)
    for seed in range(int(tries)):
        factor = np.random.default_rng(seed).uniform(1 - ORDER_JITTER, 1 + ORDER_JITTER, area.size)
        yield np.argsort(-area * factor, kind="stable")
