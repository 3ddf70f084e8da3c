"""The OpenCL mesh rasterizer (paramlod.meshlod.raster, kernels/meshlod/raster.cl) against its numpy
twin (paramlod.meshlod.raster_reference: the same colour and aux keys, bit for bit), its fill
rule and watertightness, OpenGL's coverage of the same triangles, the large-triangle list's growth,
and the debug colours (kernels/common/debug_color.cl) compiled as GLSL.

Test meshes carry no DAG: ``flat_lod`` makes clusters of consecutive runs of at most 128
triangles, all roots, and every test draws every (instance, cluster) pair, as a selection buffer
the cut would write.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest
from helpers.meshes import grid, load_bunny, sphere
from scipy.spatial import ConvexHull

from paramlod.core.camera import Camera
from paramlod.core.layouts import CLUSTER, INSTANCE_F
from paramlod.device.context import cl_device, gl_context
from paramlod.errors import MeshError
from paramlod.meshlod import raster_reference as ref
from paramlod.meshlod.buffers import DeviceMeshes, MeshArrays, MeshInstances
from paramlod.meshlod.format import MeshLod
from paramlod.meshlod.raster import COUNTERS, MeshRaster
from paramlod import kernels
from paramlod.renderers.targets import KeyBuffer
from paramlod.scene.scene import Material, MeshObject

EMPTY = ref.ALL_ONES


def flat_lod(vertices, faces, run: int = 128, name: str = "test") -> MeshLod:
    """A MeshLod whose clusters are consecutive runs of ``run`` triangles, all roots, with
    area-weighted vertex normals."""
    v = np.asarray(vertices, np.float32)
    f = np.asarray(faces, np.uint32).reshape(-1, 3)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]).astype(np.float64)
    n = np.zeros((len(v), 3))
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    c = np.zeros(-(-len(f) // run), CLUSTER.dtype)
    c["first"] = np.arange(len(c)) * run
    c["count"] = np.minimum(run, len(f) - c["first"])
    c["parent_error"] = np.inf
    return MeshLod(v, n.astype(np.float32), f, c, name, "full")


def translate(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def rot_x(deg):
    a = np.radians(deg)
    m = np.eye(4)
    m[1:3, 1:3] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return m


class Scene:
    """Meshes and objects packed and uploaded, with every (instance, cluster) pair selected."""

    def __init__(self, objects):
        self.objects = list(objects)
        meshes = []
        for o in self.objects:
            if not any(o.mesh is m for m in meshes):
                meshes.append(o.mesh)
        index = lambda o: next(i for i, m in enumerate(meshes) if m is o.mesh)  # noqa: E731
        self.arrays = MeshArrays.pack(meshes)
        self.instances = MeshInstances.pack(self.objects, index)
        self.dev = DeviceMeshes(self.arrays, self.instances)
        pairs = []
        for mesh, first, count in self.instances.batches:
            c0, nc = self.arrays.ranges[mesh]
            pairs += [(i, c) for i in range(first, first + count) for c in range(c0, c0 + nc)]
        self.pairs = np.array(pairs, np.uint32).reshape(-1, 2)

    def selection(self, count=None, capacity=None):
        """(pairs buffer, capacity, cut counters buffer) as the cut leaves them."""
        ctx = cl_device().context
        cap = len(self.pairs) if capacity is None else capacity
        pairs = np.zeros((max(cap, 1), 2), np.uint32)
        pairs[:min(cap, len(self.pairs))] = self.pairs[:cap]
        counters = np.zeros(8, np.uint64)
        counters[0] = len(self.pairs) if count is None else count
        mf = cl.mem_flags
        return (cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=pairs), cap,
                cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=counters))

    def draw(self, camera, raster=None, color_by=0, keys=None, selection=None):
        """Device keys (colour, aux) and the raster's stats after one frame."""
        raster = raster or MeshRaster()
        if keys is None:
            keys = KeyBuffer(*camera.size)
            keys.clear()
        raster.enqueue(keys, camera, self.dev, *(selection or self.selection()), color_by=color_by)
        raster.collect()
        cl_device().queue.finish()
        c, a = keys.read_keys()
        return c, a, raster.stats()

    def twin(self, camera, color_by=0, large_pixels=None, pairs=None):
        return ref.rasterize_detail(*camera.size, camera, self.arrays, self.instances,
                                    self.pairs if pairs is None else pairs, color_by=color_by,
                                    large_pixels=large_pixels)


