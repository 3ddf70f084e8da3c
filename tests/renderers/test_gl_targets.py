"""The OpenGL targets' resolve and the lazy Frames it lends (paramlod.renderers.gl_targets): the
8-bit image equals the host's encoding bit for bit, a Frame keeps its arrays however many frames
follow, and the output sets are reused once Frames are dropped."""
import gc

import moderngl
import numpy as np
import pytest

import paramlod as pl
from paramlod import kernels
from paramlod.core.color import SRGB8_BUCKETS, linear_to_srgb8, linear_to_srgb8_buckets, linear_to_srgb8_thresholds
from paramlod.device.context import gl_context
from paramlod.renderers import gl_targets
from paramlod.renderers.tess import build_programs


def _scene():
    s = pl.Scene(background=(0.3, 0.1, 0.05))
    s.add("torus", transform=pl.rotate(50, (1, 0, 0)), material=pl.Material(color=(0.9, 0.3, 0.1)))
    s.add("sphere", transform=pl.translate(0.4, 0, 0.3) @ pl.scale(0.5))
    return s


def _tess(scene, cam, aa="noAA"):
    rs = pl.RenderSettings()
    rs.tess.aa = aa
    return pl.render(scene, cam, "tess", rs)


def _bucket_codes(x):
    """The resolve's encoding (kernels/tess/tess_resolve_fragment.glsl srgb8_code) in numpy."""
    table = linear_to_srgb8_buckets()
    c = np.clip(x, 0, 1)
    i = np.minimum((c * np.float32(SRGB8_BUCKETS)).astype(np.int64), SRGB8_BUCKETS - 1)
    return (table[i, 0] + (c >= table[i, 1])).astype(np.uint8)


def test_the_encoders_tables_give_the_host_encoder_bit_for_bit():
    """The thresholds (count those <= x) and the buckets the resolve reads (a bucket's code, plus
    one past its threshold) give linear_to_srgb8's code on every float32 near a threshold, on
    random ones and out of range."""
    thr = linear_to_srgb8_thresholds()
    assert thr.dtype == np.float32 and len(thr) == 255 and np.all(np.diff(thr) > 0)
    bits = thr.view(np.uint32).astype(np.int64)
    near = (bits[:, None] + np.arange(-64, 65)[None, :]).ravel()
    rng = np.random.default_rng(7)
    x = np.concatenate([near.astype(np.uint32).view(np.float32), rng.random(2_000_000, np.float32),
                        np.float32([0, 1, -1, 2, 1e-30, 0.0031308, np.inf, -np.inf])])
    want = linear_to_srgb8(x)
    np.testing.assert_array_equal(np.searchsorted(thr, x, side="right").astype(np.uint8), want)
    np.testing.assert_array_equal(_bucket_codes(x), want)


def test_the_buckets_give_the_host_encoder_on_every_float_in_0_1():
    """All 1,065,353,217 float32 values in [0, 1], in slices (about 15 s on two cores)."""
    one = int(np.float32(1).view(np.uint32))
    step = 1 << 24
    for start in range(0, one + 1, step):
        x = np.arange(start, min(start + step, one + 1), dtype=np.uint32).view(np.float32)
        bad = np.flatnonzero(_bucket_codes(x) != linear_to_srgb8(x))
        assert not len(bad), f"{len(bad)} values encode differently, e.g. {x[bad[:3]]}"


