"""Multi-view hardware tessellation (paramlod/renderers/tess.py draw_views, kernels/tess/
tess_geometry.glsl, gl_targets.LayeredGLTargets): the shared render list drawn into layered
targets, a pass per view or several views a pass through the geometry stage; each view against a
single-view draw of its camera, view chunks past 32 views, empty views, MSAA per layer and the
geometry stage's adaptive levels for the view that needs most.

Small frames only: tessellation on llvmpipe is slow, and each view count compiles a program.
"""
import warnings
from dataclasses import replace

import numpy as np
import pytest

import paramlod as pl
from paramlod.core.views import MAX_VIEWS, Views, cube_faces
from paramlod.device.context import gl_context
from paramlod.device.programs import check_block
from paramlod.errors import SceneError
from paramlod.function.registry import get_function
from paramlod.lod.stage import LodSettings, LodStage
from paramlod.lod.uploads import SceneBuffers
from paramlod.meshlod.draw import VIEW_RECORD, draw_program as mesh_program
from paramlod.renderers.shading import LIGHT
from paramlod.renderers.tess import VIEW_FLOATS, TessRenderer, TessSettings, build_programs, view_chunks

SIZE = (96, 72)
FIXED = TessSettings(mode="fixed", levels=(10, 10))


def axes_scene():
    """A sphere or torus 3 units out along each axis: each face of a cube map at the origin sees
    exactly one of them, whole."""
    s = pl.Scene()
    for i, d in enumerate(((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))):
        at = pl.translate(*(3.0 * np.asarray(d, float)))
        if i % 2:
            s.add("torus", transform=at @ pl.rotate(50, (1, 1, 0)) @ pl.scale(0.7))
        else:
            s.add("sphere", transform=at @ pl.scale(0.8))
    return s


def render_list(scene, cams, settings=None):
    """The render list of one LOD pass for all of ``cams``."""
    views = Views(cams)
    lod, bufs = LodStage(scene.functions()), SceneBuffers(LIGHT)
    d = bufs.upload(scene, views)
    _, n, _, _ = lod.run(d["inst"], d["domains"], d["cam"], settings or LodSettings(), n_views=d["n_views"])
    return lod.read_render_list(n)


def assert_same_image(a, b):
    """Coverage identical, depth within 1e-5 relative, ids and (resolved) colour alike."""
    np.testing.assert_array_equal(a.coverage, b.coverage)
    both = a.coverage & b.coverage
    assert np.all(np.abs(a.depth[both] - b.depth[both]) <= 1e-5 * b.depth[both])
    assert np.all(np.isinf(a.depth[~a.coverage]))
    np.testing.assert_array_equal(a.object_id, b.object_id)
    assert np.abs(a.color - b.color).max() <= 1e-3


def test_view_chunks_spread_views_evenly():
    assert view_chunks(1) == (1, 1)
    assert view_chunks(6) == (6, 1)
    assert view_chunks(32) == (32, 1)
    assert view_chunks(33) == (17, 2)
    assert view_chunks(40) == (20, 2)
    assert view_chunks(64) == (32, 2)
    assert view_chunks(40, most=8) == (8, 5)


@pytest.mark.parametrize("per_pass", [1, 6])
def test_cube_faces_through_the_pipeline_equal_single_view_renders(per_pass):
    """Six cube faces from one LOD pass: each face sees one object that no other face sees, so
    its Frame is the single-view render of its camera (same render list for it), whether each
    face is a pass of its own or the geometry stage draws all six in one."""
    scene = axes_scene()
    cams = cube_faces((0, 0, 0), size=64, near=0.05, far=50)
    rs = pl.RenderSettings(tess=TessSettings(views_per_pass=per_pass))   # adaptive levels
    frames = pl.render_views(scene, cams, variant="tess", settings=rs)
    assert len(frames) == 6
    singles = [pl.render(scene, c, variant="tess", settings=rs) for c in cams]
    for v, (f, s) in enumerate(zip(frames, singles)):
        assert f.coverage.sum() > 200
        assert_same_image(f, s)
        assert f.stats["view"] == v and f.stats["views"] == 6
        assert f.stats["pixels_written"] == int(f.coverage.sum())
        assert f.stats["views_per_pass"] == per_pass and f.stats["passes"] == 6 // per_pass
    # one LOD pass: the shared list holds every face's patches
    assert frames[0].stats["render_patches"] == sum(s.stats["render_patches"] for s in singles)
    total = sum(s.stats["triangles"] for s in singles)   # each face's own object
    if per_pass == 1:   # each face's pass draws the patches it sees (the LOD stage's view masks): its own object
        assert [f.stats["view_patches"] for f in frames] == [s.stats["render_patches"] for s in singles]
        assert [f.stats["view_triangles"] for f in frames] == [s.stats["triangles"] for s in singles]
        assert frames[0].stats["triangles"] == total
    else:   # one tessellation; the geometry stage keeps, per face, the triangles of its object
        assert frames[0].stats["triangles"] == total