@pytest.fixture(scope="module")
def meshes():
    return {"sphere": flat_lod(*sphere(3)), "grid": flat_lod(*grid(24), run=100)}


@pytest.fixture(scope="module")
def scene(meshes):
    s, g = meshes["sphere"], meshes["grid"]
    return Scene([
        MeshObject(s, np.eye(4), Material((0.8, 0.3, 0.2)), 1, count=2,
                   transforms=np.stack([np.eye(4), translate(1.2, 0, -0.5) @ np.diag([0.7, 0.7, 0.7, 1])])),
        MeshObject(g, translate(0, -1, 0) @ rot_x(-90) @ np.diag([2.0, 2.0, 2.0, 1]),
                   Material((0.2, 0.6, 0.3), specular=0.6), 2),
        # a mirrored copy: its triangles wind the other way on screen
        MeshObject(s, translate(-1.3, 0.3, -1) @ np.diag([-0.5, 0.5, 0.5, 1]), Material((0.3, 0.4, 0.9)), 3),
    ])


CASES = {
    # name: (camera, color_by, large_pixels)
    "outside": (Camera.look_at((0.0, 0.8, 3.6), (0.1, -0.1, -0.3), size=(96, 72), near=0.1, far=50), 0, 256),
    # the camera inside the sphere's bounds: triangles cross the near plane
    "inside": (Camera.look_at((0.2, 0.1, 0.9), (0.3, -0.2, -1), size=(80, 60), near=0.05, far=50), 1, 256),
    # a low threshold sends most triangles to the large list
    "large": (Camera.look_at((0.0, 0.5, 2.2), (0.3, -0.2, 0), size=(64, 48), near=0.05, far=50), 2, 16),
    # the far plane through the scene: per-pixel depth test
    "far": (Camera.look_at((0.0, 0.5, 2.2), (0.3, -0.2, 0), size=(64, 48), near=0.05, far=2.3), 0, 32),
}


@pytest.mark.parametrize("case", CASES)
def test_device_keys_equal_the_twin(scene, case):
    camera, color_by, large_pixels = CASES[case]
    c, a, st = scene.draw(camera, MeshRaster(large_pixels=large_pixels), color_by)
    d = scene.twin(camera, color_by, large_pixels)
    assert (d["color"] != EMPTY).sum() > 300
    np.testing.assert_array_equal(c, d["color"])
    np.testing.assert_array_equal(a, d["aux"])
    for k in ("triangles", "near_clipped", "culled", "large", "pixels"):
        assert st[k] == d["counters"][k], k
    assert st["large_overflow"] == 0
    assert st["atomics"] <= st["pixels"]
    if case == "inside":
        assert st["near_clipped"] > 20
    if case == "large":
        assert st["large"] > 100
    if case == "far":
        assert (d["coverage"] > 0).sum() < (scene.twin(CASES["large"][0])["coverage"] > 0).sum()


def test_debug_colours_reach_the_keys(scene):
    """color_by 1 and 2 colour the pixels by cluster and by level, and only the colour changes."""
    camera = CASES["outside"][0]
    keys = {cb: scene.draw(camera, color_by=cb)[:2] for cb in (0, 1, 2)}
    for cb in (1, 2):
        np.testing.assert_array_equal(keys[cb][0] >> np.uint64(32), keys[0][0] >> np.uint64(32))
        np.testing.assert_array_equal(keys[cb][1], keys[0][1])
    cov = keys[0][0] != EMPTY
    by_cluster = np.unique(keys[1][0][cov] & np.uint64(0xFFFFFF00)).size
    by_level = np.unique(keys[2][0][cov] & np.uint64(0xFFFFFF00)).size
    assert by_cluster > 2 * by_level


def pixel_centre_scene(w, h, corners, splits, depth=3.0):
    """Triangles in front of a camera at the origin (looking down -z) whose vertices project onto
    the pixel centres ``corners`` (pixel indices), split in every way in ``splits``: each is a
    list of triangles (indices into corners), drawn as its own object at its own depth."""
    cam = Camera.look_at((0, 0, 0), (0, 0, -1), size=(w, h), near=0.1, far=100)
    P = cam.projection
    objects = []
    for k, tris in enumerate(splits):
        pts = []
        for i, (px, py) in enumerate(corners):
            z = depth + 0.5 * k + 0.1 * (i % 3)                # tilted: depth varies per vertex
            nx = (px + 0.5) / w * 2 - 1
            ny = 1 - (py + 0.5) / h * 2
            pts.append((nx * z / P[0, 0], ny * z / P[1, 1], -z))
        mesh = flat_lod(np.array(pts), np.array(tris), name=f"split{k}")
        objects.append(MeshObject(mesh, np.eye(4), Material((0.7, 0.7, 0.7)), k + 1))
    return cam, objects


