"""Files on disk: the checks every reader makes first, and the all-or-nothing writer.

Text rows of numbers are written by :func:`write_rows`.  Every file jaxparam writes (meshes,
JSON reports, batch summaries) goes through
:func:`atomic_write`: a temporary file in the same folder, renamed over the target when
complete, so a failure or Ctrl-C midway never leaves a half-written file.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import IO, Callable

import numpy as np

from ..errors import MeshFileError

__all__ = ["file_path", "existing_file", "read_text", "atomic_write", "write_rows"]


def file_path(path, where: str, hint: str = "") -> Path:
    """``path`` (a ``str`` or ``os.PathLike``) as a :class:`~pathlib.Path`.

    Raises :class:`MeshFileError` naming ``where`` and the type given otherwise (a mesh or an
    array passed where the file name goes: ``jp.save(mesh, "out.obj")``), followed by
    ``hint``, instead of pathlib's ``TypeError``."""
    if not isinstance(path, (str, os.PathLike)):
        raise MeshFileError(f"{where}: the file must be given by its path (a str or "
                            f"os.PathLike), got {type(path).__name__}{hint}.")
    return Path(path)


def existing_file(path, *, what: str = "mesh file") -> Path:
    """``path`` as a :class:`~pathlib.Path`, checked to name an existing file.

    Raises :class:`MeshFileError` (``"{path}: no such file."``, ``"{path}: is a folder, not a
    {what}."``, or a path that is not a path: :func:`file_path`) otherwise; messages show
    ``path`` as given.
    """
    p = file_path(path, f"reading a {what}")
    if not p.exists():
        raise MeshFileError(f"{path}: no such file.")
    if p.is_dir():
        raise MeshFileError(f"{path}: is a folder, not a {what}.")
    return p


def read_text(path) -> str:
    """The text of a mesh file (UTF-8, else Latin-1).

    Raises :class:`MeshFileError` for a missing, unreadable, empty (blank) or binary file.
    """
    p = existing_file(path)
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
        return data.decode("utf-8-sig")     # a byte-order mark (Windows editors) is not text
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _new_file_mode() -> int:
    """The permissions ``open()`` would give a new file: ``0o666`` less the umask."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_write(path, write_fn: Callable[[IO], object], *, mode: str = "w") -> None:
    """Write ``path`` through ``write_fn(file)`` into a temporary file, then rename.

    **Arguments:** ``path`` the target file (its folder is created when missing);
    ``write_fn`` writes the whole content to the open file it is given; ``mode`` the
    ``open`` mode (``"w"`` text, ``"wb"`` bytes).

    A failure or Ctrl-C leaves no partial file behind (an existing ``path`` keeps its old
    content).  An operating-system error (a folder in the way, no permission, a full
    disk) becomes a :class:`MeshFileError` naming the path.  The file gets the usual
    permissions of a new file (``0o666`` less the umask).
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


def write_rows(f, fmt: str, rows, chunk: int = 65536) -> None:
    """Write ``rows (k, c)`` to the open text file ``f``, one ``fmt % row`` line each (``fmt``
    ends in a newline), as ``np.savetxt`` would but 3x faster: one ``%`` over a block of rows."""
    rows = np.asarray(rows)
    for s in range(0, rows.shape[0], chunk):
        block = rows[s:s + chunk]
        f.write((fmt * block.shape[0]) % tuple(block.ravel().tolist()))
