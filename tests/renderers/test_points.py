"""Direct point renderer: the 64-bit buffer against np.minimum.at, silhouettes, holes, NaN."""
import re

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest
import sympy as sp

import paramlod as pl
from paramlod import kernels
from paramlod.app.bench import peers
from paramlod.app.bench.scenes import apply_variant_settings
from paramlod.core.color import SRGB8_BUCKETS, srgb8_thresholds
from paramlod.core.layouts import cl_prelude
from paramlod.device.context import cl_device
from paramlod.function import programs as function_programs
from paramlod.function.codegen_cl import SPLIT_NONE, SPLIT_U, SPLIT_V, surface_split
from paramlod.pipeline.driver import scene_state
from paramlod.scene.framing import framing_camera
from paramlod.renderers import points as points_module
from paramlod.renderers.points import DirectPointRenderer, grid_counts, packs, patch_wraps
from paramlod.renderers.targets import KeyBuffer

from conftest import check_every_sample_once, iou, record_direct_points, sphere_disc
from helpers.stages import ParametricStage as renderer_for


def test_key_buffer_equals_minimum_at_over_the_same_samples():
    # each sample covering the pixel it lands in (the recording hook records that pixel)
    check_every_sample_once(*record_direct_points(pl.PointSettings(coverage="pixel"), (96, 80)))


def test_runs_of_split_functions_visit_every_sample_once(monkeypatch):
    # the fibre splits along u, a seashell along v, the sphere not at all (codegen_cl.split_surface):
    # the work-items' runs down grid lines (points.cl patch_runs) take each sample once, and give
    # the keys of runs of one sample evaluated whole (PL_RUN 1, as on GPUs) bit for bit
    scene = pl.Scene()
    scene.add("fiber", material=pl.Material(color=(0.8, 0.5, 0.3)))
    scene.add("seashell1", transform=pl.translate(9.0, 0.0, 0.0) @ pl.scale(0.6))
    scene.add("sphere", transform=pl.translate(-4.0, 0.0, 0.0) @ pl.scale(2.0))
    assert [split_kind(f) for f in scene.functions()] == [SPLIT_U, SPLIT_V, SPLIT_NONE]
    cam = framing_camera(scene, size=(120, 72))
    colors = []
    for run in (1, 3, 16):
        monkeypatch.setattr(function_programs, "RUN_CPU", run)
        colors.append(check_every_sample_once(*record_direct_points(pl.PointSettings(coverage="pixel"), cam.size,
                                                                    scene, cam)))
    for color in colors[1:]:
        np.testing.assert_array_equal(color, colors[0])


