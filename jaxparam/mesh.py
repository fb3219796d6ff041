"""``TriMesh``: vertices, faces and their topology; reading and writing mesh files.

A ``TriMesh`` is immutable and a JAX pytree whose only array leaves are the
vertex positions (and the UVs, when it carries them): the faces and the
:class:`~jaxparam.topology.Topology` travel as static data, so a ``TriMesh``
passes through ``jax.jit`` and ``jax.grad`` and a new mesh of the same
connectivity reuses compiled code.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from . import tol
from . import topology as topo
from .errors import DegenerateFaceError, MeshError, MeshFileError, first_few

__all__ = ["TriMesh", "load", "save", "read_obj", "read_off", "atomic_write", "grid_faces"]


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


@jax.tree_util.register_pytree_node_class
class TriMesh:
    """A triangle mesh: ``vertices (n, 3) float``, ``faces (m, 3) int``, ``topology``.

    **Arguments:**

    - ``vertices``: ``(n, 3)`` (or ``(n, 2)``, lifted to z = 0) float positions;
      numpy, JAX arrays and tracers are accepted.
    - ``faces``: ``(m, 3)`` integer, counter-clockwise, concrete.
    - ``uv``: optional ``(n, 2)`` texture coordinates carried along (from an OBJ's ``vt``).
    - ``validate``: check coordinates and face areas (needs concrete vertices; skipped for tracers).

    Raises :class:`MeshError` subclasses naming the offending element: non-finite
    coordinates, indices out of range, repeated vertices, zero-area faces,
    non-manifold edges or vertices, inconsistent orientation.

    Example::

        mesh = TriMesh(np.random.rand(3, 3), [[0, 1, 2]])
        mesh.topology.boundary_loops
    """

    def __init__(self, vertices, faces, topology=None, *, uv=None, validate: bool = True,
                 name: str | None = None):
        if _is_concrete(vertices) and not isinstance(vertices, jax.Array):
            V = np.asarray(vertices)
            if V.dtype == object or not (np.issubdtype(V.dtype, np.number)):
                raise MeshError(f"TriMesh: vertices must be numbers, got dtype {V.dtype}.")
            V = V.astype(np.float64, copy=False)
        else:
            V = vertices
        if V.ndim != 2 or V.shape[1] not in (2, 3):
            raise MeshError(f"TriMesh: vertices must have shape (n, 3), got {tuple(V.shape)}.")
        if V.shape[1] == 2:
            V = (np.concatenate if isinstance(V, np.ndarray) else jnp.concatenate)(
                [V, (np.zeros if isinstance(V, np.ndarray) else jnp.zeros)((V.shape[0], 1))], axis=1)
        if topology is None:
            topology = topo.build(faces, V.shape[0])
        elif topology.n_vertices != V.shape[0]:
            raise MeshError(f"TriMesh: topology has {topology.n_vertices} vertices, vertices has {V.shape[0]}.")
        self.vertices = V
        self.topology = topology
        self.uv = uv
        self.name = name
        if validate and _is_concrete(V):
            self._validate_geometry(np.asarray(V))

    # -- pytree ---------------------------------------------------------------------------
    def tree_flatten(self):
        return (self.vertices, self.uv), (self.topology, self.name)

    @classmethod
    def tree_unflatten(cls, aux, children):
        obj = object.__new__(cls)
        obj.vertices, obj.uv = children
        obj.topology, obj.name = aux
        return obj

    # -- convenience ----------------------------------------------------------------------
    @property
    def faces(self) -> np.ndarray:
        """``(m, 3) int64`` face array."""
        return self.topology.faces

    @property
    def n_vertices(self) -> int:
        return self.topology.n_vertices

    @property
    def n_faces(self) -> int:
        return self.topology.n_faces

    def with_vertices(self, vertices) -> "TriMesh":
        """The same connectivity with new positions (no re-validation of topology)."""
        return TriMesh(vertices, None, self.topology, uv=self.uv, validate=False, name=self.name)

    def with_uv(self, uv) -> "TriMesh":
        return TriMesh(self.vertices, None, self.topology, uv=uv, validate=False, name=self.name)

    def __repr__(self) -> str:
        t = self.topology
        return (f"TriMesh({t.n_vertices} vertices, {t.n_faces} faces, "
                f"{len(t.boundary_loops)} boundary loops, genus {t.genus}, "
                f"{t.n_components} component{'s' if t.n_components != 1 else ''})")

    def _validate_geometry(self, V: np.ndarray) -> None:
        F = self.faces
        bad = np.flatnonzero(~np.all(np.isfinite(V), axis=1))
        if bad.size:
            raise MeshError(f"TriMesh: vertices {first_few(bad)} have non-finite coordinates "
                            f"(vertex {int(bad[0])} is {tuple(float(x) for x in V[bad[0]])}); "
                            "remove or repair them before parameterizing.")
        e1 = V[F[:, 1]] - V[F[:, 0]]
        e2 = V[F[:, 2]] - V[F[:, 0]]
        area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
        scale = np.mean(np.concatenate([np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)])) ** 2
        zero = np.flatnonzero(area2 <= tol.DEGENERATE_AREA_REL * max(scale, np.finfo(float).tiny))
        if zero.size:
            raise DegenerateFaceError(
                f"TriMesh: faces {first_few(zero)} have zero area (face {int(zero[0])} = "
                f"{tuple(int(v) for v in F[zero[0]])}); collapse or remove them "
                "(e.g. trimesh's remove_degenerate_faces), or pass validate=False to keep them.")


def grid_faces(nu: int, nv: int) -> np.ndarray:
    """Faces of a ``nu x nv`` vertex grid (vertex ``i * nv + j``), two triangles a cell,
    diagonals alternating so the grid has no preferred direction."""
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    a = (i * nv + j).ravel()
    b, c, d = a + nv, a + nv + 1, a + 1
    flip = ((i + j) % 2 == 1).ravel()
    t1 = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
    t2 = np.where(flip[:, None], np.stack([b, c, d], 1), np.stack([a, c, d], 1))
    return np.concatenate([t1, t2]).astype(np.int64)


# ------------------------------------------------------------------------------------------
# Files
# ------------------------------------------------------------------------------------------

def _number(tok: str, path, line_no: int, what: str) -> float:
    try:
        return float(tok)
    except ValueError:
        raise MeshFileError(f"{path}, line {line_no}: cannot read {what} from {tok!r}; "
                            "the file is malformed.") from None


def read_obj(path):
    """Read an OBJ file keeping the vertex order: ``(vertices, faces, uv_or_None)``.

    Polygons are split into triangle fans; negative (relative) indices are
    honoured; ``vt`` coordinates become per-vertex UVs when every face corner
    of a vertex uses the same one.
    """
    verts, tex, faces, ftex = [], [], [], []
    text = _read_text(path)
    for line_no, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        tag = parts[0]
        if tag == "v":
            if len(parts) < 4:
                raise MeshFileError(f"{path}, line {line_no}: a vertex needs three coordinates, "
                                    f"got {len(parts) - 1}.")
            verts.append([_number(t, path, line_no, "a coordinate") for t in parts[1:4]])
        elif tag == "vt":
            if len(parts) < 3:
                raise MeshFileError(f"{path}, line {line_no}: a texture coordinate needs two values.")
            tex.append([_number(t, path, line_no, "a texture coordinate") for t in parts[1:3]])
        elif tag == "f":
            if len(parts) < 4:
                raise MeshFileError(f"{path}, line {line_no}: a face needs at least three vertices, "
                                    f"got {len(parts) - 1}.")
            vi, ti = [], []
            for tok in parts[1:]:
                fields = tok.split("/")
                vi.append(_obj_index(fields[0], len(verts), path, line_no))
                if len(fields) > 1 and fields[1]:
                    ti.append(_obj_index(fields[1], len(tex), path, line_no))
            for k in range(1, len(vi) - 1):
                faces.append([vi[0], vi[k], vi[k + 1]])
                ftex.append([ti[0], ti[k], ti[k + 1]] if len(ti) == len(vi) else None)
    if not verts:
        raise MeshFileError(f"{path}: no vertices ('v' lines) found; is this an OBJ mesh file?")
    if not faces:
        raise MeshFileError(f"{path}: no faces ('f' lines) found; jaxparam needs a triangle mesh "
                            "(for bare points use jaxparam meshless).")
    V = np.asarray(verts, np.float64)
    F = np.asarray(faces, np.int64)
    uv = None
    if tex and all(t is not None for t in ftex):
        T = np.asarray(ftex, np.int64)
        uv_all = np.asarray(tex, np.float64)
        uv = np.full((V.shape[0], 2), np.nan)
        uv[F.reshape(-1)] = uv_all[T.reshape(-1)]
        # Only a true per-vertex parameterization is kept (no seams).
        consistent = np.all(uv_all[T.reshape(-1)] == uv[F.reshape(-1)])
        if not consistent:
            uv = None
    return V, F, uv


def _obj_index(tok: str, count: int, path, line_no: int) -> int:
    try:
        i = int(tok)
    except ValueError:
        raise MeshFileError(f"{path}, line {line_no}: bad index {tok!r}; the file is malformed.") from None
    if i < 0:
        i = count + i + 1
    if i < 1 or i > count:
        raise MeshFileError(f"{path}, line {line_no}: index {tok} refers to element {i} but only "
                            f"{count} are defined before this line.")
    return i - 1


def read_off(path):
    """Read an OFF file keeping the vertex order: ``(vertices, faces)``; polygons are fanned."""
    text = _read_text(path)
    tokens_by_line = []
    for line_no, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if line:
            tokens_by_line.append((line_no, line.split()))
    if not tokens_by_line:
        raise MeshFileError(f"{path}: the file is empty.")
    line_no, first = tokens_by_line[0]
    if not first[0].upper().endswith("OFF"):
        raise MeshFileError(f"{path}, line {line_no}: expected the header 'OFF', got {first[0]!r}.")
    rest = [(ln, toks) for ln, toks in ([(line_no, first[1:])] if len(first) > 1 else []) + tokens_by_line[1:]]
    if not rest:
        raise MeshFileError(f"{path}: missing the counts line 'nv nf ne' after the header.")
    ln, counts = rest[0]
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (ValueError, IndexError):
        raise MeshFileError(f"{path}, line {ln}: expected the counts 'nv nf ne', got {' '.join(counts)!r}.") from None
    if nv < 0 or nf < 0:
        raise MeshFileError(f"{path}, line {ln}: negative counts {nv} {nf}.")
    body = rest[1:]
    if len(body) < nv + nf:
        raise MeshFileError(f"{path}: the header promises {nv} vertices and {nf} faces but the file has "
                            f"only {len(body)} data lines; the file is truncated or the counts are wrong.")
    V = np.empty((nv, 3))
    for i in range(nv):
        ln, toks = body[i]
        if len(toks) < 3:
            raise MeshFileError(f"{path}, line {ln}: a vertex needs three coordinates, got {len(toks)}.")
        V[i] = [_number(t, path, ln, "a coordinate") for t in toks[:3]]
    faces = []
    for j in range(nf):
        ln, toks = body[nv + j]
        try:
            k = int(toks[0])
            idx = [int(t) for t in toks[1:1 + k]]
        except (ValueError, IndexError):
            raise MeshFileError(f"{path}, line {ln}: cannot read a face from {' '.join(toks)!r}.") from None
        if k < 3 or len(idx) != k:
            raise MeshFileError(f"{path}, line {ln}: a face with {k} vertices but {len(idx)} indices given.")
        bad = [i for i in idx if i < 0 or i >= nv]
        if bad:
            raise MeshFileError(f"{path}, line {ln}: vertex index {bad[0]} is out of range [0, {nv}).")
        faces.extend([idx[0], idx[t], idx[t + 1]] for t in range(1, k - 1))
    if not faces:
        raise MeshFileError(f"{path}: the file has no faces.")
    return V, np.asarray(faces, np.int64)


def _read_text(path) -> str:
    p = Path(path)
    if not p.exists():
        raise MeshFileError(f"{path}: no such file.")
    if p.is_dir():
        raise MeshFileError(f"{path}: is a folder, not a mesh file.")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise MeshFileError(f"{path}: cannot read the file ({exc.strerror}).") from None
    if not data.strip():
        raise MeshFileError(f"{path}: the file is empty.")
    if b"\x00" in data[:4096]:
        raise MeshFileError(f"{path}: the file looks binary but its extension says text; "
                            "is it the right file?")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def load(path, *, validate: bool = True) -> TriMesh:
    """Read a triangle mesh file, keeping the vertex order.

    OBJ and OFF are read by jaxparam's own readers (no merging or reordering;
    an OBJ's per-vertex ``vt`` becomes ``mesh.uv``); PLY, STL, GLB and other
    formats go through ``trimesh`` with ``process=False`` (STL stores
    triangle soup, so its coincident corners are merged, in first-seen order).

    Raises :class:`MeshFileError` for a missing or malformed file (with the
    line) and :class:`MeshError` for an invalid mesh.

    Example::

        mesh = jp.load("camelhead.off")
    """
    p = Path(path)
    ext = p.suffix.lower()
    uv = None
    if ext == ".obj":
        V, F, uv = read_obj(p)
    elif ext == ".off":
        V, F = read_off(p)
    else:
        V, F = _read_with_trimesh(p, ext)
    return TriMesh(V, F, uv=uv, validate=validate, name=p.stem)


def _read_with_trimesh(p: Path, ext: str):
    if not p.exists():
        raise MeshFileError(f"{p}: no such file.")
    if p.is_dir():
        raise MeshFileError(f"{p}: is a folder, not a mesh file.")
    if p.stat().st_size == 0:
        raise MeshFileError(f"{p}: the file is empty.")
    try:
        import trimesh
        kw = {"process": ext == ".stl", "force": "mesh"}
        m = trimesh.load(str(p), **kw)
    except Exception as exc:  # trimesh raises many types on malformed input
        raise MeshFileError(f"{p}: cannot read the file as {ext or 'a mesh'} ({type(exc).__name__}: "
                            f"{exc}); check the format and that the file is complete.") from None
    V = np.asarray(getattr(m, "vertices", np.empty((0, 3))), np.float64)
    F = np.asarray(getattr(m, "faces", np.empty((0, 3))), np.int64)
    if V.size == 0 or F.size == 0:
        raise MeshFileError(f"{p}: no triangles found in the file.")
    return V, F


def _new_file_mode() -> int:
    """The permissions ``open()`` would give a new file: ``0o666`` less the umask."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_write(path, write_fn, *, mode: str = "w") -> None:
    """Write ``path`` through ``write_fn(file)`` into a temporary file, then rename.

    A failure or Ctrl-C leaves no partial file behind.  An operating-system
    error (a folder in the way, no permission, a full disk) becomes a
    :class:`MeshFileError` naming the path.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.is_dir():
            raise IsADirectoryError(21, "is a folder")
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=str(path.parent))
    except OSError as exc:
        raise MeshFileError(f"{path}: cannot write the file ({exc.strerror or exc}); give a file "
                            "path in a folder you can write to.") from exc
    try:
        with os.fdopen(fd, mode) as f:
            write_fn(f)
        os.chmod(tmp, _new_file_mode())     # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError) and not isinstance(exc, MeshFileError):
            raise MeshFileError(f"{path}: writing the file failed ({exc.strerror or exc}); nothing "
                                "was written: check the free space and permissions.") from exc
        raise


def save(path, mesh: TriMesh, uv=None) -> None:
    """Write ``mesh`` (and ``uv: (n, 2)``) as OBJ: ``v``, per-vertex ``vt``, faces ``f a/a b/b c/c``.

    Vertices keep the mesh's order.  The file is written to a temporary name
    and renamed, so it never exists half-written.

    Example::

        jp.save("out.obj", mesh, uv)
    """
    V = np.asarray(mesh.vertices, np.float64)
    F = mesh.faces + 1
    if uv is None:
        uv = mesh.uv
    if uv is not None:
        uv = np.asarray(uv, np.float64)
        if uv.shape != (V.shape[0], 2):
            raise MeshError(f"save: uv must have shape ({V.shape[0]}, 2), got {uv.shape}.")

    def write(f):
        f.write("# written by jaxparam\n")
        np.savetxt(f, V, fmt="v %.17g %.17g %.17g")
        if uv is not None:
            np.savetxt(f, np.nan_to_num(uv), fmt="vt %.17g %.17g")
            np.savetxt(f, np.repeat(F, 2, axis=1), fmt="f %d/%d %d/%d %d/%d")
        else:
            np.savetxt(f, F, fmt="f %d %d %d")

    atomic_write(path, write)
