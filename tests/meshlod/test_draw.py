"""The meshlets-gl draw (paramlod/meshlod/draw.py: MeshDraw) on llvmpipe: indirect draws of a
selection of clusters into the GL targets of paramlod.renderers.gl_targets.

The mesh is an icosphere whose clusters are consecutive runs of at most 128 triangles, all roots
(the draw does not care how the DAG was built). Frames are small: llvmpipe is a CPU rasterizer.
"""
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import sphere_disc
from helpers.meshes import sphere

import paramlod as pl
from paramlod.core.camera import Camera
from paramlod.core.color import linear_to_srgb8
from paramlod.core.layouts import CLUSTER
from paramlod.errors import MeshError
from paramlod.lod.stage import LodSettings
from paramlod.meshlod.buffers import MeshArrays, MeshInstances
from paramlod.meshlod.draw import MeshDraw
from paramlod.meshlod.format import MeshLod
from paramlod.meshlod.raster_reference import cluster_color, level_color
from paramlod.pipeline.composite import composite
from paramlod.renderers.tess import Tessellation, TessSettings
from paramlod.scene.scene import Material, MeshObject

FLAT = (0.0, 0.0, 1.0, 1.0)   # ambient share 1: a pixel's colour is its base colour (with specular 0)


def sphere_lod(subdiv=3, run=128, levels=None) -> MeshLod:
    """An icosphere as a MeshLod of consecutive runs of ``run`` triangles; ``levels`` (per cluster)
    only labels the clusters, for the per-level colouring."""
    v, f = sphere(subdiv)
    n = (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)
    c = np.zeros((len(f) + run - 1) // run, CLUSTER.dtype)
    c["first"] = np.arange(len(c)) * run
    c["count"] = np.minimum(run, len(f) - c["first"])
    c["parent_error"] = np.inf
    if levels is not None:
        c["level"] = levels
    return MeshLod(v, n, f, c, name="icosphere", lod="full")


def drawer(objects) -> MeshDraw:
    meshes = list({id(o.mesh): o.mesh for o in objects}.values())   # MeshLod is not hashable
    index = {id(m): k for k, m in enumerate(meshes)}
    d = MeshDraw()
    d.upload(MeshArrays.pack(meshes), MeshInstances.pack(objects, lambda o: index[id(o.mesh)]))
    return d


def everything(mesh: MeshLod, instances=(0,), offset=0) -> np.ndarray:
    """Every cluster of ``mesh`` (its clusters start at ``offset``) for each of ``instances``."""
    return np.array([(i, offset + c) for i in instances for c in range(len(mesh.clusters))], np.uint32)


def ray_mesh_depth(mesh: MeshLod, camera: Camera, px, py, model=np.eye(4)) -> float:
    """Linear view depth of the nearest triangle of ``mesh`` (placed by ``model``) along the ray
    through the centre of pixel (px, py), in float64 (Moeller-Trumbore over all triangles)."""
    w, h = camera.size
    ndc = np.array([(px + 0.5) / w * 2 - 1, 1 - (py + 0.5) / h * 2])
    inv = np.linalg.inv(camera.projection @ camera.view)
    a = inv @ np.array([*ndc, -1.0, 1.0])
    b = inv @ np.array([*ndc, 1.0, 1.0])
    o = a[:3] / a[3]
    d = b[:3] / b[3] - o
    d /= np.linalg.norm(d)
    v = (np.c_[mesh.vertices.astype(np.float64), np.ones(len(mesh.vertices))] @ model.T)[:, :3]
    p0, p1, p2 = (v[mesh.triangles[:, k]] for k in range(3))
    e1, e2 = p1 - p0, p2 - p0
    q = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, q)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = o - p0
        u = np.einsum("ij,ij->i", s, q) / det
        r = np.cross(s, e1)
        vv = (r @ d) / det
        t = np.einsum("ij,ij->i", e2, r) / det
    hit = (np.abs(det) > 1e-15) & (u >= 0) & (vv >= 0) & (u + vv <= 1) & (t > 0)
    tmin = t[hit].min()
    return float(-(camera.view @ np.array([*(o + tmin * d), 1.0]))[2])