@pytest.mark.parametrize("per_pass, settings", [(1, TessSettings()), (2, FIXED)])
def test_two_views_of_one_render_list_equal_single_view_draws(per_pass, settings):
    """Two views that both see the torus, drawn from the same render list: each view equals a
    single-view draw of that list bit for bit (colour, depth, normal, id). A pass per view
    tessellates each view for itself (adaptive levels too); the geometry stage shares one
    tessellation, so the levels must not depend on the view (fixed)."""
    scene = pl.Scene()
    scene.add("sphere", transform=pl.translate(-1.2, 0, 0))
    scene.add("torus", transform=pl.translate(1.0, 0, 0) @ pl.rotate(60, (1, 0, 0)))
    cams = [pl.Camera.look_at((-0.5, 0.5, 4), (0, 0, 0), size=SIZE), pl.Camera.look_at((2.5, 2.0, 2.5), (1, 0, 0), size=SIZE)]
    records = render_list(scene, cams)
    r = TessRenderer(scene.functions())
    settings = replace(settings, views_per_pass=per_pass)
    frames = r.draw_views(records, None, scene, Views(cams), settings)
    singles = [r.draw(records, None, scene, cam, settings) for cam in cams]
    for f, s in zip(frames, singles):
        assert f.coverage.sum() > 500
        np.testing.assert_array_equal(f.depth, s.depth)
        np.testing.assert_array_equal(f.color, s.color)
        np.testing.assert_array_equal(f.normal, s.normal)
        np.testing.assert_array_equal(f.object_id, s.object_id)
        assert f.stats["pixels_written"] == s.stats["pixels_written"]
    assert all(2 in f.object_id for f in frames)
    if per_pass == 1:
        assert [f.stats["view_triangles"] for f in frames] == [s.stats["triangles"] for s in singles]
    else:   # one tessellation, drawn into each view where its frustum holds it
        assert singles[0].stats["triangles"] < frames[0].stats["triangles"] < 2 * singles[0].stats["triangles"]


@pytest.mark.parametrize("per_pass, passes", [(1, 40), (32, 2)])
def test_more_views_than_invocations_take_chunks(per_pass, passes):
    """40 tiny views around a sphere (one looking away): a pass each, or up to 32 views a pass of
    the geometry stage (two passes of 20), and every view equals a single-view draw of the shared
    list."""
    scene = pl.Scene()
    scene.add("sphere")
    cams = []
    for i in range(40):
        a = 2 * np.pi * i / 40
        eye = np.array([3 * np.sin(a), 0.4, 3 * np.cos(a)])
        cams.append(pl.Camera.look_at(eye, eye * 2 if i == 37 else (0, 0, 0), size=(24, 18)))
    records = render_list(scene, cams)
    r = TessRenderer(scene.functions())
    settings = replace(FIXED, views_per_pass=per_pass)
    frames = r.draw_views(records, None, scene, cams, settings)
    assert len(frames) == 40
    assert frames[0].stats["views_per_pass"] == 40 // passes and frames[0].stats["passes"] == passes
    assert frames[0].stats["draw_calls"] >= passes
    for v, (cam, f) in enumerate(zip(cams, frames)):
        s = r.draw(records, None, scene, cam, settings)
        assert_same_image(f, s)
        assert f.stats["view"] == v
        assert f.coverage.any() == (v != 37)
        assert f.stats["pixels_written"] == int(f.coverage.sum())


@pytest.mark.parametrize("per_pass", [1, 2])
def test_views_that_see_nothing_give_empty_frames(per_pass):
    scene = pl.Scene()
    scene.add("sphere")
    toward = pl.Camera.look_at((0, 0, 3), (0, 0, 0), size=SIZE)
    away = pl.Camera.look_at((0, 0, 3), (0, 0, 6), size=SIZE)
    rs = pl.RenderSettings(tess=TessSettings(views_per_pass=per_pass))
    frames = pl.render_views(scene, [toward, away], variant="tess", settings=rs)
    assert frames[0].coverage.sum() > 500
    f = frames[1]
    assert not f.coverage.any() and np.all(np.isinf(f.depth)) and not f.object_id.any() and not f.normal.any()
    assert f.stats["pixels_written"] == 0 and f.stats["nothing_drawn"]
    # no view sees anything: the LOD stage culls every patch and nothing is drawn
    frames = pl.render_views(scene, [away, pl.Camera.look_at((0, 0, 3), (3, 0, 6), size=SIZE)], variant="tess",
                             settings=rs)
    assert frames[0].stats["render_patches"] == 0
    for f in frames:
        assert not f.coverage.any() and f.stats["nothing_drawn"]


