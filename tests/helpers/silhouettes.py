"""Silhouette cases shared by the silhouette tests (tests/renderers/test_silhouettes.py,
test_points_coverage.py): render settings for a variant and AA mode, coverage IoU against a dense
analytic silhouette, and small SH glyph fields with their reference."""
import paramlod as pl
from paramlod.app.bench import peers


def settings_for(variant, aa, threshold=84.0, detail_levels=False):
    rs = pl.RenderSettings()
    rs.lod.threshold = (threshold, threshold)
    rs.tess.l_max, rs.tess.l_min = 64.0, 8.0
    rs.tess.detail_levels = detail_levels
    rs.apply_aa(aa, variant=variant)
    return rs


def iou_of(frame, reference) -> float:
    mask = frame.color[..., 3] >= 0.5
    return 1.0 - peers.silhouette_error(mask, reference)


def glyph_case(order, px):
    spec = peers.scene_spec(f"glyphs{order}", (2 * px, 2 * px), grid=2)
    field = peers.glyph_field(order, 2)
    return peers.paramlod_scene(spec, field), peers.camera_of(spec), peers.reference_silhouette(spec, field)[0]
