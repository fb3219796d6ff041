"""File input and output: meshes (:mod:`.meshes`), point sets (:mod:`.points`) and the
all-or-nothing writer every output goes through (:mod:`.files`).

``jp.load``, ``jp.save`` and ``jp.load_points`` are these functions.
"""
from .files import atomic_write, existing_file, read_text
from .meshes import load, read_obj, read_off, save
from .points import load_points

__all__ = ["load", "save", "read_obj", "read_off", "load_points", "atomic_write",
           "existing_file", "read_text"]
