"""Tessellation renderer (paramlod/tess.py), its GLSL code generation and the composition of variants.

Small images only: tessellation on llvmpipe is about 100x slower than on a GPU.
"""
import math
import warnings

import numpy as np
import pytest
import sympy as sp
from conftest import iou, sphere_disc
from helpers.stages import ParametricStage

import paramlod as pl
from paramlod.pipeline.composite import composite
from paramlod.pipeline.driver import render_passes
from paramlod.errors import FunctionError, SceneError
from paramlod.core.frame import Frame
from paramlod.lod.stage import LodSettings
from paramlod.lod.patches import RENDER_DTYPE
from paramlod.function.probes import glsl_surface
from paramlod.function.registry import all_functions, get_function
from paramlod.renderers import tess
from paramlod.renderers.tess import AAMode, TessRenderer, TessSettings, lod_divisor, parse_aa


def render_tess(scene, camera, settings=None, lod_settings=None):
    """A frame of the tess variant through the frame driver."""
    rs = pl.RenderSettings(tess=settings or TessSettings(), lod=lod_settings or LodSettings())
    return pl.render(scene, camera, variant="tess", settings=rs)


def erode(mask, r=1):
    """Pixels whose (2r+1)^2 neighbourhood lies inside ``mask`` (image border counts as outside)."""
    m = np.pad(mask, r, constant_values=False)
    out = np.ones_like(mask)
    h, w = mask.shape
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            out &= m[dy:dy + h, dx:dx + w]
    return out