@pytest.mark.parametrize("per_pass", [1, 2])
@pytest.mark.parametrize("aa", ["8xMS", "4xSS+8xMS"])
def test_msaa_per_layer(aa, per_pass):
    """Multisampled (and supersampled) layered targets resolve layer by layer like a single
    view's: the same fractional coverage, colour and depth; a request above the device's samples
    is capped with the same warning."""
    scene = pl.Scene()
    scene.add("sphere", transform=pl.translate(-1.2, 0, 0))
    scene.add("torus", transform=pl.translate(1.0, 0, 0) @ pl.rotate(60, (1, 0, 0)))
    cams = [pl.Camera.look_at((-1.2, 0, 3.5), (-1.2, 0, 0), size=(64, 48)),
            pl.Camera.look_at((1.0, 1.5, 2.5), (1.0, 0, 0), size=(64, 48))]
    records = render_list(scene, cams)
    settings = TessSettings(mode="fixed", levels=(10, 10), aa=aa, views_per_pass=per_pass)
    r = TessRenderer(scene.functions())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frames = r.draw_views(records, None, scene, cams, settings)
        singles = [r.draw(records, None, scene, c, settings) for c in cams]
    for f, s in zip(frames, singles):
        assert_same_image(f, s)
        np.testing.assert_array_equal(f.color[..., 3], s.color[..., 3])
        a = f.color[..., 3]
        assert ((a > 0) & (a < 1)).sum() >= 20   # anti-aliased edges
        assert f.stats["msaa_samples_device"] == s.stats["msaa_samples_device"] > 1
        assert f.stats["aa_effective"] == s.stats["aa_effective"]
    if r.max_samples < 8:
        msgs = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
        assert sum("8xMS requested" in m for m in msgs) == 3
        assert any("8xMS requested" in m for m in frames[1].stats["warnings"])


def test_adaptive_levels_serve_the_view_that_needs_most():
    """A sphere seen whole from near and from far, drawn for both by one geometry-stage pass: it
    is tessellated as finely as the near view asks, so the far view's image is finer than the far
    view alone would draw."""
    scene = pl.Scene()
    scene.add("sphere")
    near = pl.Camera.look_at((0, 0.5, 3.4), (0, 0, 0), size=SIZE)
    far = pl.Camera.look_at((9, 2, 1), (0, 0, 0), size=SIZE)
    records = render_list(scene, [near, far])
    r = TessRenderer(scene.functions())
    st = TessSettings(l_min=2, views_per_pass=2)
    frames = r.draw_views(records, None, scene, [near, far], st)
    # triangles each view draws: each sees the whole sphere, so every triangle of the shared
    # tessellation lands in both; the single draws are each view's own tessellation
    shared = frames[0].stats["triangles"] / 2
    t_near = r.draw(records, None, scene, near, st).stats["triangles"]
    t_far = r.draw(records, None, scene, far, st).stats["triangles"]
    assert t_far < t_near <= shared <= 1.2 * t_near   # the near view asks for most almost everywhere
    assert_same_image(frames[0], r.draw(records, None, scene, near, st))


def test_one_view_is_a_single_view_draw():
    scene = pl.Scene()
    scene.add("torus")
    cam = pl.Camera.look_at((0, 2, 2), (0, 0, 0), size=(48, 36))
    records = render_list(scene, [cam])
    r = TessRenderer(scene.functions())
    (f,) = r.draw_views(records, None, scene, Views([cam]))
    s = r.draw(records, None, scene, cam)
    np.testing.assert_array_equal(f.color, s.color)
    np.testing.assert_array_equal(f.depth, s.depth)
    assert f.stats["view"] == 0 and f.stats["views"] == 1 and f.stats["view_triangles"] == s.stats["triangles"]
    (g,) = r.draw_views(records, None, scene, Views([cam]), TessSettings(views_per_pass=8))   # no geometry stage
    np.testing.assert_array_equal(g.depth, s.depth)
    assert g.stats["views_per_pass"] == 1


def test_draw_views_checks_its_input():
    scene = pl.Scene()
    scene.add("sphere")
    cams = [pl.Camera.look_at((0, 0, 3), (0, 0, 0), size=(32, 24)), pl.Camera.look_at((3, 0, 0), (0, 0, 0), size=(32, 24))]
    r = TessRenderer(scene.functions())
    with pytest.raises(SceneError, match="RENDER_DTYPE"):
        r.draw_views(np.zeros(3, np.float32), 3, scene, cams)
    with pytest.raises(SceneError, match="same size"):
        r.draw_views(render_list(scene, cams[:1]), None, scene, [cams[0], cams[1].with_size((16, 16))])
    for bad in (0, 33, 2.5, True):
        with pytest.raises(SceneError, match="views_per_pass"):
            TessSettings(views_per_pass=bad).validate()


def test_the_views_block_is_the_size_python_writes():
    # PlViews' GLSL structs (tess_views.glsl, mesh_common.glsl) and the records Python writes into
    # them are written twice; the programs check their sizes when built, and say so when they differ
    ctx = gl_context()
    tess = build_programs(ctx, [get_function("sphere")], "equal", invocations=2)
    mesh = mesh_program(ctx, 0, 2)
    assert tess["PlViews"].size == MAX_VIEWS * VIEW_FLOATS * 4
    assert mesh["PlViews"].size == MAX_VIEWS * VIEW_RECORD
    with pytest.raises(RuntimeError, match=f"PlViews of kernels/tess/tess_views.glsl takes {MAX_VIEWS * 144} bytes"):
        check_block(tess, "PlViews", MAX_VIEWS * 32 * 4, "kernels/tess/tess_views.glsl")