def tess_frame(scene, camera):
    """The tess variant's frame of ``scene`` (its per-scene state, without the frame driver)."""
    state = Tessellation(scene.functions())
    settings = SimpleNamespace(tess=TessSettings(), lod=LodSettings())
    state.prepare(scene, camera, settings)
    return state.enqueue(camera, settings)


def dilate(mask, r=1):
    m = np.pad(mask, r, constant_values=False)
    h, w = mask.shape
    out = np.zeros_like(mask)
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            out |= m[dy:dy + h, dx:dx + w]
    return out


def boundary(mask):
    """Pixels with a neighbour (of 8) on the other side of ``mask``'s edge, on both sides."""
    return dilate(mask) & dilate(~mask)


@pytest.fixture(scope="module")
def mesh():
    return sphere_lod(3)


@pytest.fixture(scope="module")
def one(mesh):
    return drawer([MeshObject(mesh, np.eye(4), Material(color=(0.7, 0.5, 0.3), specular=0.0), 1)])


CAM = Camera.look_at((0, 0, 3), (0, 0, 0), size=(80, 64))


# --- the whole mesh -----------------------------------------------------------------------------
def test_all_clusters_give_the_projected_sphere(mesh, one):
    f = one.draw(everything(mesh), CAM)
    disc, depth = sphere_disc(CAM)
    cov = np.isfinite(f.depth)
    # silhouette: the inscribed icosphere (1280 faces) differs from the sphere's disc by well under a
    # pixel here, so only pixels next to the disc's boundary may disagree
    assert np.all((cov != disc) <= dilate(boundary(disc)))
    assert (cov != disc).sum() <= 0.15 * boundary(disc).sum()
    # depth: the mesh's own ray-cast depth to the rasterizer's interpolation precision (NVIDIA:
    # 5e-6 relative), the sphere's within the faceting (sagitta)
    for px, py in [(40, 32), (30, 25), (52, 40)]:
        assert f.depth[py, px] == pytest.approx(ray_mesh_depth(mesh, CAM, px, py), rel=2e-5)
        assert depth[py, px] <= f.depth[py, px] <= depth[py, px] + 0.02
    assert np.all(f.object_id[cov] == 1) and np.all(f.object_id[~cov] == 0)
    assert np.all(f.color[cov, 3] == 1) and np.all(f.color[~cov] == 0)
    assert np.all(np.isinf(f.depth[~cov]))
    # world normal at the centre faces the camera; shading is the material's colour in the light
    assert f.normal[32, 40] == pytest.approx([0, 0, 1], abs=0.03)
    assert np.all(np.linalg.norm(f.normal[cov], axis=1) == pytest.approx(1, abs=2e-3))
    s = f.stats
    assert s["variant"] == "meshlets-gl" and s["clusters"] == len(mesh.clusters)
    assert s["triangles"] == s["triangles_selected"] == len(mesh.triangles) == 1280
    assert s["draw_calls"] == 1 and s["draw_commands"] == len(mesh.clusters)
    assert s["samples_per_pixel"] == 1 and s["pixels_written"] == cov.sum()