def local_range(a):
    """max - min over each pixel's 3x3 neighbourhood (NaN = not covered, ignored)."""
    p = np.pad(a, 1, constant_values=np.nan)
    h, w = a.shape
    stack = np.stack([p[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # all-NaN neighbourhoods: NaN
        return np.nanmax(stack, axis=0) - np.nanmin(stack, axis=0)


def coverage_reference(camera, k=16):
    """Analytic disc coverage of the unit sphere, supersampled k x k per pixel."""
    w, h = camera.size
    disc, _ = sphere_disc(camera.with_size((w * k, h * k)))
    return disc.reshape(h, k, w, k).mean(axis=(1, 3))


# --- modes and settings -------------------------------------------------------------------------
def test_aa_modes_parse_and_divide_the_threshold():
    assert parse_aa("noAA") == AAMode(1, 1)
    assert parse_aa("8xMS") == parse_aa("msaa8") == AAMode(1, 8)
    assert parse_aa("4xSS") == parse_aa("ssaa2x2") == AAMode(2, 1)
    assert parse_aa("9xSS") == parse_aa("ssaa3x3") == AAMode(3, 1)
    assert parse_aa("16xSS") == AAMode(4, 1)
    assert parse_aa("4xSS+8xMS") == parse_aa("8xMS+4xSS") == AAMode(2, 8)
    assert parse_aa("4xSS+8xMS").samples_per_pixel == 32
    assert lod_divisor("noAA") == 1
    # by default the LOD stage measures in the supersampled target's pixels; MSAA adds no patches
    assert lod_divisor("8xMS") == 1
    assert lod_divisor("4xSS") == pytest.approx(2)
    assert lod_divisor("4xSS+8xMS") == pytest.approx(2)
    # msaa_lod: sqrt(samples per pixel), the hybrid scheme's guideline
    assert lod_divisor("8xMS", msaa_lod=True) == pytest.approx(math.sqrt(8))
    assert lod_divisor("4xSS+8xMS", msaa_lod=True) == pytest.approx(math.sqrt(32))
    assert lod_divisor("8xMS", max_samples=4, msaa_lod=True) == pytest.approx(2)  # capped to what a device has
    for bad in ["", "3xMS", "16xMS", "8xSS", "4xSS+4xSS", "2xMS+4xMS", "fancy", None]:
        with pytest.raises(SceneError):
            parse_aa(bad)


@pytest.mark.parametrize("kw, word", [
    ({"mode": "smooth"}, "mode"), ({"spacing": "odd"}, "spacing"), ({"l_max": 65}, "l_max"),
    ({"l_min": 0}, "l_min"), ({"l_min": 32, "l_max": 16}, "l_min"), ({"levels": (8, 100)}, "outer"),
    ({"levels": "x"}, "levels"), ({"overlap": -0.1}, "overlap"), ({"aa": "7xMS"}, "7xMS"),
])
def test_bad_settings_are_named(kw, word):
    with pytest.raises(SceneError, match=word):
        TessSettings(**kw).validate()


# --- generated GLSL -----------------------------------------------------------------------------


def _builtin_names():
    return sorted(all_functions())


@pytest.mark.parametrize("name", _builtin_names())
def test_glsl_matches_numpy(name):
    """The generated GLSL, run on the GL device, gives the numpy reference's f and partials."""
    fn = get_function(name)
    uu, vv = np.meshgrid(np.linspace(*fn.u_range, 13), np.linspace(*fn.v_range, 11))
    pos, du, dv = glsl_surface(fn, uu, vv)
    P, DU, DV = fn.surface(uu, vv)
    size = float(np.nanmax(np.abs(P))) or 1.0
    ok = np.isfinite(P).all(-1)
    assert np.array_equal(np.isfinite(pos).all(-1), ok)
    # float32 on the device; roots such as |x|^(1/4) near 0 amplify rounding: 1e-3 of the size
    assert np.max(np.abs(pos[ok] - P[ok])) <= 1e-3 * size
    # partials are compared where the surface is regular: both finite, bounded and stable. Where
    # a small step in (u, v) changes them a lot, or one of them is unbounded (|x|^(1/4) at x = 0 in
    # the hearts, along v = pi), float32 may land on the singularity itself and give 0 * inf = NaN
    # for the other one too (NVIDIA's sin(pi) is exactly 0, Mesa's is not)
    hu, hv = 1e-5 * (fn.u_range[1] - fn.u_range[0]), 1e-5 * (fn.v_range[1] - fn.v_range[0])
    _, DU2, DV2 = fn.surface(uu + hu, vv + hv)
    regular = np.ones(uu.shape, bool)
    for want, near in ((DU, DU2), (DV, DV2)):
        tol = 1e-3 * (size + np.nanmax(np.abs(want[np.abs(want).max(-1) < 100 * size])))
        regular &= (np.isfinite(want).all(-1) & (np.abs(want).max(-1) < 100 * size)
                    & (np.abs(near - want).max(-1) < tol))
    assert regular.mean() > 0.6   # 0.69-1 for the built-ins
    for got, want in ((du, DU), (dv, DV)):
        assert np.max(np.abs(got[regular] - want[regular])) <= 1e-3 * (size + np.abs(want[regular]).max())


def test_function_without_glsl_form_is_named():
    @pl.parametric(u=(0, 1), v=(0, 1))
    def erf_sheet(u, v):
        return u, v, sp.erf(u)

    with pytest.raises(FunctionError, match="erf_sheet.*erf|erf.*erf_sheet"):
        TessRenderer([erf_sheet])


def test_shader_compile_error_shows_generated_lines():
    from paramlod.device.context import gl_context
    from paramlod.renderers.tess import _program

    bad = "#version 450 core\nout vec4 c;\nvoid main() {\n    c = vec4(no_such_name);\n}\n"
    good = "#version 450 core\nvoid main() { gl_Position = vec4(0.0); }\n"
    with pytest.raises(FunctionError) as exc:
        _program(gl_context(), {"vertex_shader": good, "fragment_shader": bad}, [get_function("sphere")])
    msg = str(exc.value)
    assert "fragment_shader" in msg and "no_such_name" in msg and ">    4 |" in msg and "'sphere'" in msg


# --- silhouettes, depth and holes ---------------------------------------------------------------
VIEWS = {
    "sphere": ((0.0, 0.0, 3.0), (0.0, 0.0, 0.0)),
    "torus": ((0.0, 1.9, 1.9), (0.0, 0.0, 0.0)),
    "johis_heart": ((0.0, 0.0, 2.6), (0.0, 0.0, 0.0)),
}


@pytest.mark.parametrize("name", sorted(VIEWS))
def test_tess_and_points_agree(name):
    """Silhouettes IoU >= 0.98 at 256x256. Depths, where both cover a pixel whose 3x3 neighbourhood
    both cover: the point renderer keeps the nearest sample anywhere in the pixel, the tessellation
    the pixel centre, so they differ by at most the depth range over the 3x3 neighbourhood plus
    0.1% of the depth, and by at most 0.3% of the depth in the median."""
    scene = pl.Scene()
    scene.add(name)
    eye, target = VIEWS[name]
    cam = pl.Camera.look_at(eye, target, size=(256, 256))
    t = render_tess(scene, cam)
    p = pl.render(scene, cam)
    assert t.stats["variant"] == "tess" and t.stats["render_patches"] > 0 and t.stats["triangles"] > 0
    assert iou(t.coverage, p.coverage) >= 0.98
    both = erode(t.coverage & p.coverage, 1)
    diff = np.abs(t.depth[both] - p.depth[both])
    # the point sample lies somewhere in the pixel: its depth is within the surface's depth range
    # over the pixel, bounded by the tessellation's range over the 3x3 neighbourhood
    spread = local_range(np.where(t.coverage, t.depth, np.nan))[both]
    assert np.all(diff <= spread + 1e-3 * t.depth[both])
    assert np.median(diff / t.depth[both]) <= 0.003
    # the same shading: colours close, normals nearly parallel
    assert np.median(np.abs(t.color[both, :3] - p.color[both, :3])) <= 0.01
    assert np.median(np.sum(t.normal[both] * p.normal[both], axis=-1)) >= 0.999
    assert set(np.unique(t.object_id[t.coverage])) == {1}
    assert np.all(t.object_id[~t.coverage] == 0) and np.all(np.isinf(t.depth[~t.coverage]))


def test_sphere_depth_matches_the_analytic_sphere():
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0, 0, 3), (0, 0, 0), size=(128, 128))
    f = render_tess(scene, cam)
    disc, depth = sphere_disc(cam)
    assert iou(disc, f.coverage) >= 0.995
    inner = erode(disc, 1)
    assert np.all(f.coverage[inner])
    # away from the silhouette the chords are within 0.05% of the depth; towards it the surface
    # turns edge-on and a sub-pixel chord error becomes a larger depth error, bounded by the depth
    # range over the pixel's neighbourhood
    core = sphere_disc(cam, radius=0.8)[0]
    assert np.max(np.abs(f.depth[core] - depth[core]) / depth[core]) <= 5e-4
    spread = local_range(np.where(disc, depth, np.nan))
    assert np.all(np.abs(f.depth[inner] - depth[inner]) <= spread[inner] + 5e-4 * depth[inner])


@pytest.mark.parametrize("aa", ["noAA", "4xSS+4xMS"])
def test_nothing_of_the_previous_frame_shows(aa):
    """Only colour and depth are cleared between frames: depth, normal and id of a larger earlier
    frame must not reappear where the next frame draws nothing."""
    big, small = pl.Scene(), pl.Scene()
    big.add("sphere", transform=pl.scale(1.4))
    small.add("sphere", transform=pl.scale(0.5))
    cam = pl.Camera.look_at((0, 0, 3), (0, 0, 0), size=(48, 48))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # sample counts capped on small devices
        render_tess(big, cam, TessSettings(aa=aa))
        f = render_tess(small, cam, TessSettings(aa=aa))
    empty = ~f.coverage
    assert empty.sum() > 0.5 * empty.size
    assert np.all(np.isinf(f.depth[empty])) and not f.object_id[empty].any() and not f.normal[empty].any()
    disc = sphere_disc(cam, radius=0.5)[0]
    # with AA a pixel counts as covered when any of its samples is: the edge ring adds a little
    assert iou(disc, f.coverage) >= (0.95 if aa == "noAA" else 0.85)


def test_many_patches_fixed_levels_leave_no_hole():
    """A sphere split into many patches (non-uniform splits, T-junctions) at fixed levels: every
    pixel inside the analytic disc (shrunk by one pixel for the polygonal silhouette) is drawn, and
    by the front surface (a crack would show the back of the sphere, far deeper)."""
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0, 0, 3), (0, 0, 0), size=(128, 128))
    f = render_tess(scene, cam, TessSettings(mode="fixed", levels=(6, 6)), LodSettings(threshold=(12.0, 12.0)))
    assert f.stats["render_patches"] >= 100
    disc, depth = sphere_disc(cam)
    inner = erode(disc, 1)
    assert not np.any(~f.coverage[inner])
    spread = local_range(np.where(disc, depth, np.nan))
    assert np.all(np.abs(f.depth[inner] - depth[inner]) <= spread[inner] + 2e-3 * depth[inner])


