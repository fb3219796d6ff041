"""UV atlases of any mesh (issue 18): charts, flip-free chart maps, packing into [0, 1]^2.

``jp.atlas(mesh)`` cuts the mesh into disk charts (:mod:`~jaxparam.atlas.charts`),
flattens them all at once (:mod:`~jaxparam.atlas.flatten`), splits and redoes any chart
whose map folds over, and packs them (:mod:`~jaxparam.atlas.pack`) into an
:class:`~jaxparam.atlas.result.Atlas`.
"""
from .build import atlas
from .charts import segment
from .gradients import atlas_uv, chart_pieces
from .pack import Packing, pack_charts
from .result import Atlas, AtlasStats

__all__ = ["atlas", "atlas_uv", "chart_pieces", "Atlas", "AtlasStats", "Packing", "pack_charts", "segment"]
