"""The sparsity pattern of a square matrix (:class:`Pattern`) and the registry of live
patterns by uid, through which a host callback finds its pattern from a traced integer."""
from __future__ import annotations

import functools
import itertools
import operator
import weakref

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError, first_few


class Pattern:
    """A fixed CSR sparsity pattern of a square ``n x n`` matrix (numpy, concrete).

    Hashable and compared by identity, so it can be a static argument of
    ``jax.jit`` or a closure constant, and the key of cached analyses.  Its
    arrays are read-only.

    **Arguments:** ``indptr: (n+1,) int`` row starts; ``indices: (nnz,) int``
    the column of each entry, strictly increasing within each row (sorted, no
    duplicates); ``n`` the size.

    **Fields:** ``indptr (n+1,) int64``, ``indices (nnz,) int64``, ``rows (nnz,)
    int64`` (the row of each entry), ``n``, ``nnz``.
    """

    def __init__(self, indptr, indices, n: int, *, _uid: int | None = None):
        n = operator.index(n)
        indptr, indices = np.asarray(indptr), np.asarray(indices)
        for name, a in (("indptr", indptr), ("indices", indices)):
            if a.ndim != 1 or not (np.issubdtype(a.dtype, np.integer) or a.size == 0):
                raise ValueError(f"Pattern: {name} must be a 1-D integer array, got shape "
                                 f"{a.shape} of {a.dtype}.")
        if n < 0 or indptr.shape != (n + 1,):
            raise ValueError(f"Pattern: indptr must have shape ({n + 1},) for n = {n}, "
                             f"got {indptr.shape}.")
        counts = np.diff(indptr)
        if indptr[0] != 0 or indptr[-1] != indices.size or np.any(counts < 0):
            raise ValueError(f"Pattern: indptr must rise from 0 to nnz = {indices.size}; it runs "
                             f"from {indptr[0]} to {indptr[-1]}"
                             + (" and decreases" if np.any(counts < 0) else "") + ".")
        self.n, self.nnz = n, int(indices.size)
        self.indptr = _frozen(indptr)
        self.indices = _frozen(indices)
        self.rows = _frozen(np.repeat(np.arange(n, dtype=np.int64), counts))
        if self.nnz:
            out = np.flatnonzero((self.indices < 0) | (self.indices >= n))
            if out.size:
                raise ValueError(f"Pattern: column indices must lie in [0, {n}); entries "
                                 f"{first_few(out)} do not.")
            # Within a row the columns must strictly increase (PARDISO reads sorted rows).
            same_row = self.rows[1:] == self.rows[:-1]
            bad = np.flatnonzero(same_row & (self.indices[1:] <= self.indices[:-1]))
            if bad.size:
                raise ValueError(f"Pattern: columns must be sorted and unique within each row; rows "
                                 f"{first_few(np.unique(self.rows[bad]))} are not (use "
                                 "scipy's sum_duplicates() / sort_indices()).")
        #: rows with no entry (the matrix is then singular)
        self.empty_rows = np.flatnonzero(counts == 0)
        self._triangles: dict = {}
        self.uid = _register(self, _uid)

    def matrix(self, values) -> sp.csr_matrix:
        """The scipy CSR matrix with these values.  **Arguments:** ``values: (nnz,) float``."""
        return sp.csr_matrix((np.asarray(values, np.float64), self.indices, self.indptr),
                             shape=(self.n, self.n))

    def triangle(self, upper: bool):
        """The entries on and above (``upper``) or on and below the diagonal.

        **Returns:** ``(indptr (n+1,) int32, indices (m,) int32, take (m,) int64)``,
        a CSR pattern and the positions of its entries in the full value array.
        """
        if upper not in self._triangles:
            keep = np.flatnonzero(self.indices >= self.rows if upper else self.indices <= self.rows)
            indptr = np.zeros(self.n + 1, np.int64)
            np.cumsum(np.bincount(self.rows[keep], minlength=self.n), out=indptr[1:])
            self._triangles[upper] = (indptr.astype(np.int32), self.indices[keep].astype(np.int32), keep)
        return self._triangles[upper]

    @functools.cached_property
    def has_diagonal(self) -> bool:
        """Whether every diagonal entry is in the pattern."""
        return int(np.count_nonzero(self.indices == self.rows)) == self.n

    @functools.cached_property
    def int32(self):
        """``(indptr, indices)`` as int32, for the C backends."""
        if self.nnz >= 2 ** 31:
            raise SolverError(f"sparse: {self.nnz} entries exceed the 32-bit indices of the "
                              "backends.", stage="factorize")
        return self.indptr.astype(np.int32), self.indices.astype(np.int32)

    def __repr__(self) -> str:
        return f"Pattern(n={self.n}, nnz={self.nnz})"


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=np.int64, copy=True)
    a.flags.writeable = False
    return a


#: Live patterns by uid (int, from 1; a :class:`Pattern` is dropped when it is collected), so a
#: host callback can find its pattern from a traced integer.
registry: "weakref.WeakValueDictionary[int, Pattern]" = weakref.WeakValueDictionary()
_uids = itertools.count(1)


def _register(pattern: Pattern, uid: int | None) -> int:
    uid = next(_uids) if uid is None else uid
    registry[uid] = pattern
    return uid

def pattern_for_uid(uid: int, indptr, indices) -> Pattern:
    """The live pattern with this uid or, if it has been collected since (a compiled solve
    outlived it), the pattern rebuilt from its arrays under the same uid.

    **Arguments:** ``uid`` a :attr:`Pattern.uid`; ``indptr: (n+1,) int``,
    ``indices: (nnz,) int`` its CSR arrays.
    """
    uid = int(uid)
    pattern = registry.get(uid)
    if pattern is None:   # collected since tracing: rebuild it from the operands, same uid
        pattern = Pattern(np.asarray(indptr), np.asarray(indices), np.asarray(indptr).size - 1, _uid=uid)
    return pattern