def test_equal_patches_watertight_without_overlap():
    """Equal-size patches (an initial 8x4 grid, no splits) with overlap off and adaptive levels:
    shared edges get equal outer levels from the edge's own samples, so nothing shows through."""
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0.3, 0.8, 2.9), (0, 0, 0), size=(128, 128))
    f = render_tess(scene, cam, TessSettings(overlap=0.0, base_level=16, l_min=2),
                    LodSettings(threshold=(1e4, 1e4), initial_grid=(8, 4)))
    assert f.stats["render_patches"] >= 16
    disc, depth = sphere_disc(cam)
    inner = erode(disc, 1)
    assert np.all(f.coverage[inner])
    spread = local_range(np.where(disc, depth, np.nan))
    assert np.all(np.abs(f.depth[inner] - depth[inner]) <= spread[inner] + 2e-3 * depth[inner])


def test_small_draw_batches_draw_the_same_frame(monkeypatch):
    """On llvmpipe the render list is drawn in runs whose bound on generated vertices stays within
    LLVMPIPE_VERTEX_BUDGET (a large draw of clipped triangles is slow there, and one past 65,536
    vertices loses triangles). A close-up torus, partly outside the frame (clipped triangles), drawn
    with that budget and with one ten times larger: the same triangles, pixels and depths, and the
    runs cover every patch once, in order, each within the budget unless it is a single patch."""
    scene = pl.Scene()
    scene.add("torus")
    cam = pl.Camera.look_at((0.35, 0.45, 0.3), (0, 0, 0), size=(96, 96), near=0.05)
    small = render_tess(scene, cam)
    monkeypatch.setattr(tess, "LLVMPIPE_VERTEX_BUDGET", 10 * tess.LLVMPIPE_VERTEX_BUDGET)
    large = render_tess(scene, cam)
    assert small.stats["triangles"] == large.stats["triangles"] > 0
    assert np.array_equal(small.color, large.color) and np.array_equal(small.depth, large.depth)
    monkeypatch.undo()

    settings = TessSettings()
    threshold = small.stats["threshold"]
    stage = ParametricStage(scene)
    dev = stage.upload(scene, cam)
    n = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], LodSettings(threshold=tuple(threshold)))[1]
    records = stage.lod.read_render_list(n)
    r = TessRenderer(scene.functions())
    batches = r.draw_batches(records, settings, threshold)
    assert [first for first, _ in batches] == list(np.cumsum([0] + [c for _, c in batches])[:-1])
    assert sum(c for _, c in batches) == n
    if "llvmpipe" in str(r.ctx.info["GL_RENDERER"]).lower():
        bound = tess.vertex_bound(records["ext"], settings, threshold)
        assert len(batches) > 1
        for first, count in batches:
            assert count == 1 or bound[first:first + count].sum() <= tess.LLVMPIPE_VERTEX_BUDGET


