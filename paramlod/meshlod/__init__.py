"""Meshes as first-class sources with per-frame level of detail (docs/meshes.md): an offline
cluster DAG (``build``, cached ``.meshlod`` files: ``format``, ``source``), a cut chosen on the
device every frame for every instance (``cut`` + twin), drawn by an OpenCL rasterizer into the
shared key buffers (``raster`` + twin) or by OpenGL indirect draws (``draw``). Importing the
package registers the "mesh" object kind, its renderers and its scene loader (``render``)."""
from paramlod.meshlod.format import MeshLod, load_meshlod, mesh_info, save_meshlod
from paramlod.meshlod.render import MeshSettings
from paramlod.meshlod.source import load_mesh

__all__ = ["MeshLod", "MeshSettings", "load_mesh", "load_meshlod", "mesh_info", "save_meshlod"]
