"""RenderSettings: the settings of the LOD stage and of every registered renderer, and the one
mapping of an anti-aliasing mode onto them."""
from __future__ import annotations

from dataclasses import dataclass, field

from paramlod.lod.stage import LodSettings
from paramlod.renderers.aa import AAMode, local_framebuffer_ss, parse_aa, supersampling_only
from paramlod.renderers.registry import settings_factory


@dataclass
class RenderSettings:
    lod: LodSettings = field(default_factory=LodSettings)
    points: "PointSettings" = field(default_factory=settings_factory("points"))     # direct variant, surfels
    ssaa: "SsaaSettings" = field(default_factory=settings_factory("points-ssaa"))   # local framebuffer
    tess: "TessSettings" = field(default_factory=settings_factory("tess"))          # levels, spacing, AA
    mesh: "MeshSettings" = field(default_factory=settings_factory("meshlets"))      # cut threshold, culling
    # the frame-wide mode apply_aa was given, unless it was noAA (a scene file without `aa` applies
    # its noAA default): points-ssaa checks it can draw it (4xSS or 9xSS), never ignores it
    aa: AAMode | None = None

    def apply_aa(self, mode, points_only: bool = False, variant: str | None = None):
        """Anti-aliasing ``mode`` (e.g. "4xSS+8xMS") for every renderer: tess takes it whole, the
        points variant its supersampling, points-ssaa its 4xSS or 9xSS (``ssaa.ss`` 2 or 3).
        ``points_only``: the frame is drawn by the points variant alone, so multisampling is an
        error. ``variant``: the variant that draws the whole frame; "points-ssaa" makes every
        mode but 4xSS and 9xSS (noAA included) an error now. Other modes reach points-ssaa as
        ``self.aa``, which it refuses when it draws. Returns the parsed AAMode."""
        self.tess.aa = mode
        self.tess.validate()
        if points_only or variant == "points":
            supersampling_only(mode)
        aa = parse_aa(mode)
        if variant == "points-ssaa":
            local_framebuffer_ss(aa)
        self.points.supersample = aa.ss
        self.points.hybrid = aa.hybrid
        if aa.ss in (2, 3):
            self.ssaa.ss = aa.ss
        self.aa = aa if (aa.ss, aa.msaa) != (1, 1) or aa.hybrid or variant == "points-ssaa" else None
        return aa