@pytest.mark.parametrize("tessellator", ["hardware", "grid"])
def test_nan_vertices_are_dropped_and_counted(tessellator):
    @pl.parametric(u=(-1, 1), v=(-1, 1))
    def cap(u, v):
        return u, v, sp.sqrt(0.8 - u ** 2 - v ** 2)   # NaN in the corners of the domain

    scene = pl.Scene()
    scene.add(cap)
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(64, 64))
    f = render_tess(scene, cam, TessSettings(tessellator=tessellator))
    assert f.stats["tessellator"] == tessellator and f.stats["nan_vertices"] > 0
    assert f.coverage.sum() > 100
    assert np.all(np.isfinite(f.color)) and not np.any(np.isnan(f.depth))


# --- anti-aliasing ------------------------------------------------------------------------------
def _aa_error(mode, cam, ref, scene):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # capped MSAA is tested on its own
        f = render_tess(scene, cam, TessSettings(aa=mode))
    return f, float(np.abs(f.color[..., 3] - ref).mean())


def test_aa_coverage_error_falls_with_samples():
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(64, 64))
    ref = coverage_reference(cam, 16)
    edge_zone = ~erode(ref >= 1.0, 1) & ~erode(ref <= 0.0, 1)
    results = {}
    for mode in ["noAA", "2xMS", "4xMS", "8xMS", "4xSS", "9xSS", "16xSS", "4xSS+4xMS", "16xSS+4xMS"]:
        f, err = _aa_error(mode, cam, ref, scene)
        spp = f.stats["ssaa"] ** 2 * f.stats["msaa_samples_device"]
        results[mode] = (spp, err)
        a = f.color[..., 3]
        partial = (a > 0) & (a < 1)
        if mode == "noAA":
            assert not partial.any()
        else:   # fractional coverage, on edge pixels only
            assert partial.sum() >= 40 and np.all(edge_zone[partial])
    # MSAA: the error falls with each distinct sample count the device really gives
    ms = sorted({results[m] for m in ["noAA", "2xMS", "4xMS", "8xMS"]})
    assert len(ms) >= 2
    assert all(b[1] < a[1] for a, b in zip(ms, ms[1:])), ms
    # SSAA 2x2 < 3x3 < 4x4, and SS+MS beats both of its parts
    errs = [results[m][1] for m in ["noAA", "4xSS", "9xSS", "16xSS"]]
    assert all(b < a for a, b in zip(errs, errs[1:])), errs
    assert results["16xSS+4xMS"][1] < results["4xSS+4xMS"][1] < results["4xSS"][1]
    assert results["16xSS+4xMS"][1] < results["16xSS"][1]