def test_mesh_and_parametric_sphere_agree_and_composite_by_depth(mesh, one):
    """The tess variant's unit sphere and the mesh sphere shade alike; composited, the nearer wins."""
    scene = pl.Scene()
    scene.add("sphere", material=pl.Material(color=(0.7, 0.5, 0.3), specular=0.0))
    same = tess_frame(scene, CAM)
    f = one.draw(everything(mesh), CAM)
    inner = np.isfinite(same.depth) & np.isfinite(f.depth)
    inner &= ~dilate(boundary(inner), 2)
    assert inner.sum() > 1000
    # one shading body; the mesh's interpolated vertex normals are close to the analytic ones
    assert np.abs(f.color[inner, :3] - same.color[inner, :3]).mean() < 0.01
    assert np.all(f.depth[inner] >= same.depth[inner] - 1e-4)   # inscribed: never in front

    # a mesh sphere half a radius nearer the camera and to the right, composited with the tess one
    near = drawer([MeshObject(mesh, pl.translate(0.6, 0.1, 0.5) @ pl.scale(0.6), Material(color=(0.2, 0.8, 0.3)), 2)])
    fm = near.draw(everything(mesh), CAM, background=scene.background)
    out = composite([same, fm], background=scene.background)
    with np.errstate(invalid="ignore"):
        mesh_front = fm.depth < same.depth
        tess_front = same.depth < fm.depth
    assert (mesh_front & np.isfinite(same.depth)).sum() > 100   # a real overlap
    assert np.all(out.object_id[mesh_front] == 2) and np.all(out.object_id[tess_front] == 1)
    np.testing.assert_array_equal(out.depth, np.minimum(same.depth, fm.depth))
    opaque = mesh_front & (fm.color[..., 3] == 1)
    assert np.allclose(out.color[opaque], fm.color[opaque], atol=1e-6)
    assert out.stats["variant"] == "composite" and {p["variant"] for p in out.stats["passes"]} == {"tess", "meshlets-gl"}


# --- selections ---------------------------------------------------------------------------------
def test_a_subset_draws_exactly_those_clusters(mesh, one):
    chosen = [0, 3, 4, 7]
    alone = [one.draw(np.array([[0, c]], np.uint32), CAM, color_by=1, light=FLAT) for c in chosen]
    sub = one.draw(np.array([[0, c] for c in chosen], np.uint32), CAM, color_by=1, light=FLAT)
    full = one.draw(everything(mesh), CAM, color_by=1, light=FLAT)
    # each cluster alone has one colour, and different clusters different ones
    colours = []
    for f in alone:
        cov = np.isfinite(f.depth)
        assert cov.sum() > 20
        rgb = np.unique(f.color[cov, :3], axis=0)
        assert len(rgb) == 1
        colours.append(tuple(rgb[0]))
    assert len(set(colours)) == len(chosen)
    # kernels/common/debug_color.cl's colour of the global cluster index (its numpy twin), in the
    # RGBA16F target's precision
    np.testing.assert_allclose(colours, cluster_color(np.array(chosen, np.uint32)), atol=1e-3)
    # the subset covers the union of its clusters, each pixel shows the nearest of them
    stack = np.stack([f.depth for f in alone])
    cov = np.isfinite(sub.depth)
    np.testing.assert_array_equal(cov, np.isfinite(stack).any(axis=0))
    assert 0 < cov.sum() < np.isfinite(full.depth).sum()
    nearest = np.argmin(stack, axis=0)
    np.testing.assert_array_equal(sub.depth[cov], stack.min(axis=0)[cov])
    np.testing.assert_array_equal(sub.color[cov, :3], np.asarray(colours, np.float32)[nearest[cov]])
    # the same clusters within the full draw keep their colour (a colour per global cluster index)
    # (where they are not hidden: a cluster on the far side shows only when drawn without the rest)
    seen_total = 0
    for c, rgb, f in zip(chosen, colours, alone):
        seen = np.isfinite(f.depth) & (full.depth == f.depth)
        assert np.all(full.color[seen, :3] == rgb), c
        seen_total += seen.sum()
    assert seen_total > 50
    assert sub.stats["triangles"] == int(mesh.clusters["count"][chosen].sum())


def test_colour_per_level(mesh):
    levels = np.arange(len(mesh.clusters)) % 2
    lod = sphere_lod(3, levels=levels)
    d = drawer([MeshObject(lod, np.eye(4), Material(specular=0.0), 1)])
    sel = everything(lod)
    alone = [d.draw(sel[k:k + 1], CAM, color_by=2, light=FLAT) for k in range(4)]
    rgb = [np.unique(f.color[np.isfinite(f.depth), :3], axis=0) for f in alone]
    assert all(len(x) == 1 for x in rgb)
    assert np.array_equal(rgb[0], rgb[2]) and np.array_equal(rgb[1], rgb[3])   # one colour per level
    assert not np.array_equal(rgb[0], rgb[1])
    np.testing.assert_allclose(np.concatenate(rgb[:2]), level_color([0, 1]), atol=1e-3)
    per_level = d.draw(sel, CAM, color_by=2, light=FLAT)
    assert len(np.unique(per_level.color[np.isfinite(per_level.depth), :3], axis=0)) == 2
    per_cluster = d.draw(sel, CAM, color_by=1, light=FLAT)
    assert len(np.unique(per_cluster.color[np.isfinite(per_cluster.depth), :3], axis=0)) >= 6
    material = d.draw(sel, CAM, color_by=0, light=FLAT)
    assert np.all(material.color[np.isfinite(material.depth), :3] == pytest.approx(0.8, abs=1e-3))


