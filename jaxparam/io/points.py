"""Reading point sets: ``.xyz``/``.txt`` (or any other text, e.g. ``.csv``), ``.npy`` and
``.ply`` files into ``(N, 3)`` arrays; mesh files and other binary files are refused with
the formats that are read."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MeshFileError
from .files import existing_file

__all__ = ["load_points", "POINT_FORMATS"]

#: The point files :func:`load_points` reads, as its messages list them.
POINT_FORMATS = (".xyz/.txt/.csv text (x y z per line), .npy (one (N, 3) array) or .ply "
                 "(its vertices)")

#: Mesh formats that are not point files (a ``.ply`` mesh is read for its vertices).
_MESH_EXTENSIONS = {".obj": "an OBJ", ".off": "an OFF", ".stl": "an STL", ".glb": "a glTF",
                    ".gltf": "a glTF"}


def load_points(path) -> np.ndarray:
    """Read points: ``.xyz``/``.txt`` (x y z per line), ``.npy``, ``.ply``; ``(N, 3) float64``.

    Text files (any other extension, e.g. ``.csv``, is read as text too) take one point a
    line, the first three numbers (separated by blanks or commas; ``#`` starts a comment; a
    first row of names, such as a CSV header ``x,y,z``, is skipped);
    ``.npy`` holds an ``(N, 3)`` array; a ``.ply`` file's vertices are read by :mod:`.ply`
    (ASCII or binary; faces ignored).  Units are the file's.

    Raises :class:`MeshFileError` for a missing or malformed file (with the line), an
    array that is not ``(N, 3)``, and a file of another kind: a mesh (``.obj``, ``.off``,
    ``.stl``, ``.glb``/``.gltf``, or OBJ/OFF text under another name: the message says how
    to take its vertices), an ``.npz`` archive or other binary data.

    Example::

        P = jp.load_points("camelhead.xyz")
    """
    p = existing_file(path, what="point file")
    ext = p.suffix.lower()
    if ext in _MESH_EXTENSIONS:
        raise _mesh_file(path, f"{_MESH_EXTENSIONS[ext]} mesh file ({ext})")
    if ext == ".npy":
        try:
            P = np.load(p, allow_pickle=False)
        except Exception as exc:
            raise MeshFileError(f"{path}: not a readable .npy array ({exc}).") from None
    elif ext == ".ply":
        P = _read_ply_points(path)
    else:
        _refuse_other_kinds(p, path, ext)
        P = _read_xyz(p, path)
    P = np.asarray(P, np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise MeshFileError(f"{path}: expected an (N, 3) array of points, got shape {P.shape}.")
    return P


def _read_ply_points(path) -> np.ndarray:
    """The ``(N, 3)`` vertex positions of a PLY file (ASCII or binary, points or a mesh), read
    by :mod:`.ply`: a header that does not match the data is refused with the place."""
    from .ply import read_elements
    try:
        vertex = read_elements(path).get("vertex")
    except MeshFileError:
        raise
    except Exception as exc:
        raise MeshFileError(f"{path}: cannot read the PLY file ({type(exc).__name__}: {exc}); "
                            "check the format and that the file is complete.") from None
    if vertex is None or not all(c in vertex for c in "xyz"):
        raise MeshFileError(f"{path}: the PLY file has no vertex element with x, y and z "
                            "properties; points are read from the vertices' x y z.")
    return np.stack([np.asarray(vertex[c], np.float64) for c in "xyz"], axis=1)


def _mesh_file(path, what: str, rename: str | None = None) -> MeshFileError:
    """The error for a mesh file given where points are read, saying how to use its vertices;
    ``rename`` the extension the file should have (mesh text under another name)."""
    mesh = path if rename is None else Path(path).with_suffix(rename)
    first = "" if rename is None else f" Rename it to {mesh.name} first."
    return MeshFileError(
        f"{path}: {what}, not a point file; points are read (jp.load_points, jaxparam meshless) "
        f"from {POINT_FORMATS}.{first} To parameterize the mesh use jaxparam flatten; to use its "
        "vertices as points, save them first, e.g. python -c \"import jaxparam as jp, numpy as "
        f"np; np.save('points.npy', jp.load('{mesh}').vertices)\".")


def _refuse_other_kinds(p, path, ext: str) -> None:
    """Raise for a file read as text that is not: an archive, binary data, or mesh text."""
    with open(p, "rb") as f:
        head = f.read(4096)
        partial = bool(f.read(1))               # the head's last line may be cut
    named = f"the extension {ext!r}" if ext else "no extension"
    if head.startswith(b"PK\x03\x04") or ext == ".npz":
        kind = "a NumPy .npz archive" if ext == ".npz" else "a zip archive"
        raise MeshFileError(f"{path}: {kind}, not a point file; points are read from "
                            f"{POINT_FORMATS}: save the (N, 3) array alone with "
                            "np.save('points.npy', array).")
    if head.startswith(b"\x93NUMPY"):
        raise MeshFileError(f"{path}: a .npy array under {named}; "
                            "rename the file to end in .npy.")
    if head.startswith(b"glTF"):
        raise _mesh_file(path, "a binary glTF mesh file")
    if b"\x00" in head:
        raise MeshFileError(f"{path}: binary data, not a point file; points are read from "
                            f"{POINT_FORMATS}.")
    lines = head.decode("utf-8-sig", "replace").splitlines()
    for raw in lines[:-1] if partial else lines:
        tok = raw.split("#", 1)[0].split()
        if not tok:
            continue
        if tok[0].upper() in ("OFF", "COFF", "NOFF", "CNOFF", "STOFF", "4OFF"):
            raise _mesh_file(path, f"an OFF mesh file (its first line is {tok[0]!r})", ".off")
        if tok[0] in ("v", "vt", "vn", "f", "o", "g", "mtllib", "usemtl", "s"):
            raise _mesh_file(path, f"an OBJ mesh file (it has '{tok[0]}' lines)", ".obj")
        if tok[0] in ("ply", "solid"):
            raise MeshFileError(f"{path}: a {'PLY' if tok[0] == 'ply' else 'STL'} file under "
                                f"{named}; "
                                + ("rename it to end in .ply." if tok[0] == "ply" else
                                   f"points are read from {POINT_FORMATS}."))
        return


def _is_number(token: str) -> bool:
    try:
        float(token)
        return True
    except ValueError:
        return False


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
            if not rows and not any(_is_number(t) for t in parts):
                continue               # a header row of column names ('x,y,z', as CSV writers do)
            raise MeshFileError(f"{path}, line {line_no}: cannot read numbers from {line!r}.") from None
    if not rows:
        raise MeshFileError(f"{path}: the file holds no points (no 'x y z' lines); is it the "
                            "right file?")
    return np.asarray(rows, np.float64).reshape(-1, 3)
