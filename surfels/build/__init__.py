"""Offline surfel building: sources, G-buffers, views, the sampler and its numpy twin.

Modules, each importing only those above it: ``schedule`` (sample keys and the round/level
schedule, shared by the sampler and its twin), ``sources`` (meshes -> triangle soup), ``views``,
``raster_reference`` and ``raster`` (mesh G-buffers in OpenCL and their numpy twin), ``gbuffer``,
``reference`` (numpy twins), ``relax`` (the final host-side relaxation), ``sampler`` (OpenCL; also
samples scene files through ``paramlod.app.scenefile``)."""
from paramlod.surfels.build.gbuffer import GBuffer, mesh_gbuffer, scene_gbuffer
from paramlod.surfels.build.sampler import Sampler, sample, sample_gbuffer, sample_mesh, sample_scene
from paramlod.surfels.build.sources import TriangleSoup, load_mesh, soup_from_trimesh
from paramlod.surfels.build.views import OrthoCamera, fibonacci_directions, make_views

__all__ = [
    "GBuffer", "mesh_gbuffer", "scene_gbuffer", "Sampler", "sample", "sample_gbuffer", "sample_mesh",
    "sample_scene", "TriangleSoup", "load_mesh", "soup_from_trimesh", "OrthoCamera", "fibonacci_directions",
    "make_views",
]
