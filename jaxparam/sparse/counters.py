"""The counters of :mod:`jaxparam.sparse`: one mutable dict that every part of the package
updates in place (so ``jaxparam.sparse.stats`` is this same object)."""
from __future__ import annotations

#: Counters for tests and benchmarks: numeric factorizations, PARDISO symbolic analyses,
#: solves (each ``Factorization.solve`` call), hits of :func:`solve`'s factorization
#: cache, hand-overs to SuperLU (failed factorization or residual too large), and derivative
#: solves whose residual check was skipped (their factor had passed it: ``Factorization._solve``).
stats = {"factorizations": 0, "analyses": 0, "solves": 0, "cache_hits": 0, "fallbacks": 0,
         "checks_skipped": 0}