def test_msaa_request_above_the_device_is_capped_and_said():
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(32, 32))
    r = TessRenderer(scene.functions())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        f = render_tess(scene, cam, TessSettings(aa="4xSS+8xMS", msaa_lod=True))
        plain = render_tess(scene, cam, TessSettings(aa="4xSS+8xMS"))
    # without msaa_lod the LOD stage measures in supersampled pixels only: fewer, larger patches
    assert plain.stats["lod_divisor"] == 2
    assert plain.stats["render_patches"] < f.stats["render_patches"]
    msgs = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert f.stats["msaa_requested"] == 8
    if r.max_samples >= 8:
        assert f.stats["msaa_samples"] == 8 and not f.stats["warnings"]
        assert f.stats["lod_divisor"] == pytest.approx(math.sqrt(32))
    else:
        assert f.stats["msaa_samples"] < 8
        assert any("8xMS requested" in m and "at most" in m for m in msgs)
        assert any("8xMS requested" in m for m in f.stats["warnings"])
        assert f.stats["lod_divisor"] == pytest.approx(2 * math.sqrt(f.stats["msaa_samples"]))
    assert f.stats["aa"] == "4xSS+8xMS" and f.stats["ssaa"] == 2


# --- renderer input -----------------------------------------------------------------------------
def test_draw_checks_its_input():
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(32, 32))
    r = TessRenderer(scene.functions())
    with pytest.raises(SceneError, match="RENDER_DTYPE"):
        r.draw(np.zeros(3, np.float32), 3, scene, cam)
    good = np.zeros(2, RENDER_DTYPE)
    with pytest.raises(SceneError, match="outside"):
        r.draw(good, 5, scene, cam)
    bad_inst = good.copy()
    bad_inst["inst"] = 7
    with pytest.raises(SceneError, match="instance"):
        r.draw(bad_inst, 2, scene, cam)
    other = pl.Scene()
    other.add("torus")
    with pytest.raises(SceneError, match="other functions"):
        r.draw(good, 0, other, cam)
    empty = r.draw(good, 0, scene, cam)   # nothing to draw is a valid, empty frame
    assert not empty.coverage.any() and empty.stats["triangles"] == 0


def test_render_list_transfer_is_reported():
    scene = pl.Scene()
    scene.add("torus")
    cam = pl.Camera.look_at((0, 2, 2), (0, 0, 0), size=(64, 64))
    f = render_tess(scene, cam)
    ms = f.stats["ms"]
    for k in ("render_list_read", "render_list_upload", "render_list", "lod", "draw", "resolve", "total"):
        assert k in ms and ms[k] >= 0
    assert f.stats["render_list_bytes"] == 64 * f.stats["render_patches"]
    # the same frame again, from the state the driver kept (LOD buffers, GL targets)
    g = render_tess(scene, cam)
    assert np.array_equal(g.depth, f.depth) and np.array_equal(g.color, f.color)


# --- composition --------------------------------------------------------------------------------
def _frame(depth, rgb, alpha, oid, spp=1, variant="x"):
    h, w = depth.shape
    color = np.zeros((h, w, 4), np.float32)
    color[..., :3] = rgb
    color[..., 3] = alpha
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = oid
    return Frame(color=color, depth=depth.astype(np.float32), normal=normal,
                 object_id=np.full((h, w), oid, np.uint32) * np.isfinite(depth),
                 stats={"samples_per_pixel": spp, "variant": variant, "ms": {"total": 1.0}})