# a 3 x 3 lattice of pixel centres around a 16 x 12-pixel rectangle from pixel (10, 8) to (26, 20)
LATTICE = [(10 + 8 * i, 8 + 6 * j) for j in range(3) for i in range(3)]
SPLITS = {
    "diagonals down": [(0, 1, 4), (0, 4, 3), (1, 2, 5), (1, 5, 4), (3, 4, 7), (3, 7, 6), (4, 5, 8), (4, 8, 7)],
    "diagonals up": [(0, 1, 3), (1, 4, 3), (1, 2, 4), (2, 5, 4), (3, 4, 6), (4, 7, 6), (4, 5, 7), (5, 8, 7)],
    # a fan around the centre, half of it wound the other way (two-sided)
    "fan": [(4, 0, 1), (4, 2, 1), (4, 2, 5), (4, 8, 5), (4, 8, 7), (4, 6, 7), (4, 6, 3), (4, 0, 3)],
    "long thin": [(0, 2, 8), (0, 8, 6)],
}


@pytest.mark.parametrize("split", SPLITS)
def test_fill_rule_covers_each_pixel_centre_once(split):
    """Edges through pixel centres (horizontal, vertical, diagonal): the rectangle's pixels are
    covered exactly once (top and left edges inside, bottom and right outside), nothing else."""
    cam, objects = pixel_centre_scene(48, 32, LATTICE, [SPLITS[split]])
    s = Scene(objects)
    c, a, st = s.draw(cam)
    d = s.twin(cam)
    np.testing.assert_array_equal(c, d["color"])
    np.testing.assert_array_equal(a, d["aux"])
    want = np.zeros((32, 48), np.uint32)
    want[8:20, 10:26] = 1
    np.testing.assert_array_equal(d["coverage"], want)
    assert st["pixels"] == want.sum() == (c != EMPTY).sum()


def test_large_and_small_paths_agree_on_shared_edges():
    """Every fan triangle through the large list and through the small path: the same keys."""
    cam, objects = pixel_centre_scene(48, 32, LATTICE, list(SPLITS.values()))
    s = Scene(objects)
    small = s.draw(cam, MeshRaster(large_pixels=10 ** 6))
    large = s.draw(cam, MeshRaster(large_pixels=1))
    assert small[2]["large"] == 0 and large[2]["large"] == sum(len(t) for t in SPLITS.values())
    np.testing.assert_array_equal(small[0], large[0])
    np.testing.assert_array_equal(small[1], large[1])


def hull_mask(points, w, h, eps=1e-3):
    """(inside, undecided): pixel centres inside the convex hull of screen points, and those
    within ``eps`` pixels of its boundary."""
    hull = ConvexHull(points)
    ys, xs = np.mgrid[0:h, 0:w]
    p = np.stack([xs + 0.5, ys + 0.5], axis=-1).reshape(-1, 2)
    dist = (p @ hull.equations[:, :2].T + hull.equations[:, 2]).max(axis=1)   # > 0 outside
    return (dist < -eps).reshape(h, w), (np.abs(dist) <= eps).reshape(h, w)


def screen(camera, model, vertices):
    """Screen positions (pixels, y down) of object-space vertices, float64."""
    p = np.concatenate([vertices, np.ones((len(vertices), 1))], axis=1) @ (camera.projection @ camera.view @ model).T
    ndc = p[:, :2] / p[:, 3:]
    w, h = camera.size
    return np.stack([(ndc[:, 0] * 0.5 + 0.5) * w, (0.5 - ndc[:, 1] * 0.5) * h], axis=1)


@pytest.mark.parametrize("eye,size", [((0.3, 0.4, 2.8), (96, 72)), ((-1.9, 1.2, -1.1), (80, 60)),
                                      ((0.05, -2.3, 0.4), (64, 48))])