def ring_grid(major: float, minor, tilt: float = 0.0) -> pl.Scene:
    """40 rings 0.3 apart on an 8 x 5 grid: ring k of minor radius ``minor(k)``, turned ``tilt`` x k
    degrees about x."""
    scene = pl.Scene()
    for k in range(40):
        scene.add("torus", params={"major": major, "minor": minor(k)},
                  transform=pl.translate(0.3 * (k % 8) - 1.05, 0.3 * (k // 8) - 0.6, 0.0) @ pl.rotate(tilt * k, (1, 0, 0)))
    return scene


@pytest.mark.parametrize("run", [1, 16])
def test_packed_work_draws_the_keys_of_a_pass_per_patch(run, monkeypatch):
    # many small patches (40 thin rings and a fibre, a unit or a few each) and large ones (a sphere):
    # work-items that take their own runs across patches (PL_PACK 1) visit every sample once and
    # leave the keys of a pass of the work-group per patch (PL_PACK 0), with runs of one sample
    # (as on GPUs) and of 16. One work-group per compute unit: each takes hundreds of units, so
    # a work-item's next unit is often several patches on
    scene = ring_grid(0.12, lambda k: 0.002 + 0.001 * (k % 5), tilt=9.0)
    scene.add("fiber", transform=pl.translate(0.0, -1.0, 0.0) @ pl.scale(0.08))
    scene.add("sphere", transform=pl.translate(1.4, 0.0, -1.0) @ pl.scale(0.5))
    cam = framing_camera(scene, size=(160, 120))
    monkeypatch.setattr(function_programs, "RUN_CPU", run)
    monkeypatch.setattr(DirectPointRenderer, "groups_per_unit", 1)
    colors = []
    for pack in (True, False):
        monkeypatch.setattr(DirectPointRenderer, "pack", pack)
        colors.append(check_every_sample_once(*record_direct_points(pl.PointSettings(coverage="pixel"), cam.size,
                                                                    scene, cam)))
    np.testing.assert_array_equal(colors[0], colors[1])


@pytest.mark.parametrize("pack", [True, False])
def test_work_group_schedule_draws_the_keys_of_one_atomic_per_patch(pack, monkeypatch):
    # GPUs schedule a work-group's patches with one atomic (points.cl PL_GROUP_SCHEDULE): every
    # sample is drawn once, and the keys and samples are those of one atomic a patch; here on
    # the CPU, with few work-groups (each schedules several passes of 64 patches) and runs of one
    # sample, as on GPUs
    n_dots = 64 * cl_device().device.max_compute_units + 100   # more patches than one pass of the groups

    def rings():   # a new scene each time: its own programs
        scene = ring_grid(0.12, lambda k: 0.002 + 0.001 * (k % 5), tilt=9.0)
        at = np.tile(np.eye(4), (n_dots, 1, 1))
        at[:, 0, 0] = at[:, 1, 1] = at[:, 2, 2] = 0.004
        at[:, 0, 3], at[:, 1, 3] = np.linspace(-1.2, 1.2, n_dots), 0.9
        scene.add_instances("sphere", n_dots, transforms=at)
        return scene

    cam = framing_camera(rings(), size=(160, 120))
    monkeypatch.setattr(function_programs, "RUN_CPU", 1)
    monkeypatch.setattr(DirectPointRenderer, "groups_per_unit", 1)
    monkeypatch.setattr(DirectPointRenderer, "pack", pack)
    rs = pl.RenderSettings()
    rs.points.occlusion = False
    colors, frames = [], []
    for grouped in (True, False):
        monkeypatch.setattr(DirectPointRenderer, "group_schedule", grouped)
        colors.append(check_every_sample_once(*record_direct_points(pl.PointSettings(coverage="pixel"), cam.size,
                                                                    rings(), cam)))
        frame = pl.render(rings(), cam, "points", rs)   # a frame without the recording hook
        frames.append(frame)
    assert frames[0].stats["render_patches"] > n_dots
    np.testing.assert_array_equal(colors[0], colors[1])
    assert frames[0].stats["samples"] == frames[1].stats["samples"] > 0
    np.testing.assert_array_equal(frames[0].rgb8(), frames[1].rgb8())
    np.testing.assert_array_equal(frames[0].depth, frames[1].depth)


def test_gpus_pack_after_frames_of_small_patches():
    # the fibre curtain's patches (19-30 samples) are drawn packed; the 19,600 glyphs' far away
    # (34) and larger ones keep a pass of the work-group each
    assert packs(30 * 358_140, 358_140) and not packs(34 * 19_600, 19_600) and not packs(5_402 * 3_786, 3_786)


def test_a_gpu_switches_to_packed_work_after_a_frame_of_small_patches():
    # the GPUs' choice, made here on the CPU: a frame of 40 thin rings drawn a pass of the
    # work-group per patch has under 32 samples a patch, so the next is drawn packed, with the
    # same image
    rings = ring_grid(0.04, lambda k: 0.002)
    cam = framing_camera(rings, size=(160, 120))
    rs = pl.RenderSettings()
    rs.points.occlusion = False
    pl.render(rings, cam, "points", rs)   # builds the scene's renderer (a CPU's packs always)
    sampler = next(r.points for r in scene_state(rings).renderer_states()
                   if isinstance(getattr(r, "points", None), DirectPointRenderer))
    sampler._auto_pack, sampler.packed = True, False
    first = pl.render(rings, cam, "points", rs)
    assert first.stats["samples"] < 32 * first.stats["render_patches"] and sampler.packed
    second = pl.render(rings, cam, "points", rs)
    np.testing.assert_array_equal(second.rgb8(), first.rgb8())
    np.testing.assert_array_equal(second.depth, first.depth)
    kinds = {kind for _, _, kind in sampler._launches}
    assert kinds == {("pixel", False, False), ("pixel", False, True)}


def test_a_frame_of_more_units_than_the_schedule_numbers_is_refused(monkeypatch):
    # order[] holds a patch's first unit in 32 bits: a frame past that would draw wrong patches,
    # so it is refused by name (the limit lowered here to a sphere's units)
    monkeypatch.setattr(points_module, "MAX_UNITS", 100)
    scene = pl.Scene()
    scene.add("sphere")
    with pytest.raises(pl.CapacityError, match="sample runs, more than the schedule numbers"):
        pl.render(scene, pl.Camera.look_at((0, 0, 3), (0, 0, 0), size=(64, 48)), "points")


def split_kind(fn):
    split = surface_split(fn)
    return SPLIT_NONE if split is None else split.axis


def test_early_depth_before_shading_keeps_every_key():
    """points_direct skips shading a sample whose pixel already holds a strictly nearer depth
    (kernels/points/points.cl); the recording hook draws without that test. Five tori one behind
    the other: most samples are hidden, and both renders leave the same colour and aux keys."""
    scene = pl.Scene()
    for k in range(5):
        scene.add("torus", transform=pl.translate(0.1 * k, 0.05 * k, -0.6 * k) @ pl.rotate(20 * k, (1, 0, 0)),
                  material=pl.Material(color=(0.2 * k, 0.5, 0.9 - 0.15 * k)))
    cam = pl.Camera.look_at((0.4, 0.3, 3.0), (0.2, 0.1, -1.2), size=(120, 96))
    settings = pl.PointSettings()
    r = renderer_for(scene)
    dev = r.upload(scene, cam)
    rbuf, n, _, _ = r.lod.run(dev["inst"], dev["domains"], dev["cam"], pl.LodSettings(), one_sided=dev["one_sided"])
    rl = r.lod.read_render_list(n)
    nu, nv = grid_counts(rl, settings, wraps=patch_wraps(rl, dev["flags"], dev["domains"]))
    counts = nu * nv
    q = cl_device().queue
    off = cla.to_device(q, np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.uint32))
    pix, key = cla.empty(q, int(counts.sum()), np.uint32), cla.empty(q, int(counts.sum()), np.uint64)
    drawn = []
    for record in (False, True):
        keys = KeyBuffer(*cam.size)
        keys.clear()
        DirectPointRenderer(scene.functions(), record=record).draw(
            rbuf, n, dev["inst"], dev["materials"], dev["cam"], dev["light"], keys, settings,
            record_args=(off.data, pix.data, key.data) if record else ())
        drawn.append(keys.read_keys())
    (color, aux), (color_all, aux_all) = drawn
    np.testing.assert_array_equal(color, color_all)
    np.testing.assert_array_equal(aux, aux_all)
    # most drawn samples lie behind their pixel's final depth: the test had work to skip
    p, k = pix.get(), key.get()
    kept = p != 0xFFFFFFFF
    hidden = (k[kept] >> np.uint64(32)) > (color_all.reshape(-1)[p[kept]] >> np.uint64(32))
    assert hidden.mean() > 0.5


@pytest.mark.parametrize("dist", [2.2, 2.6, 9.0])
def test_sphere_silhouette_and_no_holes(dist):
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0.3 * dist, 0.2 * dist, dist), (0, 0, 0), size=(256, 256))
    frame = pl.render(scene, cam)
    disc, depth = sphere_disc(cam)
    # points cover every pixel a sample lands in (conservative), so the silhouette may grow by
    # up to a pixel: IoU >= 0.99 once the disc is large (radius >= 100 px), and always within 1 px
    if dist <= 2.6:
        assert iou(frame.coverage, disc) >= 0.99
    assert not np.any(frame.coverage & ~_dilate(disc, 1))
    assert np.all(frame.coverage[disc & ~_dilate(~disc, 1)])
    # no holes: every pixel well inside the disc shows the front surface at the analytic depth
    inner = disc & ~_dilate(~disc, 2)
    assert inner.sum() > 500
    assert np.all(frame.coverage[inner])
    err = np.abs(frame.depth[inner] - depth[inner])
    assert np.max(err) < 0.02 * dist, f"max depth error {np.max(err)} (a hole shows the back side)"
    assert frame.stats["nan_samples"] == 0


