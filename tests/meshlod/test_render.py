"""Meshes through the whole frame (paramlod.render): the cut and the raster in the shared key
buffers with parametric objects and surfels, the OpenGL path composited with tess, no cracks at
1-4 px thresholds, the LOD doing its job with distance, debug colours, supersampling."""
from __future__ import annotations

import numpy as np
import pytest

import paramlod as pl
from paramlod.errors import MeshError, SceneError
from paramlod.meshlod.build.dag import build_dag
from paramlod.pipeline.driver import render_passes

from helpers.holes import count_holes
from helpers.meshes import sphere


def bumpy_sphere(subdiv=5):
    """A closed, bumpy sphere (20 * 4^subdiv triangles): the simplifier has real work to do."""
    v, f = sphere(subdiv)
    d = v / np.linalg.norm(v, axis=1, keepdims=True)
    r = 1.0 + 0.06 * np.sin(9 * d[:, 0]) * np.cos(7 * d[:, 1]) + 0.04 * np.sin(13 * d[:, 2])
    return (d * r[:, None]).astype(np.float32), f


@pytest.fixture(scope="module")
def lod():
    v, f = bumpy_sphere(5)
    return build_dag(v, f, name="bumpy sphere")


def camera(dist, size=(128, 96), eye_dir=(0.3, 0.4, 1.0)):
    d = np.asarray(eye_dir, float)
    d /= np.linalg.norm(d)
    return pl.Camera.look_at(d * dist, (0, 0, 0), (0, 1, 0), 40.0, size, near=0.05, far=dist + 4)


def settings(threshold=1.0, **kw):
    rs = pl.RenderSettings()
    rs.mesh.threshold_px = threshold
    for k, v in kw.items():
        setattr(rs.mesh, k, v)
    return rs


def test_mesh_renders_with_lod_fewer_triangles_far_away(lod):
    s = pl.Scene()
    s.add_mesh(lod)
    near = pl.render(s, camera(3.0), settings=settings(1.0))
    far = pl.render(s, camera(12.0), settings=settings(1.0))
    full = pl.render(s, camera(12.0), settings=settings(0.0))
    assert near.stats["variant"] == "meshlets"
    assert 0 < far.stats["triangles_drawn"] < near.stats["triangles_drawn"]
    # far away at 1 px the LOD draws a fraction of the original triangles
    assert far.stats["triangles_drawn"] * 4 < full.stats["triangles_drawn"]
    assert (far.object_id == 1).sum() > 100


@pytest.mark.parametrize("threshold", [1.0, 2.0, 4.0])
def test_no_cracks_inside_the_full_silhouette(lod, threshold):
    s = pl.Scene()
    s.add_mesh(lod)
    for dist in (3.0, 6.0):
        cam = camera(dist)
        full = pl.render(s, cam, settings=settings(0.0))
        cut = pl.render(s, cam, settings=settings(threshold))
        assert cut.stats["triangles_drawn"] < full.stats["triangles_drawn"]
        # the simplified silhouette may move by up to the threshold: look inside it by that much + 1
        holes = count_holes(cut, full.object_id == 1, erode=int(np.ceil(threshold)) + 1)
        assert holes == 0, f"{holes} background pixels inside the mesh at {threshold} px, distance {dist}"


def test_threshold_zero_draws_every_original_triangle(lod):
    s = pl.Scene()
    s.add_mesh(lod)
    f = pl.render(s, camera(3.0), settings=settings(0.0, cull_backface=False, cull_frustum=False))
    assert f.stats["triangles_drawn"] == lod.original_triangles
    assert f.stats["clusters_drawn"] == int((lod.clusters["level"] == 0).sum())


@pytest.mark.parametrize("variant", ["meshlets", "meshlets-gl"])
def test_a_triangle_seen_from_behind_shows_unless_one_sided(variant):
    """Back-face culling (on by default) drops clusters of one-sided materials only: a two-sided
    triangle (the default material) still shows its back."""
    tri = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]]))   # faces +z
    behind = pl.Camera.look_at((0.3, 0.3, -3), (0.3, 0.3, 0), size=(64, 48))
    drawn = {}
    for two_sided in (True, False):
        s = pl.Scene()
        s.add_mesh(tri, material=pl.Material(two_sided=two_sided))
        drawn[two_sided] = int((pl.render(s, behind, variant).object_id == 1).sum())
    assert drawn[True] > 100 and drawn[False] == 0


def test_mesh_and_parametric_compose_in_one_key_buffer(lod):
    s = pl.Scene()
    s.add_mesh(lod, transform=pl.translate(-0.6, 0, 0), material=pl.Material((0.9, 0.3, 0.2)))
    s.add("sphere", transform=pl.translate(0.6, 0, 0.4) @ pl.scale(0.8))
    cam = camera(4.0, eye_dir=(0, 0, 1))
    passes = render_passes(s, cam)
    assert len(passes) == 1, "mesh and parametric points share the key buffers"
    f = passes[0]
    ids = set(np.unique(f.object_id)) - {0}
    assert ids == {1, 2}
    alone_mesh = pl.Scene()
    alone_mesh.add_mesh(lod, transform=pl.translate(-0.6, 0, 0))
    m = pl.render(alone_mesh, cam)
    both = np.isfinite(m.depth) & np.isfinite(f.depth)
    # where the mesh is drawn alone, the composite is never farther than it
    assert np.all(f.depth[both] <= m.depth[both] + 1e-6)