def test_closed_sphere_is_watertight(meshes, eye, size):
    """A closed convex mesh covers every pixel centre inside its projected hull and none outside."""
    mesh = meshes["sphere"]
    cam = Camera.look_at(eye, (0, 0, 0), size=size, near=0.1, far=50)
    s = Scene([MeshObject(mesh, np.eye(4), Material(), 1)])
    c, _, st = s.draw(cam)
    inside, undecided = hull_mask(screen(cam, np.eye(4), mesh.vertices.astype(np.float64)), *size)
    covered = c != EMPTY
    assert inside.sum() > 500
    assert not np.any(inside & ~covered), "background pixels inside the silhouette (cracks)"
    assert not np.any(covered & ~inside & ~undecided)


@pytest.mark.parametrize("near,gap", [(0.02, 0.01), (1e-6, 2e-6)])
def test_inside_a_closed_sphere_every_pixel_is_covered(meshes, near, gap):
    """The camera just inside a face, looking along it: the triangles around it cross the near
    plane (and, with a tiny near distance, the guard band), and still no pixel is left open."""
    mesh = meshes["sphere"]
    v, f = mesh.vertices.astype(np.float64), mesh.triangles[7]
    centre = v[f].mean(axis=0)
    normal = np.cross(v[f[1]] - v[f[0]], v[f[2]] - v[f[0]])
    normal /= np.linalg.norm(normal) * np.sign(normal @ centre)
    eye = centre - gap * normal
    along = np.cross(normal, (0.3, 0.8, 0.1))
    cam = Camera.look_at(eye, eye + along - 0.2 * normal, size=(64, 48), near=near, far=50)
    s = Scene([MeshObject(mesh, np.eye(4), Material(), 1)])
    c, a, st = s.draw(cam)
    d = s.twin(cam)
    np.testing.assert_array_equal(c, d["color"])
    np.testing.assert_array_equal(a, d["aux"])
    assert st["near_clipped"] > 10
    if near < 1e-3:
        assert d["counters"]["guard_clipped"] > 10
    assert not np.any(c == EMPTY), "open pixels inside a closed mesh"


def polygon_mask(poly, w, h, eps=1e-3):
    """(inside, undecided) for a simple polygon (even-odd rule), as hull_mask."""
    ys, xs = np.mgrid[0:h, 0:w]
    p = np.stack([xs + 0.5, ys + 0.5], axis=-1).reshape(-1, 1, 2)
    a, b = poly[None, :, :], np.roll(poly, -1, axis=0)[None, :, :]
    cross = ((a[..., 1] > p[..., 1]) != (b[..., 1] > p[..., 1])) & \
        (p[..., 0] < a[..., 0] + (p[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1] + 1e-300))
    inside = cross.sum(axis=1) % 2 == 1
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / (ab * ab).sum(-1), 0, 1)
    dist = np.linalg.norm(p - (a + t[..., None] * ab), axis=-1).min(axis=1)
    return (inside & (dist > eps)).reshape(h, w), (dist <= eps).reshape(h, w)


def test_grid_from_the_front_is_watertight_without_double_writes():
    """A single-layer height field seen from the front: every pixel centre inside its projected
    border covered, and each covered exactly once (pixels covered == pixels written)."""
    n = 20
    v, f = grid(n, bump=0.1)
    mesh = flat_lod(v, f, run=64)
    cam = Camera.look_at((0.1, -0.05, 3.0), (0, 0, 0), size=(96, 72), near=0.1, far=50)
    model = rot_x(12)
    s = Scene([MeshObject(mesh, model, Material(), 1)])
    c, _, st = s.draw(cam)
    d = s.twin(cam)
    np.testing.assert_array_equal(c, d["color"])
    k = np.arange(n)
    loop = np.concatenate([k, n + k * (n + 1), (n + 1) * n + n - k, (n - k) * (n + 1)])   # the border, in order
    inside, undecided = polygon_mask(screen(cam, model, v.astype(np.float64))[loop], 96, 72)
    covered = c != EMPTY
    assert inside.sum() > 1500
    assert not np.any(inside & ~covered)
    assert not np.any(covered & ~inside & ~undecided)
    assert d["coverage"].max() == 1
    assert st["pixels"] == covered.sum()


