"""jaxparam: differentiable parameterization of triangle meshes and point sets (Floater & Hormann).

Importing jaxparam turns on JAX's float64 mode (``jax_enable_x64``): every
computation of the library is double precision, and so are the JAX arrays you
create after the import.  Import jaxparam (or set ``JAX_ENABLE_X64=1``) before
creating arrays you pass to it.

Example::

    import jaxparam as jp
    mesh = jp.load("camelhead.off")
    uv = jp.convex_map(mesh, weights="shape_preserving", boundary="circle")
    print(jp.distortion(mesh, uv))
"""
import jax as _jax

_jax.config.update("jax_enable_x64", True)

from . import errors, tol, options, topology, triangles, subdivision, io, disk  # noqa: E402
from . import geometry, boundary, weights, sparse, combination  # noqa: E402
from . import linear, metrics, shapes, energies, optimize, points, fitting, plot  # noqa: E402
from .errors import (  # noqa: E402
    DegenerateFaceError, JaxparamError, MeshError, MeshFileError, NonManifoldError,
    PointCloudError, SolverError, TopologyError,
)
from .mesh import TriMesh  # noqa: E402
from .io import load, save  # noqa: E402
from .linear import convex_map, least_squares_map  # noqa: E402
from .metrics import DistortionReport, distortion  # noqa: E402
from .energies import ENERGIES, Energy, energy  # noqa: E402
from .optimize import MinimizeResult, minimize  # noqa: E402
from .points import Reconstruction, load_points, meshless_map, reconstruct_surface  # noqa: E402
from .fitting import fit_surface  # noqa: E402
from . import wavelets  # noqa: E402
from .remesh import Remesh, remesh  # noqa: E402  (the function; the module is jaxparam.remesh in sys.modules)
from . import manifold  # noqa: E402
from .manifold import manifold_map  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "TriMesh", "load", "save", "convex_map", "least_squares_map", "distortion",
    "DistortionReport", "JaxparamError", "MeshError", "NonManifoldError", "TopologyError",
    "DegenerateFaceError", "PointCloudError", "MeshFileError", "SolverError",
    "errors", "tol", "topology", "geometry", "boundary", "weights", "sparse", "linear",
    "metrics", "shapes", "energies", "optimize", "energy", "Energy", "ENERGIES", "minimize",
    "MinimizeResult", "points", "load_points", "meshless_map", "reconstruct_surface",
    "fitting", "fit_surface", "plot", "remesh", "wavelets", "manifold", "manifold_map",
    "options", "triangles", "subdivision", "io", "disk", "combination", "Reconstruction", "Remesh",
]
