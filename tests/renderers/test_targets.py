"""The key buffers' resolve (kernels/points/resolve.cl): its image and counters against the numpy
twin, and the lazy Frame it gives (paramlod.renderers.targets)."""
import numpy as np

import paramlod as pl
from paramlod.core.color import linear_to_srgb8
from paramlod.pipeline.driver import scene_state
from paramlod.renderers.points_reference import resolve_image


def _scene():
    s = pl.Scene(background=(0.3, 0.1, 0.05))
    s.add("torus", transform=pl.rotate(50, (1, 0, 0)), material=pl.Material(color=(0.9, 0.3, 0.1)))
    s.add("sphere", transform=pl.translate(0.4, 0, 0.3) @ pl.scale(0.5))
    return s


def test_device_image_equals_the_numpy_twin_and_the_host_encoding():
    scene = _scene()
    cam = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(80, 60))
    rs = pl.RenderSettings()
    rs.points.supersample = 2   # partly covered edge pixels blend with the background
    frame = pl.render(scene, cam, settings=rs)
    image = frame.rgb8()
    assert frame.on_device == ("color", "depth", "normal", "object_id")   # only the image was read
    keys, _ = scene_state(scene).keys(cam.size, 2).read_keys()
    bg = linear_to_srgb8(np.asarray(scene.background, np.float32))
    np.testing.assert_array_equal(image, resolve_image(keys, bg))
    host = frame.materialize()
    a = host.color[..., 3:4]
    encoded = linear_to_srgb8(host.color[..., :3] * a + np.asarray(scene.background, np.float32) * (1 - a))
    full = (a[..., 0] == 1) | (a[..., 0] == 0)
    assert (~full).sum() > 50 and full.sum() > 3000
    np.testing.assert_array_equal(image[full], encoded[full])
    assert np.abs(image.astype(int) - encoded).max() <= 1   # edges: one code at most
    assert frame.stats["pixels_written"] == int(np.isfinite(host.depth).sum())


def test_a_frame_keeps_its_arrays_when_the_buffers_are_reused():
    scene = _scene()
    near = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(64, 48))
    far = pl.Camera.look_at((0, 2, 6), (0, 0, 0), size=(64, 48))
    first = pl.render(scene, near)
    assert first.on_device                       # nothing read yet
    second = pl.render(scene, far)               # same key buffers, other output buffers
    assert first.on_device and second.on_device
    again = pl.render(scene, near).materialize()
    np.testing.assert_array_equal(first.depth, again.depth)
    np.testing.assert_array_equal(first.object_id, again.object_id)
    assert np.isfinite(second.depth).sum() < np.isfinite(first.depth).sum()


def test_output_buffers_are_reused_once_a_frame_is_dropped():
    scene = _scene()
    cam = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(64, 48))
    keys = None
    for _ in range(4):
        frame = pl.render(scene, cam)   # the previous frame is dropped when this one is bound
        keys = scene_state(scene).keys(cam.size)
    assert len(keys._free) == 1         # two sets in all: the live frame's and one free
    del frame
    assert len(keys._free) == 2