@pytest.mark.parametrize("uniform", [True, False])
def test_the_fragment_encoder_gives_the_host_encoder_bit_for_bit(uniform):
    """common/targets.glsl srgb8_code with its table read as a uniform block (llvmpipe's path) and
    as a storage buffer (the GPUs'): every float32 within 64 ULPs of each threshold, random values
    and out-of-range ones encode as linear_to_srgb8 does."""
    ctx = gl_context()
    thr = linear_to_srgb8_thresholds().view(np.uint32).astype(np.int64)
    near = ((thr[:, None] + np.arange(-64, 65)[None, :]).ravel()).astype(np.uint32).view(np.float32)
    x = np.concatenate([near, np.random.default_rng(3).random(20_000, np.float32),
                        np.float32([0.0, -0.0, 1.0, -1.0, 2.0, 1e-30, 0.0031308, np.inf, -np.inf])])
    w = 256
    h = -(-len(x) // w)
    values = np.zeros(w * h, np.float32)
    values[:len(x)] = x
    source = ctx.texture((w, h), 1, values.tobytes(), dtype="f4")
    source.filter = (ctx.NEAREST, ctx.NEAREST)
    defines = f"#define PL_SRGB8_BUCKETS {SRGB8_BUCKETS}\n" + ("#define PL_SRGB8_UNIFORM 1\n" if uniform else "")
    prog = ctx.program(
        vertex_shader="#version 450 core\n" + kernels.source("tess/tess_resolve_vertex.glsl"),
        fragment_shader="#version 450 core\n" + defines + kernels.source("common/targets.glsl") + """
uniform sampler2D u_x;
void main() { out_image = srgb8_image(vec3(texelFetch(u_x, ivec2(gl_FragCoord.xy), 0).r)); }""")
    table = ctx.buffer(gl_targets.srgb8_table().tobytes())
    (table.bind_to_uniform_block if uniform else table.bind_to_storage_buffer)(gl_targets.SRGB8_TABLE_BINDING)
    # the targets' five attachments (common/targets.glsl); the image is the fifth
    attachments = [ctx.texture((w, h), c, dtype=d) for c, d in ((4, "f4"), (1, "f4"), (4, "f4"), (1, "u4"), (4, "u1"))]
    fbo = ctx.framebuffer(attachments)
    fbo.use()
    ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
    source.use(location=0)
    prog["u_x"] = 0
    ctx.vertex_array(prog, []).render(mode=moderngl.TRIANGLES, vertices=3)
    image = np.frombuffer(fbo.read(components=4, attachment=4, dtype="u1"), np.uint8)   # rows in upload order
    np.testing.assert_array_equal(image.reshape(-1, 4)[:len(x), 0], linear_to_srgb8(x))
    for obj in (fbo, *attachments, source, table, prog):
        obj.release()
    gl_targets.bind_srgb8_buckets(ctx)   # the renderers' binding again


@pytest.mark.parametrize("aa", ["noAA", "4xSS"])
def test_tess_image_is_the_host_encoding_bit_for_bit(aa):
    scene = _scene()
    cam = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(80, 60))
    frame = _tess(scene, cam, aa)
    image = frame.rgb8()
    assert frame.on_device == ("color", "depth", "normal", "object_id")   # only the image was read
    a = frame.color[..., 3:4]
    encoded = linear_to_srgb8(frame.color[..., :3] * a + np.asarray(scene.background, np.float32) * (1 - a))
    edge = (a[..., 0] > 0) & (a[..., 0] < 1)
    assert edge.sum() > (50 if aa == "4xSS" else -1) and (a[..., 0] == 1).sum() > 1000
    np.testing.assert_array_equal(image, encoded)   # partly covered edge pixels too
    assert frame.stats["pixels_written"] == int(np.isfinite(frame.depth).sum())
    assert frame.stats["ms"]["readback"] == 0.0     # paid on access


def test_tess_image_follows_a_new_background():
    scene = _scene()
    cam = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(48, 40))
    frame = _tess(scene, cam)
    frame.background = (0.0, 0.5, 1.0)   # the device's image was made over the scene's: encoded anew
    a = frame.color[..., 3:4]
    np.testing.assert_array_equal(frame.rgb8(), linear_to_srgb8(
        frame.color[..., :3] * a + np.float32([0.0, 0.5, 1.0]) * (1 - a)))


def test_frames_keep_their_arrays_however_many_follow():
    """More live Frames than output sets (LENT_SETS): the oldest are copied to the host before
    their set is drawn into again; every one still holds its own camera's image."""
    scene = _scene()
    cams = [pl.Camera.look_at((0, 1, 3 + k), (0, 0, 0), size=(48, 40)) for k in range(gl_targets.LENT_SETS + 2)]
    frames = [_tess(scene, c) for c in cams]
    assert frames[0].on_device == ()            # copied when its set was taken back
    assert frames[-1].on_device                 # still on the device
    written = [f.stats["pixels_written"] for f in frames]
    assert written == sorted(written, reverse=True) and written[-1] < written[0]   # the torus recedes
    for cam, f in zip(cams, frames):
        again = _tess(scene, cam).materialize()
        np.testing.assert_array_equal(f.depth, again.depth)
        np.testing.assert_array_equal(f.rgb8(), again.rgb8())


