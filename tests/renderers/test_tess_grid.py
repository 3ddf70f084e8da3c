"""The grid tessellator (paramlod/renderers/tess_grid.py, kernels/tess/grid.cl) and the "chord"
levels: the kernels against their numpy twin, the triangles' tiling and shared edges, frames
against GL's tessellation stages, and the settings' errors."""
import numpy as np
import pytest
from conftest import iou

import paramlod as pl
from paramlod.app.bench import peers
from paramlod.errors import SceneError
from paramlod.lod.stage import LodSettings
from paramlod.renderers import tess_grid
from paramlod.renderers.tess import Tessellation, TessSettings
from paramlod.renderers.tess_grid import GridTessellator
from paramlod.renderers.tess_grid_reference import grid_levels, grid_topology
from paramlod.core.layouts import GRID_VERTEX
from paramlod.function import programs as function_programs
from paramlod.function.codegen_cl import SPLIT_U, SPLIT_V, surface_split
from paramlod.scene.framing import framing_camera


def render_list(scene, camera, threshold=84.0, overlap=None):
    """The LOD stage's render records of ``scene`` seen by ``camera``."""
    rs = pl.RenderSettings(lod=LodSettings(threshold=(threshold, threshold)))
    t = Tessellation(scene.functions())
    t.prepare(scene, camera, rs)
    _, n, _, _ = t.lod.run(t.dev["inst"], t.dev["domains"], t.dev["cam"], rs.lod)
    return t.lod.read_render_list(n)


def torus_case(size=160, close=False):
    spec = peers.scene_spec("torus-close" if close else "torus", (size, size))
    return peers.paramlod_scene(spec), peers.camera_of(spec), spec


def frame(scene, camera, **tess):
    rs = pl.RenderSettings(tess=TessSettings(**tess))
    return pl.render(scene, camera, variant="tess", settings=rs)


# --- the kernels and their twin -----------------------------------------------------------------
def random_levels(rng, n):
    """Levels records (grid.cl's) with every corner case: inner 2 (one inner vertex), edges of 1."""
    out = np.zeros((n, 8), np.int32)
    out[:, :4] = rng.integers(1, 13, (n, 4))
    out[:, 4:6] = rng.integers(2, 13, (n, 2))
    out[0, :6] = (1, 1, 1, 1, 2, 2)
    out[1, :6] = (64, 1, 64, 1, 2, 64)
    out[:, 6] = (out[:, 4] - 1) * (out[:, 5] - 1) + out[:, :4].sum(axis=1)
    out[:, 7] = 2 * (out[:, 4] - 2) * (out[:, 5] - 2) + out[:, :4].sum(axis=1) + 2 * (out[:, 4] - 2) + 2 * (out[:, 5] - 2)
    return out


def test_triangles_and_vertices_match_the_numpy_twin():
    scene = pl.Scene()
    scene.add("plane")
    cam = pl.Camera.look_at((0.3, 0.2, 3), (0.0, 0.0, 0.0), size=(64, 64))
    records = render_list(scene, cam)[:1].repeat(40)
    rng = np.random.default_rng(5)
    records["range"] = np.sort(rng.uniform(-0.5, 0.5, (40, 2, 2)), axis=2).reshape(40, 4).astype(np.float32)
    levels = random_levels(rng, 40)
    settings = TessSettings(overlap=0.0)
    grid = GridTessellator(scene.functions()).tessellate(records, scene, cam, settings, (84.0, 84.0), levels=levels)
    patch, t, triangles = grid_topology(levels)
    assert np.array_equal(grid.indices.reshape(-1, 3), triangles)   # the same integers, in the same order
    assert len(grid.vertices) == levels[:, 6].sum() == len(t)
    # each vertex where its parameters put it on the plane (identity transform: world = f(u, v))
    r = records["range"][patch]
    u = r[:, 0] + (r[:, 1] - r[:, 0]) * t[:, 0]
    v = r[:, 2] + (r[:, 3] - r[:, 2]) * t[:, 1]
    expect = scene.functions()[0].evaluate(u.astype(np.float64), v.astype(np.float64))
    np.testing.assert_allclose(grid.vertices["pos"][:, :3], expect, atol=1e-5)
    assert np.all(grid.vertices["pos"][:, 3] == 0) and grid.nan_vertices == 0