GL_VERTEX = """#version 450
uniform mat4 u_mvp;
uniform mat4 u_mv;
in vec3 in_pos;
out float v_depth;
void main() {
    v_depth = -(u_mv * vec4(in_pos, 1.0)).z;
    gl_Position = u_mvp * vec4(in_pos, 1.0);
}
"""
GL_FRAGMENT = """#version 450
in float v_depth;
out vec4 f_out;
void main() { f_out = vec4(v_depth, 1.0, 0.0, 1.0); }
"""


def gl_depth(scene, camera):
    """Linear view depth of the scene's triangles drawn by a plain OpenGL program (inf: none)."""
    ctx = gl_context()
    w, h = camera.size
    prog = ctx.program(vertex_shader=GL_VERTEX, fragment_shader=GL_FRAGMENT)
    fbo = ctx.framebuffer(color_attachments=[ctx.texture((w, h), 4, dtype="f4")],
                          depth_attachment=ctx.depth_renderbuffer((w, h)))
    fbo.use()
    ctx.viewport = (0, 0, w, h)
    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
    ctx.enable(ctx.DEPTH_TEST)
    ctx.disable(ctx.CULL_FACE)
    a, inst = scene.arrays, scene.instances
    for i in range(len(inst)):
        mesh = inst.inst_u[i, 0]
        c0, nc = a.ranges[mesh]
        t0 = a.clusters["first"][c0]
        t1 = a.clusters["first"][c0 + nc - 1] + a.clusters["count"][c0 + nc - 1]
        tri = a.vertices[a.triangles[t0:t1].reshape(-1)][:, :3].astype("f4")
        model = inst.inst_f[i, INSTANCE_F.slice("model")].reshape(4, 4).astype(np.float64)
        mv = camera.view @ model
        prog["u_mv"].write(mv.T.astype("f4").tobytes())
        prog["u_mvp"].write((camera.projection @ mv).T.astype("f4").tobytes())
        vbo = ctx.buffer(tri.tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f", "in_pos")])
        vao.render()
        vao.release()
        vbo.release()
    out = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(h, w, 4)[::-1]
    fbo.release()
    prog.release()
    return np.where(out[..., 1] > 0, out[..., 0], np.inf)


def test_coverage_and_depth_match_opengl(scene):
    """The same triangles drawn by OpenGL (Mesa): coverage IoU >= 0.99, depth within 1e-4."""
    bunny = flat_lod(*load_bunny())
    lo, hi = bunny.vertices.min(axis=0), bunny.vertices.max(axis=0)
    fit = translate(-0.3, -0.55, 1.45) @ rot_x(-90) @ np.diag([*[0.9 / (hi - lo).max()] * 3, 1]) @ translate(*-(lo + hi) / 2)
    big = Scene([*scene.objects, MeshObject(bunny, fit, Material(), 4)])
    for cam in (Camera.look_at((0.0, 0.8, 3.6), (0.1, -0.1, -0.3), size=(160, 120), near=0.1, far=50),
                Camera.look_at((0.4, 0.2, 1.4), (0.3, -0.2, -1), size=(120, 90), near=0.05, far=50)):
        c, _, st = big.draw(cam)
        assert st["triangles"] > 100000
        ours = c != EMPTY
        depth = np.where(ours, (c >> np.uint64(32)).astype(np.uint32).view(np.float32), np.inf)
        gl = gl_depth(big, cam)
        theirs = np.isfinite(gl)
        iou = (ours & theirs).sum() / (ours | theirs).sum()
        assert iou >= 0.99, iou
        both = ours & theirs
        close = np.isclose(depth[both], gl[both], rtol=1e-4)
        assert close.mean() > 0.99   # the rest: pixels on depth discontinuities (edge rules differ)


def test_large_list_overflow_grows_and_redraws(scene):
    camera = CASES["large"][0]
    raster = MeshRaster(large_pixels=4, large_capacity=8)
    selection = scene.selection()
    keys = KeyBuffer(*camera.size)
    keys.clear()
    c, a, st = scene.draw(camera, raster, keys=keys, selection=selection)
    assert st["large_overflow"] == st["large"] - 8 > 0
    assert raster.grow()
    assert raster.large_capacity >= st["large"]
    keys.clear()
    c, a, st = scene.draw(camera, raster, keys=keys, selection=selection)
    assert st["large_overflow"] == 0 and not raster.grow()
    d = scene.twin(camera)
    np.testing.assert_array_equal(c, d["color"])
    np.testing.assert_array_equal(a, d["aux"])


def test_selection_count_past_the_capacity_draws_the_capacity(scene):
    """The cut may count more clusters than its buffer holds: the first ``capacity`` are drawn."""
    camera = CASES["outside"][0]
    cap = len(scene.pairs) - 7
    c, a, st = scene.draw(camera, selection=scene.selection(count=len(scene.pairs) + 50, capacity=cap))
    d = scene.twin(camera, pairs=scene.pairs[:cap])
    np.testing.assert_array_equal(c, d["color"])
    np.testing.assert_array_equal(a, d["aux"])
    assert st["triangles"] == d["counters"]["triangles"]


def test_only_nearer_keys_replace_what_is_there(scene):
    """Meshes composite with whatever else drew into the keys: the result is the per-pixel minimum."""
    camera = CASES["outside"][0]
    w, h = camera.size
    rng = np.random.default_rng(3)
    depth = rng.uniform(2.0, 4.5, (h, w)).astype(np.float32).view(np.uint32).astype(np.uint64)
    before = (depth << np.uint64(32)) | rng.integers(0, 2 ** 32, (h, w), dtype=np.uint64)
    before[rng.random((h, w)) < 0.3] = EMPTY
    keys = KeyBuffer(w, h)
    q = cl_device().queue
    cl.enqueue_copy(q, keys.color, before)
    cl.enqueue_copy(q, keys.aux, before)
    c, a, _ = scene.draw(camera, keys=keys)
    d = scene.twin(camera)
    np.testing.assert_array_equal(c, np.minimum(before, d["color"]))
    np.testing.assert_array_equal(a, np.minimum(before, d["aux"]))
    assert np.any(c == before) and np.any((c != before) & (before != EMPTY))


def test_debug_colours_compile_as_glsl_and_match_the_twin():
    ctx = gl_context()
    src = "#version 450\n" + kernels.source("common/dialect.glsl") + kernels.source("common/debug_color.cl")
    prog = ctx.program(
        vertex_shader="#version 450\nvoid main() { vec2 p = vec2(gl_VertexID & 1, gl_VertexID >> 1);"
                      " gl_Position = vec4(p * 4.0 - 1.0, 0.0, 1.0); }",
        fragment_shader=src + "out vec4 f_out;\nvoid main() {\n uint i = uint(gl_FragCoord.x);\n"
                              " f_out = vec4(gl_FragCoord.y < 1.0 ? pl_cluster_color(i * 977u) : pl_level_color(i), 1.0);\n}\n")
    w = 64
    fbo = ctx.framebuffer(color_attachments=[ctx.texture((w, 2), 4, dtype="f4")])
    fbo.use()
    ctx.viewport = (0, 0, w, 2)
    vao = ctx.vertex_array(prog, [])
    vao.render(mode=ctx.TRIANGLES, vertices=3)
    out = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(2, w, 4)[..., :3]
    idx = np.arange(w, dtype=np.uint32)
    np.testing.assert_allclose(out[0], ref.cluster_color(idx * np.uint32(977)), atol=2e-6)
    np.testing.assert_allclose(out[1], ref.level_color(idx), atol=0)
    # distinct: eight levels far apart, neighbouring clusters unlike each other
    lv = ref.level_color(np.arange(8))
    assert min(np.abs(lv[i] - lv[j]).max() for i in range(8) for j in range(i)) > 0.2
    cc = ref.cluster_color(np.arange(1000))
    assert np.all(cc >= 0) and np.all(cc <= 1)
    assert np.median(np.abs(np.diff(cc, axis=0)).max(axis=1)) > 0.2


def test_bad_input_is_named(scene):
    camera = CASES["outside"][0]
    raster = MeshRaster()
    keys = KeyBuffer(*camera.size)
    with pytest.raises(MeshError, match="color_by"):
        raster.enqueue(keys, camera, scene.dev, *scene.selection(), color_by=3)
    with pytest.raises(MeshError, match="with_size"):
        raster.enqueue(KeyBuffer(32, 32), camera, scene.dev, *scene.selection())
    with pytest.raises(MeshError, match="light record"):
        raster.enqueue(keys, camera, scene.dev, *scene.selection(), light=[0, 0, 1])
    with pytest.raises(MeshError, match="large_capacity"):
        MeshRaster(large_capacity=0)
    assert COUNTERS[0] == "triangles" and len(COUNTERS) == 7