def test_output_sets_are_reused_once_frames_are_dropped():
    scene = _scene()
    near = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(48, 40))
    far = pl.Camera.look_at((0, 2, 6), (0, 0, 0), size=(48, 40))
    sets = set()
    for _ in range(4):
        frame = _tess(scene, near)   # the previous frame is alive while this one draws: two sets
        sets.add(id(frame._source))
    assert len(sets) == 2
    del frame
    gc.collect()
    first = _tess(scene, near)       # the set just given back is drawn into again, and lent
    second = _tess(scene, far)       # so this one must take another
    assert first._source is not second._source
    assert np.isfinite(first.depth).sum() > np.isfinite(second.depth).sum()


def test_a_frame_outlives_its_targets():
    """Targets of another size replace the cached ones: a Frame lent by the old ones reads its
    arrays first."""
    scene = _scene()
    small = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(40, 32))
    frame = _tess(scene, small)
    _tess(scene, small.with_size((56, 40)))
    assert frame.on_device == ()
    np.testing.assert_array_equal(frame.rgb8(), _tess(scene, small).rgb8())


def test_a_set_drawn_into_again_keeps_nothing_of_its_last_frame():
    """noAA frames are drawn straight into an output set (GLTargets.direct), which is cleared
    only in its object ids and image; its colour, depth and normal are blanked where no object
    was drawn when read: after a near frame is dropped, a far frame drawn into its set equals one
    drawn into a fresh set, and its bare pixels hold the background only."""
    scene = _scene()
    near = pl.Camera.look_at((0, 1, 2.2), (0, 0, 0), size=(48, 40))
    far = pl.Camera.look_at((0, 2, 6), (0, 0, 0), size=(48, 40))
    frame = _tess(scene, near)
    held, written = frame._source, frame.stats["pixels_written"]
    del frame
    gc.collect()
    again = _tess(scene, far)
    assert again._source is held and again.stats["pixels_written"] < written
    fresh = _tess(scene, far)   # `again` holds the reused set: this one draws into another
    assert fresh._source is not held
    np.testing.assert_array_equal(again.rgb8(), fresh.rgb8())
    for name in ("color", "depth", "normal", "object_id"):
        np.testing.assert_array_equal(getattr(again, name), getattr(fresh, name), err_msg=name)
    bare = ~np.isfinite(again.depth)
    assert bare.sum() > 1000 and again.stats["pixels_written"] == (~bare).sum()
    assert not again.color[bare].any() and not again.normal[bare].any() and not again.object_id[bare].any()
    assert np.all(again.rgb8()[bare] == linear_to_srgb8(np.float32(scene.background)))


def test_targets_drawn_directly_take_their_background_when_begun():
    """Direct targets clear their image to the background at ``begin``: a frame with nothing drawn
    is that background with +inf depth, and a resolve asked for another background is refused
    rather than returning the wrong image."""
    ctx = gl_context()
    tg = gl_targets.targets_for(None, ctx, (24, 16), 1, 1, "test")
    prog = build_programs(ctx, [], "fractional_odd", grid=True)
    try:
        assert tg.direct
        tg.begin(prog, (0.2, 0.3, 0.4))
        with pytest.raises(ValueError, match="background"):
            tg.resolve((0.0, 0.0, 0.0))
        tg.begin(prog, (0.2, 0.3, 0.4))
        tg.resolve((0.2, 0.3, 0.4))
        frame = tg.frame()
        assert tg.pixels_written == 0
        assert np.all(frame.rgb8() == linear_to_srgb8(np.float32([0.2, 0.3, 0.4])))
        assert np.all(np.isinf(frame.depth)) and not frame.color.any() and not frame.object_id.any()
    finally:
        tg.release()
