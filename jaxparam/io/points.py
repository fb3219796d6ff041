"""Reading point sets: ``.xyz``/``.txt``, ``.npy`` and ``.ply`` files into ``(N, 3)`` arrays."""
from __future__ import annotations

import numpy as np

from ..errors import MeshFileError
from .files import existing_file

__all__ = ["load_points"]


def load_points(path) -> np.ndarray:
    """Read points: ``.xyz``/``.txt`` (x y z per line), ``.npy``, ``.ply``; ``(N, 3) float64``.

    Text files take one point a line, the first three numbers (separated by blanks or
    commas; ``#`` starts a comment); ``.npy`` holds an ``(N, 3)`` array; a ``.ply`` file's
    vertices are read with ``trimesh`` (faces ignored).  Units are the file's.

    Raises :class:`MeshFileError` for a missing or malformed file (with the line) or an
    array that is not ``(N, 3)``.

    Example::

        P = jp.load_points("camelhead.xyz")
    """
    p = existing_file(path, what="point file")
    ext = p.suffix.lower()
    if ext == ".npy":
        try:
            P = np.load(p, allow_pickle=False)
        except Exception as exc:
            raise MeshFileError(f"{path}: not a readable .npy array ({exc}).") from None
    elif ext == ".ply":
        try:
            import trimesh
            P = np.asarray(trimesh.load(str(p), process=False).vertices)
        except Exception as exc:
            raise MeshFileError(f"{path}: cannot read the PLY file ({type(exc).__name__}: {exc}).") from None
    else:
        P = _read_xyz(p, path)
    P = np.asarray(P, np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise MeshFileError(f"{path}: expected an (N, 3) array of points, got shape {P.shape}.")
    return P


def _read_xyz(p, path) -> np.ndarray:
    """The ``(N, 3)`` points of a text file, one ``x y z`` a line; ``path`` as given, for messages."""
    rows = []
    for line_no, raw in enumerate(p.read_text(encoding="utf-8-sig", errors="replace").splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").split()
        if len(parts) < 3:
            raise MeshFileError(f"{path}, line {line_no}: expected 'x y z', got {line!r}.")
        try:
            rows.append([float(t) for t in parts[:3]])
        except ValueError:
            raise MeshFileError(f"{path}, line {line_no}: cannot read numbers from {line!r}.") from None
    if not rows:
        raise MeshFileError(f"{path}: the file holds no points (no 'x y z' lines); is it the "
                            "right file?")
    return np.asarray(rows, np.float64).reshape(-1, 3)