def _dilate(mask, r):
    out = mask.copy()
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            out |= np.roll(np.roll(mask, dy, 0), dx, 1)
    return out


def test_rendering_twice_is_bit_identical():
    scene = pl.Scene()
    scene.add("torus", transform=pl.rotate(50, (1, 0, 0)))
    scene.add("sphere", transform=pl.translate(0, 0, 0.3) @ pl.scale(0.5))
    cam = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(160, 120))
    a, b = pl.render(scene, cam), pl.render(scene, cam)
    for name in ("color", "depth", "normal", "object_id"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_frame_channels_are_consistent():
    scene = pl.Scene()
    scene.add("sphere", material=pl.Material(color=(1.0, 0.0, 0.0)))
    scene.add("sphere", transform=pl.translate(2.2, 0, 0), material=pl.Material(color=(0.0, 0.0, 1.0)))
    cam = pl.Camera.look_at((1.1, 0, 6), (1.1, 0, 0), size=(160, 96))
    f = pl.render(scene, cam)
    cov = f.coverage
    assert set(np.unique(f.object_id[cov])) == {1, 2}
    assert np.all(f.object_id[~cov] == 0) and np.all(f.color[~cov] == 0)
    assert np.all(f.color[cov, 3] == 1.0)
    left, right = f.object_id == 1, f.object_id == 2
    assert f.color[left, 0].mean() > f.color[left, 2].mean()
    assert f.color[right, 2].mean() > f.color[right, 0].mean()
    # normals: unit length, facing the camera, close to the analytic sphere normals
    n = f.normal[cov]
    assert np.allclose(np.linalg.norm(n, axis=-1), 1, atol=1e-2)
    ys, xs = np.nonzero(left)
    y, x = int(round(ys.mean())), int(round(xs.mean()))   # the sphere's middle: facing the camera
    assert left[y, x] and f.normal[y, x, 2] > 0.9


def test_nan_samples_are_dropped_and_counted():
    @pl.parametric(u=(0, 1), v=(0, 1))
    def half_nan(u, v):
        # undefined (sqrt of a negative number) where u < 0.5
        return u - 0.5, v - 0.5, sp.sqrt(u - sp.Rational(1, 2)) * 0.1

    scene = pl.Scene()
    scene.add(half_nan)
    cam = pl.Camera.look_at((0, 0, 2), (0, 0, 0), size=(96, 96))
    f = pl.render(scene, cam)
    assert f.stats["nan_samples"] > 0
    cov = f.coverage
    xs = np.nonzero(cov)[1]
    assert cov.sum() > 500
    # only the defined half (x >= 0, right half of the image) is drawn
    assert xs.min() >= 96 // 2 - 2


def test_srgb_encoding_table_rounds_the_srgb_curve():
    """keys.cl encodes colour by searching SRGB8_THRESHOLDS (emitted into the OpenCL prelude by
    paramlod.core.color); the table must give the code that rounding the exact sRGB curve gives
    (checked away from the code boundaries)."""
    src = cl_prelude()
    body = src[src.index("SRGB8_THRESHOLDS[256] = {"):]
    t = np.array([float(x) for x in re.findall(r"-?\d+\.\d+(?:e-?\d+)?", body[:body.index("};")])])
    assert len(t) == 256
    x = np.random.default_rng(0).random(20_000)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    exact = np.floor(s * 255 + 0.5)
    code = np.searchsorted(t, x, side="right") - 1
    away = np.min(np.abs(x[:, None] - t[None, 1:]), axis=1) > 1e-6
    np.testing.assert_array_equal(code[away], exact[away])


@pytest.mark.parametrize("gpu_form", [0, 1])
def test_srgb8_encodes_as_the_threshold_search(gpu_form):
    """keys.cl's srgb8, both forms (CPUs: one bucket of SRGB8_BUCKET_CODES and one comparison;
    GPUs, PL_GPU: a binary search), gives the count of SRGB8_THRESHOLDS[1:] at or below x
    (raster_reference's twin), on every float32 within 3 ulps of each threshold and of each
    bucket's start, random values, and below 0, above 1, infinities and NaN (0)."""
    t = srgb8_thresholds()
    near = np.concatenate([t[1:], (np.arange(SRGB8_BUCKETS + 1) / SRGB8_BUCKETS).astype(np.float32)])
    ulps = np.arange(-3, 4, dtype=np.int32)
    x = np.concatenate([(near.view(np.int32)[:, None] + ulps[None, :]).ravel().view(np.float32),
                        np.random.default_rng(1).random(50_000, np.float32),
                        np.float32([-1.0, -0.0, 0.0, 1.0, 1.5, 1e30, np.inf, -np.inf, np.nan])])
    dev = cl_device()
    src = (cl_prelude() + "\n" + kernels.source("common/keys.cl") +
           "\n__kernel void probe(__global const float* x, __global uint* o) {\n"
           "    o[get_global_id(0)] = srgb8(x[get_global_id(0)]);\n}\n")
    prog = cl.Program(dev.context, src).build(options=[f"-DPL_GPU={gpu_form}"])
    xd, out = cla.to_device(dev.queue, x), cla.empty(dev.queue, len(x), np.uint32)
    prog.probe(dev.queue, (len(x),), None, xd.data, out.data)
    want = np.where(np.isnan(x), 0, np.searchsorted(t[1:], x, side="right"))
    np.testing.assert_array_equal(out.get(), want)


@pytest.mark.parametrize("scene_name", ["glyphs8", "torus"])
@pytest.mark.parametrize("variant", ["points", "points-centre", "points-quad"])
def test_vector_lanes_draw_the_frames_of_one_sample_at_a_time(scene_name, variant, monkeypatch):
    """CPU devices evaluate a run's samples, or a quad run's corners, on vector lanes
    (paramlod.function.codegen_vector, points.cl surface_lanes): the same samples, so the same
    frame as one at a time, bit for bit, with every coverage, on a glyph field (a split along u)
    and the torus (no split). (GPUs evaluate one at a time either way.)"""
    spec = peers.scene_spec(scene_name, (96, 96), grid=3)
    field = peers.glyph_field(spec["order"], spec["grid"]) if spec["kind"] == "glyphs" else None
    cam = peers.camera_of(spec)
    rs = pl.RenderSettings()
    apply_variant_settings(rs, variant)
    frames = []
    for vector in (True, False):
        monkeypatch.setattr(DirectPointRenderer, "vector_lanes", vector)
        frame = pl.render(peers.paramlod_scene(spec, field), cam, "points", rs)   # a new scene: its own programs
        assert frame.coverage.mean() > 0.05
        frames.append((frame.rgb8(), frame.depth, frame.stats["samples"]))
    assert frames[0][2] == frames[1][2] > 0
    assert np.array_equal(frames[0][0], frames[1][0]) and np.array_equal(frames[0][1], frames[1][1])

