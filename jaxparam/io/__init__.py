"""File input and output: meshes (:mod:`.meshes`, with one file per format: :mod:`.obj`,
:mod:`.ply`, :mod:`.off`, :mod:`.gltf`), point sets (:mod:`.points`), ``trimesh`` interop
(:mod:`.interop`), texture images (:mod:`.texture`) and the all-or-nothing writer every
output goes through (:mod:`.files`).

``jp.load``, ``jp.save`` and ``jp.load_points`` are these functions.
"""
from .files import atomic_write, existing_file, read_text
from .interop import as_mesh, from_trimesh, split_seams, to_trimesh
from .meshes import WRITE_FORMATS, check_output_format, load, read_arrays, read_obj, read_off, read_ply, save
from .points import load_points
from .texture import checker_texture

__all__ = ["load", "save", "read_obj", "read_off", "read_ply", "read_arrays", "load_points", "atomic_write",
           "existing_file", "read_text", "check_output_format", "WRITE_FORMATS", "to_trimesh",
           "from_trimesh", "as_mesh", "split_seams", "checker_texture"]
