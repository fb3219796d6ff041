"""jaxparam: differentiable parameterization of triangle meshes and point sets (Floater & Hormann).

Importing jaxparam turns on JAX's float64 mode (``jax_enable_x64``): every
computation of the library is double precision, and so are the JAX arrays you
create after the import.  Import jaxparam (or set ``JAX_ENABLE_X64=1``) before
creating arrays you pass to it.

It also turns on JAX's persistent compilation cache in the user's cache folder, so a second
process reuses compiled kernels (``JAXPARAM_CACHE`` moves it, ``JAXPARAM_CACHE=off`` turns it
off; ``jp.config.compile_cache`` changes it at run time).

``import jaxparam`` does not import JAX itself: both settings are applied when JAX loads,
whoever imports it (an import hook, :func:`jaxparam.lazy_jax.when_jax_loads`), or at once
when it is already loaded.  Submodules and functions load on first use (PEP 562), and the
NumPy paths (``jp.load``, ``jp.convex_map(..., host=True)``, ``jp.distortion``, ``jaxparam
flatten`` with a linear method) run without JAX ever loading.

Example::

    import jaxparam as jp
    mesh = jp.load("camelhead.off")
    uv = jp.convex_map(mesh, weights="shape_preserving", boundary="circle")
    print(jp.distortion(mesh, uv))
"""
import importlib as _importlib
import sys as _sys
import types as _types

from .errors import (  # cheap: no numpy
    ArgumentTypeError, DegenerateFaceError, JaxparamError, MeshError, MeshFileError,
    NonManifoldError, PointCloudError, SolverError, TopologyError,
)
from .lazy_jax import when_jax_loads as _when_jax_loads
from .settings import config, configure_jax as _configure_jax

# float64 and the compilation cache, now if JAX is loaded, else the moment anything imports it
# (jaxparam's own modules or the user's ``import jax``): importing jaxparam imports no JAX.
_when_jax_loads(_configure_jax)

__version__ = "0.1.0"

#: Public names that live in a submodule: name -> (module, attribute).
_NAMES = {
    "TriMesh": ("mesh", "TriMesh"),
    "load": ("io", "load"), "save": ("io", "save"),
    "convex_map": ("linear", "convex_map"), "least_squares_map": ("linear", "least_squares_map"),
    "DistortionReport": ("metrics", "DistortionReport"), "distortion": ("metrics", "distortion"),
    "ENERGIES": ("energies", "ENERGIES"), "Energy": ("energies", "Energy"),
    "energy": ("energies", "energy"),
    "MinimizeResult": ("optimize", "MinimizeResult"), "minimize": ("optimize", "minimize"),
    "Reconstruction": ("points", "Reconstruction"), "load_points": ("points", "load_points"),
    "meshless_map": ("points", "meshless_map"),
    "reconstruct_surface": ("points", "reconstruct_surface"),
    "fit_surface": ("fitting", "fit_surface"),
    "Remesh": ("remesh", "Remesh"), "remesh": ("remesh", "remesh"),
    "manifold_map": ("manifold", "manifold_map"),
    "to_trimesh": ("io", "to_trimesh"), "from_trimesh": ("io", "from_trimesh"),
    "as_mesh": ("io", "as_mesh"), "checker_texture": ("io", "checker_texture"),
    "boundary_loop": ("boundary", "boundary_loop"),
    "atlas": ("atlas", "atlas"), "Atlas": ("atlas", "Atlas"), "atlas_uv": ("atlas", "atlas_uv"),
}

#: Submodules reachable as ``jp.<name>``.
_MODULES = (
    "errors", "tol", "options", "topology", "triangles", "subdivision", "io", "disk", "geometry",
    "boundary", "weights", "sparse", "combination", "linear", "metrics", "shapes", "energies",
    "optimize", "points", "fitting", "plot", "wavelets", "manifold", "distance", "settings",
    "progress", "mesh",
)

#: Names that are both a submodule and a public function (``jp.remesh`` is the function; the
#: module is ``sys.modules["jaxparam.remesh"]``).  Importing the submodule must not replace
#: the function on the package.
_SHADOWED = {name for name, (module, attr) in _NAMES.items() if name == module}


class _Package(_types.ModuleType):
    """The package's module type: keeps a function that shares its name with a submodule."""

    def __setattr__(self, name, value):
        if name in _SHADOWED and isinstance(value, _types.ModuleType):
            return                                   # the import system binding the submodule
        super().__setattr__(name, value)


def __getattr__(name):
    if name in _NAMES:
        module, attr = _NAMES[name]
        value = getattr(_importlib.import_module(f"{__name__}.{module}"), attr)
    elif name in _MODULES:
        value = _importlib.import_module(f"{__name__}.{name}")
    else:
        raise AttributeError(f"module 'jaxparam' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


_sys.modules[__name__].__class__ = _Package

__all__ = [
    "TriMesh", "load", "save", "convex_map", "least_squares_map", "distortion",
    "DistortionReport", "JaxparamError", "MeshError", "NonManifoldError", "TopologyError",
    "DegenerateFaceError", "PointCloudError", "MeshFileError", "SolverError", "ArgumentTypeError",
    "errors", "tol", "topology", "geometry", "boundary", "weights", "sparse", "linear",
    "metrics", "shapes", "energies", "optimize", "energy", "Energy", "ENERGIES", "minimize",
    "MinimizeResult", "points", "load_points", "meshless_map", "reconstruct_surface",
    "fitting", "fit_surface", "plot", "remesh", "wavelets", "manifold", "manifold_map",
    "options", "triangles", "subdivision", "io", "disk", "combination", "Reconstruction", "Remesh",
    "config", "distance", "to_trimesh", "from_trimesh", "as_mesh", "checker_texture",
    "boundary_loop", "atlas", "Atlas", "atlas_uv",
]