def test_composite_by_depth_over_and_order():
    inf = np.inf
    d1 = np.array([[1.0, 5.0, inf, 2.0]])
    d2 = np.array([[3.0, 4.0, 6.0, 2.0]])
    a = _frame(d1, (1, 0, 0), np.array([[1.0, 1.0, 0.0, 1.0]]), 1, spp=1, variant="points")
    b = _frame(d2, (0, 0, 1), np.array([[1.0, 1.0, 1.0, 1.0]]), 2, spp=16, variant="tess")
    for frames in ([a, b], [b, a]):   # the result does not depend on the order given
        out = composite(frames)
        assert out.depth.tolist() == [[1.0, 4.0, 6.0, 2.0]]
        assert out.object_id.tolist() == [[1, 2, 2, 2]]   # equal depth: the finer frame (16 spp) wins
        assert out.normal[0, :, 2].tolist() == [1, 2, 2, 2]
        assert out.stats["order"][0] == "points"           # coarsest target first
    # an anti-aliased edge in front blends with what is behind it, not with the background
    front = _frame(np.array([[1.0]]), (1, 0, 0), np.array([[0.25]]), 1)
    back = _frame(np.array([[2.0]]), (0, 0, 1), np.array([[1.0]]), 2)
    out = composite([back, front])
    assert out.color[0, 0].tolist() == pytest.approx([0.25, 0.0, 0.75, 1.0])
    assert out.object_id[0, 0] == 1 and out.depth[0, 0] == 1.0
    alone = composite([front])
    assert alone.color[0, 0].tolist() == pytest.approx([1.0, 0.0, 0.0, 0.25])
    with pytest.raises(SceneError, match="at least one"):
        composite([])
    with pytest.raises(SceneError, match="size"):
        composite([a, _frame(np.ones((2, 2)), (0, 0, 0), np.ones((2, 2)), 1)])


def test_mixed_scene_composites_by_depth():
    """A sphere drawn by points and a torus in front of it drawn by tessellation."""
    def build(variants):
        scene = pl.Scene()
        scene.add("sphere", material=pl.Material(color=(0.8, 0.2, 0.2)), variant=variants[0])
        scene.add("torus", transform=pl.translate(0.5, 0.0, 1.3), material=pl.Material(color=(0.2, 0.8, 0.2)),
                  variant=variants[1])
        return scene

    scene = build(["points", "tess"])
    cam = pl.Camera.look_at((0, 0, 5), (0, 0, 0), size=(96, 96))
    # the passes the frame is composited from (on a GPU a second tess render of the torus may differ
    # where two patches tie in the depth buffer: the render list's order changes from run to run)
    fp, ft = render_passes(scene, cam)
    mixed = composite([fp, ft], background=scene.background)
    assert fp.stats["variant"] == "points" and ft.stats["variant"] == "tess"
    assert set(np.unique(fp.object_id)) == {0, 1} and set(np.unique(ft.object_id)) == {0, 2}
    np.testing.assert_array_equal(mixed.depth, np.minimum(fp.depth, ft.depth))
    with np.errstate(invalid="ignore"):
        nearer_t = ft.depth < fp.depth * (1 - 1e-4)
        nearer_p = fp.depth < ft.depth * (1 - 1e-4)
    assert nearer_t.sum() > 200 and (np.isfinite(fp.depth) & nearer_t).sum() > 100   # real overlap
    assert np.all(mixed.object_id[nearer_t] == 2)
    assert np.all(mixed.object_id[nearer_p] == 1)
    opaque = nearer_t & (ft.color[..., 3] == 1)
    assert np.allclose(mixed.color[opaque], ft.color[opaque], atol=1e-6)
    # the same scene drawn by one variant labels nearly every pixel the same way
    full = pl.render(build([None, None]), cam)
    assert (mixed.object_id == full.object_id).mean() >= 0.97
    assert (pl.render(scene, cam).object_id == mixed.object_id).mean() >= 0.999   # pl.render composites the same
    assert mixed.stats["variant"] == "composite" and len(mixed.stats["passes"]) == 2
