"""The OpenGL targets' resolve and the lazy Frames it lends (paramlod.renderers.gl_targets): the
8-bit image equals the host's encoding bit for bit, a Frame keeps its arrays however many frames
follow, and the output sets are reused once Frames are dropped."""
import gc

import numpy as np
import pytest

import paramlod as pl
from paramlod.core.color import linear_to_srgb8, linear_to_srgb8_thresholds
from paramlod.renderers import gl_targets


def _scene():
    s = pl.Scene(background=(0.3, 0.1, 0.05))
    s.add("torus", transform=pl.rotate(50, (1, 0, 0)), material=pl.Material(color=(0.9, 0.3, 0.1)))
    s.add("sphere", transform=pl.translate(0.4, 0, 0.3) @ pl.scale(0.5))
    return s


def _tess(scene, cam, aa="noAA"):
    rs = pl.RenderSettings()
    rs.tess.aa = aa
    return pl.render(scene, cam, "tess", rs)


def test_thresholds_give_the_host_encoder_bit_for_bit():
    """The resolve's encoder counts thresholds; on every float32 near a threshold, on random ones
    and out of range it gives linear_to_srgb8's code (all of [0, 1] was checked once, 20 s)."""
    thr = linear_to_srgb8_thresholds()
    assert thr.dtype == np.float32 and len(thr) == 255 and np.all(np.diff(thr) > 0)
    bits = thr.view(np.uint32).astype(np.int64)
    near = (bits[:, None] + np.arange(-64, 65)[None, :]).ravel()
    rng = np.random.default_rng(7)
    x = np.concatenate([near.astype(np.uint32).view(np.float32), rng.random(2_000_000, np.float32),
                        np.float32([0, 1, -1, 2, 1e-30, 0.0031308, np.inf, -np.inf])])
    np.testing.assert_array_equal(np.searchsorted(thr, x, side="right").astype(np.uint8), linear_to_srgb8(x))


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
