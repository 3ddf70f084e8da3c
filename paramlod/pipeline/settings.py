"""RenderSettings: the settings of the LOD stage and of every registered renderer, and the one
mapping of an anti-aliasing mode onto them."""
from __future__ import annotations

from dataclasses import dataclass, field

from paramlod.errors import SceneError
from paramlod.lod.stage import LodSettings
from paramlod.renderers.aa import parse_aa
from paramlod.renderers.registry import settings_factory


@dataclass
class RenderSettings:
    lod: LodSettings = field(default_factory=LodSettings)
    points: "PointSettings" = field(default_factory=settings_factory("points"))     # direct variant, surfels
    ssaa: "SsaaSettings" = field(default_factory=settings_factory("points-ssaa"))   # local framebuffer
    tess: "TessSettings" = field(default_factory=settings_factory("tess"))          # levels, spacing, AA

    def apply_aa(self, mode, points_only: bool = False):
        """Anti-aliasing ``mode`` (e.g. "4xSS+8xMS") for both renderers: tess takes it whole, the
        points variant its supersampling. ``points_only``: the frame is drawn by the points
        variant alone, so multisampling is an error. Returns the parsed AAMode."""
        self.tess.aa = mode
        self.tess.validate()
        aa = parse_aa(mode)
        if points_only and aa.msaa > 1:
            raise SceneError(f"anti-aliasing {mode!r}: the points variant supersamples only (4xSS, 9xSS, "
                             f"16xSS); multisampling is a mode of the tess variant")
        self.points.supersample = aa.ss
        return aa

    def of(self, spec):
        """The settings of renderer ``spec`` (a RendererSpec)."""
        return getattr(self, spec.settings)
