"""Blue surfels (Jähn 2013; Brandt et al. 2019): progressive blue-noise sampling of meshes and
parametric objects into one ordered array of surfels in which every prefix is an even sampling,
and the prefix renderer that draws as many as the view needs. See docs/surfels.md."""
from paramlod.errors import SurfelError
from paramlod.surfels.format import SurfelSet, load_surfels, packing_constant
from paramlod.surfels.build.gbuffer import GBuffer, mesh_gbuffer, scene_gbuffer
from paramlod.surfels.render import (FixedCount, FixedSize, FrameTimeAdaptive, choose_prefix, default_camera, draw_surfels,
                     render_surfels)
from paramlod.surfels.build.sampler import Sampler, sample, sample_gbuffer, sample_mesh, sample_scene
from paramlod.surfels.build.sources import TriangleSoup, load_mesh, soup_from_trimesh
from paramlod.surfels.build.views import OrthoCamera, fibonacci_directions, make_views

__all__ = [
    "SurfelError", "SurfelSet", "load_surfels", "packing_constant", "GBuffer", "mesh_gbuffer",
    "scene_gbuffer", "FixedCount", "FixedSize", "FrameTimeAdaptive", "choose_prefix", "default_camera",
    "draw_surfels", "render_surfels", "Sampler", "sample", "sample_gbuffer", "sample_mesh", "sample_scene",
    "TriangleSoup", "load_mesh", "soup_from_trimesh", "OrthoCamera", "fibonacci_directions", "make_views",
]
