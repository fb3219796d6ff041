"""The library's exception types and the helpers that write their messages.

Every error raised on bad input is a :class:`JaxparamError`, and each kind also
subclasses the builtin users already catch (``ValueError``, ``OSError``,
``RuntimeError``, ``TypeError``).  Messages name the function, the offending elements (the
first few and the count) and the remedy.
"""
from __future__ import annotations

from typing import Iterable, Sequence

__all__ = [
    "JaxparamError",
    "MeshError",
    "NonManifoldError",
    "TopologyError",
    "DegenerateFaceError",
    "PointCloudError",
    "MeshFileError",
    "SolverError",
    "ArgumentTypeError",
    "first_few",
]


class JaxparamError(Exception):
    """Base of every error jaxparam raises on purpose."""


class MeshError(JaxparamError, ValueError):
    """The mesh arrays are not a valid triangle mesh for the operation."""


class NonManifoldError(MeshError):
    """An edge with more than two faces, or a vertex whose faces form several fans."""


class TopologyError(MeshError):
    """The mesh is valid but has the wrong topology (closed, several components, ...)."""


class DegenerateFaceError(MeshError):
    """A face with a repeated vertex or with zero area."""


class PointCloudError(JaxparamError, ValueError):
    """The point set cannot be parameterized as given."""


class MeshFileError(JaxparamError, OSError):
    """A mesh or point file is missing, unreadable or malformed."""


class ArgumentTypeError(JaxparamError, TypeError):
    """An argument of the wrong kind: an array where a mesh goes, a mesh where points go
    (also a ``TypeError``, which such mistakes raise in Python)."""


class SolverError(JaxparamError, RuntimeError):
    """A numerical stage failed; ``stage`` names which one."""

    def __init__(self, message: str, *, stage: str = "solve"):
        super().__init__(message)
        self.stage = stage


def first_few(items: Iterable, *, limit: int = 5, fmt=str) -> str:
    """Format the first ``limit`` items and the total count, e.g. ``"3, 9, 12 (3 in all)"``.

    **Arguments:** ``items`` any iterable (numpy rows are formatted as tuples);
    ``fmt`` a formatter for one item.
    """
    items = list(items)
    shown: Sequence = items[:limit]
    text = ", ".join(fmt(_plain(i)) for i in shown)
    if len(items) > limit:
        text += ", ..."
    return f"{text} ({len(items)} in all)"


def _plain(item):
    """Numpy scalars and rows as plain Python ints/tuples so messages read ``(3, 9)``."""
    try:
        import numpy as np

        if isinstance(item, np.ndarray):
            return tuple(int(v) if np.issubdtype(item.dtype, np.integer) else float(v) for v in item)
        if isinstance(item, np.generic):
            return item.item()
        if isinstance(item, tuple):
            return tuple(_plain(v) for v in item)
    except ImportError:  # pragma: no cover
        pass
    return item