def test_empty_selection_gives_the_background(one):
    bg = (0.2, 0.3, 0.4)
    f = one.draw(np.zeros((0, 2), np.uint32), CAM, background=bg)
    assert np.all(f.color == 0) and np.all(np.isinf(f.depth)) and np.all(f.object_id == 0)
    assert np.all(f.normal == 0)
    assert np.all(f.rgb8() == linear_to_srgb8(np.asarray(bg, np.float32)[None, None]))
    assert f.stats["triangles"] == 0 and f.stats["draw_calls"] == 0 and f.stats["pixels_written"] == 0


@pytest.mark.parametrize("aa", ["4xMS", "noAA"])
def test_nothing_of_the_previous_frame_shows(mesh, one, aa):
    """noAA draws straight into an output set that the dropped first frame held: the background
    pass must clear what it drew."""
    one.draw(everything(mesh), CAM, aa=aa, background=(0.2, 0.3, 0.4))
    small = one.draw(np.array([[0, 2]], np.uint32), CAM, aa=aa, background=(0.2, 0.3, 0.4))
    fresh = drawer([MeshObject(mesh, np.eye(4), Material(color=(0.7, 0.5, 0.3), specular=0.0), 1)])
    alone = fresh.draw(np.array([[0, 2]], np.uint32), CAM, aa=aa, background=(0.2, 0.3, 0.4))
    assert 0 < np.isfinite(alone.depth).sum() < 0.2 * np.isfinite(sphere_disc(CAM)[0]).sum()
    np.testing.assert_array_equal(small.rgb8(), alone.rgb8())
    for name in ("depth", "object_id", "color", "normal"):
        np.testing.assert_array_equal(getattr(small, name), getattr(alone, name), err_msg=name)
    assert small.stats["pixels_written"] == np.isfinite(alone.depth).sum()


def test_instances_with_their_own_transforms(mesh):
    a = pl.translate(-1.1, 0.2, 0.0) @ pl.scale(0.8)
    b = pl.translate(1.0, -0.3, -0.5) @ pl.rotate(40, (0, 1, 0)) @ pl.scale(-0.6, 0.6, 0.6)   # mirrored
    objects = [MeshObject(mesh, np.eye(4), Material(color=(0.9, 0.2, 0.2)), 3, count=2,
                          transforms=np.stack([a, b])),
               MeshObject(mesh, pl.translate(0, 0, -3), Material(color=(0.2, 0.2, 0.9)), 5)]
    d = drawer(objects)
    cam = Camera.look_at((0, 0, 4), (0, 0, 0), size=(96, 64))
    f = d.draw(everything(mesh, (0, 1)), cam)
    for model in (a, b):
        c = model[:3, 3]
        r = abs(np.linalg.det(model[:3, :3])) ** (1 / 3)
        disc, depth = sphere_disc(cam, c, r)
        cov = np.isfinite(f.depth) & dilate(disc, 2)
        assert np.all((cov != disc) <= dilate(boundary(disc)))
        assert np.all(f.object_id[disc & ~dilate(boundary(disc))] == 3)
        inner = disc & ~dilate(boundary(disc), 2)
        assert np.all((f.depth[inner] >= depth[inner] - 1e-4) & (f.depth[inner] <= depth[inner] + 0.02 * r))
    # the mirrored copy is shaded from its outside too (two-sided, facing normals)
    disc_b, _ = sphere_disc(cam, b[:3, 3], 0.6)
    inner_b = disc_b & ~dilate(boundary(disc_b), 2)
    assert np.all(f.normal[inner_b, 2] > 0)
    # only the third instance: the other object, behind
    g = d.draw(everything(mesh, (2,)), cam)
    assert set(np.unique(g.object_id)) == {0, 5}
    # material per instance: the first object red, the second blue
    lit = d.draw(everything(mesh, (0, 1, 2)), cam, light=FLAT)
    assert np.all(lit.color[lit.object_id == 3, 0] > 0.85) and np.all(lit.color[lit.object_id == 5, 2] > 0.85)