def test_runs_of_split_functions_give_the_vertices_bit_for_bit(monkeypatch):
    # the fibre's split reads u (runs down inner-grid columns), a seashell's v (rows), the sphere
    # has none: runs of 3 and 16 visits a work-item (CPU devices; runs cross patches) give the
    # vertices of one visit a work-item evaluated whole (PL_RUN 1, as on GPUs) bit for bit, and
    # every vertex is written
    scene = pl.Scene()
    scene.add("fiber", material=pl.Material(color=(0.8, 0.5, 0.3)))
    scene.add("seashell1", transform=pl.translate(9.0, 0.0, 0.0) @ pl.scale(0.6))
    scene.add("sphere", transform=pl.translate(-4.0, 0.0, 0.0) @ pl.scale(2.0))
    assert [None if s is None else s.axis for s in map(surface_split, scene.functions())] == [SPLIT_U, SPLIT_V, None]
    cam = framing_camera(scene, size=(240, 144))
    records = render_list(scene, cam, threshold=12.0)
    settings = TessSettings(mode="chord", chord_px=0.25, l_min=1.0)
    grids = []
    for run in (1, 3, 16):
        monkeypatch.setattr(function_programs, "RUN_CPU", run)
        grid = GridTessellator(scene.functions()).tessellate(records, scene, cam, settings, (12.0, 12.0))
        grids.append(grid.vertices.view(np.uint8))
    assert len(records) > 100 and len(grids[0]) > 3000 * GRID_VERTEX.dtype.itemsize
    # every vertex written: its patch's instance and a normal (not normalized; the output is not cleared)
    inst = np.repeat(records["inst"], grid.levels[:, tess_grid.VERTICES])
    np.testing.assert_array_equal(grid.vertices["inst"], inst)
    assert set(np.unique(inst)) == {0, 1, 2}
    assert np.all(np.linalg.norm(grid.vertices["normal"], axis=1) > 0)
    for other in grids[1:]:
        np.testing.assert_array_equal(other, grids[0])


def test_each_patch_is_tiled_by_counter_clockwise_triangles():
    levels = random_levels(np.random.default_rng(11), 60)
    patch, t, triangles = grid_topology(levels)
    a, b, c = (t[triangles[:, k]].astype(np.float64) for k in range(3))
    area = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    assert np.all(area > 0)   # none degenerate, none flipped
    owner = patch[triangles[:, 0]]
    assert np.all(patch[triangles] == owner[:, None])
    # positive triangles whose areas sum to the unit square's, inside it: they tile it
    np.testing.assert_allclose(np.bincount(owner, weights=area, minlength=60), 1.0, atol=1e-5)
    assert len(np.unique(triangles)) == len(t)   # every vertex used
    counts = np.bincount(owner, minlength=60)
    assert np.array_equal(counts, levels[:, 7])


@pytest.mark.parametrize("mode", ["adaptive", "adaptive-segment", "chord", "fixed"])
@pytest.mark.parametrize("case", ["torus", "glyphs"])
def test_levels_match_the_numpy_twin(mode, case):
    if case == "torus":
        scene, cam, _ = torus_case(320, close=True)
    else:
        scene, cam, _ = (lambda s: (peers.paramlod_scene(s, peers.glyph_field(8, 3)), peers.camera_of(s), s))(
            peers.scene_spec("glyphs8", (240, 240), grid=3))
    records = render_list(scene, cam)
    mode, _, measure = mode.partition("-")
    settings = TessSettings(mode=mode, l_min=1.0, levels=(5.0, 3.0), inner_measure=measure or "extent")
    grid = GridTessellator(scene.functions()).tessellate(records, scene, cam, settings, (84.0, 84.0))
    expect, raw = grid_levels(records, scene, cam, settings, (84.0, 84.0))
    differ = (grid.levels != expect).any(axis=1)
    # a level may differ only where the float32 measure lies at a whole number
    near_whole = (np.abs(raw - np.round(raw)) <= 1e-3 * np.maximum(raw, 1)).any(axis=1)
    assert not np.any(differ & ~near_whole), grid.levels[differ & ~near_whole][:3]
    assert differ.sum() <= max(1, len(records) // 20)


def test_patches_sharing_an_edge_share_its_vertices():
    """Without overlap, two patches that agree on a shared edge's level place the same vertices on
    it (so GL's rasterization rules leave no crack between them)."""
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0.5, 1.0, 2.4), (0.0, 0.0, 0.0), size=(160, 160))
    records = render_list(scene, cam, threshold=40.0)
    settings = TessSettings(mode="chord", overlap=0.0, l_min=1.0)
    grid = GridTessellator(scene.functions()).tessellate(records, scene, cam, settings, (40.0, 40.0))
    patch, t, _ = grid_topology(grid.levels)
    pos = grid.vertices["pos"][:, :3]
    r = records["range"]
    pairs = 0
    for p, q in zip(*np.nonzero((r[:, None, 1] == r[None, :, 0]) & (r[:, None, 2] == r[None, :, 2])
                                & (r[:, None, 3] == r[None, :, 3]))):   # p's edge u = u1 is q's u = u0
        if grid.levels[p, 2] != grid.levels[q, 0]:
            continue
        on_p = pos[(patch == p) & (t[:, 0] == 1)]
        on_q = pos[(patch == q) & (t[:, 0] == 0)]
        key = lambda x: x[np.lexsort(x.T)]
        assert np.array_equal(key(on_p), key(on_q))
        pairs += 1
    assert pairs >= 4


