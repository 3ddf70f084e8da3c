"""Meshes as first-class sources with per-frame level of detail (docs/meshes.md): an offline
cluster DAG (``build``, cached ``.meshlod`` files: ``format``, ``source``), a cut chosen on the
device every frame for every instance (``cut`` + twin), drawn by an OpenCL rasterizer into the
shared key buffers (``raster`` + twin) or by OpenGL indirect draws (``draw``). Skinned glTF meshes
(docs/skinning.md: ``skinned``, ``skin`` + twin, conservative bounds ``build/skin_bounds`` and their
cull ``skin_cull`` + twin) are drawn by the same renderers. Importing the package registers the
"mesh" object kind, its renderers and its scene loaders (``render``)."""
from paramlod.meshlod.format import MeshLod, load_meshlod, mesh_info, save_meshlod
from paramlod.meshlod.render import MeshSettings
from paramlod.meshlod.skinned import Rig, SkinnedMesh, load_skinned
from paramlod.meshlod.source import load_mesh

__all__ = ["MeshLod", "MeshSettings", "load_mesh", "load_meshlod", "mesh_info", "save_meshlod", "Rig", "SkinnedMesh", "load_skinned"]
