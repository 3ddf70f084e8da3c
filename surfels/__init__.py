"""Blue surfels (Jähn 2013; Brandt et al. 2019): progressive blue-noise sampling of meshes and
parametric objects into one ordered array of surfels in which every prefix is an even sampling,
and the prefix renderer that draws as many as the view needs. See docs/surfels.md.

This package is the runtime (the file format and the renderer). The offline builder (sources,
G-buffers, views, the sampler and its numpy twin) is ``paramlod.surfels.build``; the runtime room
may not import it (tests/test_layers.py), so its names are re-exported there, not here."""
from paramlod.errors import SurfelError
from paramlod.surfels.format import SurfelSet, load_surfels, packing_constant
from paramlod.surfels.render import (FixedCount, FixedSize, FrameTimeAdaptive, choose_prefix, default_camera,
                                     draw_surfels, render_surfels)

__all__ = [
    "SurfelError", "SurfelSet", "load_surfels", "packing_constant", "FixedCount", "FixedSize",
    "FrameTimeAdaptive", "choose_prefix", "default_camera", "draw_surfels", "render_surfels",
]