# --- frames -------------------------------------------------------------------------------------
def test_grid_frames_match_hardware_frames():
    scene, cam, _ = torus_case(120)
    for mode in ("adaptive", "chord"):
        hw = frame(scene, cam, mode=mode, tessellator="hardware", l_min=1.0)
        grid = frame(scene, cam, mode=mode, tessellator="grid", l_min=1.0)
        assert hw.stats["tessellator"] == "hardware" and grid.stats["tessellator"] == "grid"
        assert iou(hw.coverage, grid.coverage) > 0.99
        both = hw.coverage & grid.coverage
        diff = np.abs(hw.color[both, :3] - grid.color[both, :3])
        assert np.median(diff) < 0.01 and np.mean(diff) < 0.03
        assert set(np.unique(grid.object_id[grid.coverage])) == {1}


def test_chord_levels_keep_the_silhouette_with_far_fewer_triangles():
    for close in (False, True):
        scene, cam, spec = torus_case(200, close)
        reference, _ = peers.reference_silhouette(spec)
        fine = frame(scene, cam, tessellator="hardware")
        chord = frame(scene, cam, mode="chord", chord_px=0.25, l_min=1.0)
        # "auto": the grid on llvmpipe, GL's stages on a GPU
        llvmpipe = "llvmpipe" in str(chord.stats["device"]).lower()
        assert chord.stats["tessellator"] == ("grid" if llvmpipe else "hardware")
        assert peers.silhouette_error(chord.coverage, reference) <= 0.01
        assert chord.stats["triangles"] * 20 < fine.stats["triangles"]
        coarse = frame(scene, cam, mode="chord", chord_px=8.0, l_min=1.0)
        assert coarse.stats["triangles"] < chord.stats["triangles"]


def test_auto_picks_the_grid_for_chord_levels_on_llvmpipe():
    scene, cam, _ = torus_case(64)
    llvmpipe = "llvmpipe" in str(frame(scene, cam).stats["device"]).lower()
    assert frame(scene, cam).stats["tessellator"] == "hardware"
    assert frame(scene, cam, mode="chord").stats["tessellator"] == ("grid" if llvmpipe else "hardware")


# --- errors -------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, words", [
    ({"tessellator": "cpu"}, "tessellator must be one of"),
    ({"mode": "curvy"}, "mode must be one of"),
    ({"chord_px": 0.0}, "chord_px"),
    ({"tessellator": "grid", "views_per_pass": 4}, "one view a pass"),
    ({"mode": "chord", "views_per_pass": 4}, "one view a pass"),
    ({"inner_measure": "longest"}, "inner_measure must be one of"),
])
def test_bad_settings_are_named(kwargs, words):
    with pytest.raises(SceneError, match=words):
        TessSettings(**kwargs).validate()


def test_the_vertex_limit_is_named(monkeypatch):
    scene, cam, _ = torus_case(64)
    monkeypatch.setattr(tess_grid, "MAX_VERTICES", 1000)
    with pytest.raises(SceneError, match="MAX_VERTICES"):
        frame(scene, cam, tessellator="grid")
