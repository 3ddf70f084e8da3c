"""Blue surfels (Jähn 2013; Brandt et al. 2019): progressive blue-noise sampling of meshes and
parametric objects into one ordered array of surfels in which every prefix is an even sampling,
and the prefix renderer that draws as many as the view needs. See docs/surfels.md."""
from .errors import SurfelError
from .format import SurfelSet, load_surfels, packing_constant
from .gbuffer import GBuffer, mesh_gbuffer, scene_gbuffer
from .render import (FixedCount, FixedSize, FrameTimeAdaptive, choose_prefix, default_camera, draw_surfels,
                     render_surfels)
from .sampler import Sampler, sample, sample_gbuffer, sample_mesh, sample_scene
from .sources import TriangleSoup, load_mesh, soup_from_trimesh
from .views import OrthoCamera, fibonacci_directions, make_views

__all__ = [
    "SurfelError", "SurfelSet", "load_surfels", "packing_constant", "GBuffer", "mesh_gbuffer",
    "scene_gbuffer", "FixedCount", "FixedSize", "FrameTimeAdaptive", "choose_prefix", "default_camera",
    "draw_surfels", "render_surfels", "Sampler", "sample", "sample_gbuffer", "sample_mesh", "sample_scene",
    "TriangleSoup", "load_mesh", "soup_from_trimesh", "OrthoCamera", "fibonacci_directions", "make_views",
]
