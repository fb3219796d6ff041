"""Pictures: the UV layout coloured by distortion, a checkerboard textured per pixel on
the surface, remeshes and iso-parameter curves.

Every function returns a matplotlib Figure (displayed by Jupyter, ``plt.show()`` or
``fig.savefig``) and saves it when given a ``path``; 150 dpi by default.  No backend is
forced: matplotlib's own choice stands (Agg on a machine without a display).  3D views are
rasterized per pixel with an orthographic camera (:mod:`.raster`): one scale on both
screen axes, so a sphere is round, and the surface fills the frame.

Modules: :mod:`.common` (figure, saving, robust colour limits, flipped/degenerate
counts), :mod:`.raster` (the z-buffer rasterizer), :mod:`.layout` (:func:`plot_uv`),
:mod:`.surface` (:func:`plot_checkerboard`, :func:`plot_remesh`,
:func:`plot_isocurves`).
"""
from .common import DPI, FaceStates, RobustLimits, face_states, robust_limits
from .layout import plot_uv
from .surface import checker_image, plot_checkerboard, plot_isocurves, plot_remesh

__all__ = ["plot_uv", "plot_checkerboard", "plot_isocurves", "plot_remesh", "face_states",
           "FaceStates", "robust_limits", "RobustLimits", "checker_image", "DPI"]
