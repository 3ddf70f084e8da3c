"""RenderSettings: the settings of the LOD stage and of every registered renderer, and the one
mapping of an anti-aliasing mode onto them."""
from __future__ import annotations

from dataclasses import dataclass, field

from paramlod.lod.stage import LodSettings
from paramlod.renderers.aa import parse_aa, supersampling_only
from paramlod.renderers.registry import settings_factory


@dataclass
class RenderSettings:
    lod: LodSettings = field(default_factory=LodSettings)
    points: "PointSettings" = field(default_factory=settings_factory("points"))     # direct variant, surfels
    ssaa: "SsaaSettings" = field(default_factory=settings_factory("points-ssaa"))   # local framebuffer
    tess: "TessSettings" = field(default_factory=settings_factory("tess"))          # levels, spacing, AA
    mesh: "MeshSettings" = field(default_factory=settings_factory("meshlets"))      # cut threshold, culling

    def apply_aa(self, mode, points_only: bool = False):
        """Anti-aliasing ``mode`` (e.g. "4xSS+8xMS") for both renderers: tess takes it whole, the
        points variant its supersampling. ``points_only``: the frame is drawn by the points
        variant alone, so multisampling is an error. Returns the parsed AAMode."""
        self.tess.aa = mode
        self.tess.validate()
        if points_only:
            supersampling_only(mode)
        aa = parse_aa(mode)
        self.points.supersample = aa.ss
        return aa