def test_mesh_and_surfels_compose(lod, tmp_path):
    import trimesh

    from paramlod.surfels.build import sample_mesh

    v, fc = sphere(2)
    surf = sample_mesh(trimesh.Trimesh(v, fc, process=False), 3000)
    s = pl.Scene()
    s.add_mesh(lod, transform=pl.translate(-0.7, 0, 0))
    s.add_surfels(surf, transform=pl.translate(0.7, 0, 0) @ pl.scale(0.6))
    f = pl.render(s, camera(4.0, eye_dir=(0, 0, 1)))
    assert set(np.unique(f.object_id)) - {0} == {1, 2}


def test_gl_path_composites_with_tess_and_msaa(lod):
    s = pl.Scene()
    s.add_mesh(lod, transform=pl.translate(-0.6, 0, 0))
    s.add("sphere", transform=pl.translate(0.6, 0, 0) @ pl.scale(0.7))
    rs = settings(1.0)
    rs.apply_aa("4xMS")
    cam = camera(4.0, size=(96, 72), eye_dir=(0, 0, 1))
    passes = render_passes(s, cam, "tess", rs)
    assert sorted(p.stats["variant"] for p in passes) == ["meshlets-gl", "tess"]
    f = pl.render(s, cam, "tess", rs)
    assert set(np.unique(f.object_id)) - {0} == {1, 2}
    a = f.color[..., 3]
    assert np.any((a > 0.05) & (a < 0.95)), "4xMS edges have partial coverage"


def test_cl_raster_and_gl_agree(lod):
    s = pl.Scene()
    s.add_mesh(lod)
    cam = camera(3.0, size=(96, 72))
    cl_f = pl.render(s, cam, "meshlets")
    gl_f = pl.render(s, cam, "meshlets-gl")
    assert cl_f.stats["triangles_drawn"] == gl_f.stats["triangles_drawn"]
    a, b = cl_f.object_id > 0, gl_f.object_id > 0
    assert (a & b).sum() / (a | b).sum() > 0.99
    both = a & b
    assert np.allclose(cl_f.depth[both], gl_f.depth[both], rtol=1e-3)


def test_supersampled_mesh_has_fractional_edges(lod):
    s = pl.Scene()
    s.add_mesh(lod, aa="4xSS")
    f = pl.render(s, camera(3.0))
    a = f.color[..., 3]
    assert f.stats["supersample"] == 2
    assert np.any((a > 0.1) & (a < 0.9))


@pytest.mark.parametrize("mode,least", [("cluster", 20), ("level", 2)])
def test_debug_colours(lod, mode, least):
    s = pl.Scene()
    s.add_mesh(lod)
    f = pl.render(s, camera(5.0), settings=settings(2.0, color_by=mode))
    img = f.rgb8()[f.object_id == 1]
    assert len(np.unique(img // 32, axis=0)) >= least


def test_bad_mesh_settings_are_named(lod):
    s = pl.Scene()
    s.add_mesh(lod)
    with pytest.raises(MeshError, match="threshold_px"):
        pl.render(s, camera(3.0), settings=settings(-1.0))
    with pytest.raises(MeshError, match="color_by"):
        pl.render(s, camera(3.0), settings=settings(1.0, color_by="rainbow"))
    with pytest.raises(SceneError, match="for mesh objects"):
        s.meshes[0].variant = "tess"
        s.touch()
        pl.render(s, camera(3.0))


def test_many_instances_of_one_mesh_share_its_upload(lod):
    s = pl.Scene()
    tr = np.repeat(np.eye(4)[None], 9, axis=0)
    tr[:, 0, 3] = np.repeat([-2.5, 0, 2.5], 3)
    tr[:, 1, 3] = np.tile([-2.5, 0, 2.5], 3)
    s.add_mesh_instances(lod, 9, transforms=tr)
    f = pl.render(s, camera(14.0, eye_dir=(0, 0, 1)))
    assert f.stats["mesh_device_bytes"] < 2 * lod.nbytes + 9 * 1024 * 64   # the mesh is on the device once
    # every copy is drawn: the image's 3 x 3 cells each hold some of object 1
    h, w = f.object_id.shape
    cells = f.object_id.reshape(3, h // 3, 4, w // 4)
    xs = [(cells[:, :, k, :] == 1).sum(axis=(1, 2)) for k in (0, 1, 2, 3)]
    assert (f.object_id == 1).sum() > 9 * 30 and all(x.sum() > 0 for x in xs[1:3])