# --- anti-aliasing ------------------------------------------------------------------------------
def coverage_error(f, cam, k=16):
    w, h = cam.size
    disc, _ = sphere_disc(cam.with_size((w * k, h * k)))
    ref = disc.reshape(h, k, w, k).mean(axis=(1, 3))
    return np.abs(f.color[..., 3] - ref).mean(), ref


@pytest.mark.parametrize("aa", ["4xMS", "4xSS", "4xSS+4xMS"])
def test_anti_aliased_edges_are_fractional(mesh, one, aa):
    plain = one.draw(everything(mesh), CAM)
    f = one.draw(everything(mesh), CAM, aa=aa)
    err0, ref = coverage_error(plain, CAM)
    err, _ = coverage_error(f, CAM)
    a = f.color[..., 3]
    partial = (a > 0) & (a < 1)
    edge = dilate(boundary(ref > 0.5), 1)
    assert not ((plain.color[..., 3] > 0) & (plain.color[..., 3] < 1)).any()
    assert partial.sum() >= 40 and np.all(partial <= edge)
    assert err < 0.6 * err0, (err, err0)
    # edge pixels blend the colour of the surface only (straight alpha); the interior is unchanged
    inner = (a == 1) & (plain.color[..., 3] == 1) & ~edge
    assert np.abs(f.color[inner, :3] - plain.color[inner, :3]).max() < 0.02
    assert np.all(f.object_id[partial] == 1) and np.all(np.isfinite(f.depth[partial]))
    assert f.stats["aa_effective"] == aa and f.stats["samples_per_pixel"] == f.stats["ssaa"] ** 2 * f.stats["msaa_samples"]


def test_msaa_request_above_the_device_is_capped(mesh, one):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        f = one.draw(everything(mesh), CAM, aa="8xMS")
    assert f.stats["msaa_requested"] == 8
    if f.stats["msaa_samples"] < 8:
        assert any("8xMS requested" in str(w.message) for w in caught)
        assert any("8xMS requested" in m for m in f.stats["warnings"])


# --- bad input ----------------------------------------------------------------------------------
def test_bad_input_is_named(mesh, one):
    other = sphere_lod(1)
    two = drawer([MeshObject(mesh, np.eye(4), Material(), 1), MeshObject(other, np.eye(4), Material(), 2)])
    cases = [
        (lambda: one.draw(np.zeros((3, 3), np.uint32), CAM), "pairs"),
        (lambda: one.draw(np.zeros((2, 2), np.float32), CAM), "integer"),
        (lambda: one.draw(np.array([[1, 0]], np.uint32), CAM), "instance 1"),
        (lambda: one.draw(np.array([[0, 99]], np.uint32), CAM), "cluster 99"),
        (lambda: one.draw(np.array([[0, -1]]), CAM), "negative"),
        (lambda: two.draw(np.array([[1, 0]], np.uint32), CAM), "does not own"),
        (lambda: one.draw(everything(mesh), CAM, color_by=3), "color_by"),
        (lambda: one.draw(everything(mesh), "camera"), "Camera"),
        (lambda: one.draw(everything(mesh), CAM, light=(1, 2)), "light"),
        (lambda: MeshDraw().draw(everything(mesh), CAM), "upload"),
        (lambda: MeshDraw().upload(mesh, None), "MeshArrays"),
    ]
    for call, word in cases:
        with pytest.raises(MeshError, match=word):
            call()
    with pytest.raises(pl.SceneError, match="anti-aliasing"):
        one.draw(everything(mesh), CAM, aa="3xMS")
