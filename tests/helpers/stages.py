"""A scene's LOD stage and device buffers outside the frame driver, for tests of the stage itself."""
from __future__ import annotations

from paramlod.lod.stage import LodStage
from paramlod.lod.uploads import SceneBuffers
from paramlod.renderers.shading import LIGHT


class ParametricStage:
    def __init__(self, scene):
        self.lod = LodStage(scene.functions())
        self.buffers = SceneBuffers(LIGHT)

    def upload(self, scene, camera) -> dict:
        return self.buffers.upload(scene, camera)

    def render_list(self, scene, camera, lod, tiers=None):
        """The LOD stage run once for ``camera`` (``tiers``: hybrid tiers 1 and 2's divisors):
        (render list, per-step stats)."""
        dev = self.upload(scene, camera)
        _, n, steps, _ = self.lod.run(dev["inst"], dev["domains"], dev["cam"], lod, tiers=tiers,
                                      one_sided=dev["one_sided"])   # the kind of stage a renderer builds
        return self.lod.read_render_list(n), steps
