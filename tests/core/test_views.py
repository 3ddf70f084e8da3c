"""Camera sets for multi-view frames (paramlod.views): their geometry and the assembled images."""
import numpy as np
import pytest

import paramlod as pl
from paramlod import views
from paramlod.core.frame import Frame
from paramlod.core.views import parse_grid


def ndc(cam, point):
    c = cam.projection @ cam.view @ np.append(point, 1.0)
    return c[:2] / c[3]


def test_lens_shift_moves_the_image_and_is_checked():
    cam = pl.Camera.look_at((0, 0, 5), (0, 0, 0), size=(64, 48), shift=(0.25, -0.5))
    np.testing.assert_allclose(ndc(cam, (0, 0, 0)), (0.25, -0.5), atol=1e-12)
    assert cam.with_size((32, 24)).shift == (0.25, -0.5)
    with pytest.raises(pl.SceneError, match="shift"):
        pl.Camera.look_at((0, 0, 5), (0, 0, 0), shift=(float("nan"), 0))
    with pytest.raises(pl.SceneError, match="shift"):
        pl.Camera.look_at((0, 0, 5), (0, 0, 0), shift=3)


def test_stereo_pair_is_ipd_apart_and_meets_at_the_focus():
    cam = pl.Camera.look_at((1, 2, 5), (0, 0, 0), size=(80, 60))
    left, right = views.stereo(cam, 0.3, focus=np.linalg.norm((1, 2, 5)))
    right_axis = cam.view[0, :3]
    np.testing.assert_allclose(right.eye - left.eye, 0.3 * right_axis, atol=1e-12)
    np.testing.assert_allclose(left.view[:3, :3], cam.view[:3, :3])      # both look the same way
    for eye in (left, right):
        np.testing.assert_allclose(ndc(eye, (0, 0, 0)), (0, 0), atol=1e-9)   # zero parallax at the focus
    far_point = cam.eye + 50 * (-cam.view[2, :3])
    assert ndc(left, far_point)[0] < ndc(right, far_point)[0] - 1e-3 or \
        ndc(left, far_point)[0] > ndc(right, far_point)[0] + 1e-3          # parallax behind the focus
    parallel = views.stereo(cam, 0.3)
    assert all(c.shift == (0.0, 0.0) for c in parallel)
    with pytest.raises(pl.SceneError, match="ipd"):
        views.stereo(cam, -1)


def test_quilt_spans_the_view_cone_left_to_right_with_a_fixed_focal_plane():
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(40, 30))
    q = views.quilt(cam, 4, 3, view_cone=30.0)
    assert len(q) == 12
    xs = [c.eye @ cam.view[0, :3] for c in q]
    assert np.all(np.diff(xs) > 0)                                         # view 0 leftmost
    for c in q:
        np.testing.assert_allclose(ndc(c, (0, 0, 0)), (0, 0), atol=1e-9)
    a0 = np.arctan2(xs[0], 4.0)
    a1 = np.arctan2(xs[-1], 4.0)
    assert np.degrees(a1 - a0) == pytest.approx(30.0)
    with pytest.raises(pl.SceneError, match="views"):
        views.quilt(cam, 10, 10)
    assert parse_grid("8x6") == (8, 6)
    with pytest.raises(pl.SceneError, match="COLSxROWS"):
        parse_grid("8by6")


def test_cube_faces_cover_every_direction_once():
    faces = views.cube_faces((1, 2, 3), size=16)
    assert [c.size for c in faces] == [(16, 16)] * 6
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(200, 3))
    for d in dirs:
        inside = []
        for c in faces:
            e = c.view[:3, :3] @ d
            if e[2] < 0:
                x, y = ndc(c, np.array((1, 2, 3)) + d)
                inside.append(abs(x) <= 1 + 1e-9 and abs(y) <= 1 + 1e-9)
            else:
                inside.append(False)
        assert sum(inside) >= 1


def flat_frame(rgb, size):
    w, h = size
    color = np.zeros((h, w, 4), np.float32)
    color[..., :3] = rgb
    color[..., 3] = 1
    return Frame(color=color, depth=np.ones((h, w), np.float32), normal=np.zeros((h, w, 3), np.float32),
                 object_id=np.ones((h, w), np.uint32))


def test_equirect_looks_up_each_face_where_its_direction_points():
    faces = views.cube_faces((0, 0, 0), size=8)
    colours = np.eye(3).tolist() + [[1, 1, 0], [0, 1, 1], [1, 0, 1]]   # +x red, -x green, +y blue ...
    frames = [flat_frame(c, (8, 8)) for c in colours]
    pano = views.equirect(frames, faces, height=32)
    assert pano.shape == (32, 64, 3)
    assert tuple(pano[0, 10]) == (0, 0, 255)                 # top row looks up (+y)
    assert tuple(pano[16, 32]) == (255, 0, 255)              # centre looks along -z
    assert tuple(pano[16, 48]) == (255, 0, 0)                # a quarter turn right: +x
    with pytest.raises(pl.SceneError, match="six"):
        views.equirect(frames[:5], faces)


def test_quilt_image_puts_view_zero_bottom_left():
    frames = [flat_frame((i / 5, 0, 0), (4, 3)) for i in range(6)]
    img = views.quilt_image(frames, 3, 2)
    assert img.shape == (6, 12, 3)
    assert img[5, 0, 0] == frames[0].rgb8()[0, 0, 0]          # bottom left
    assert img[0, 11, 0] == frames[5].rgb8()[0, 0, 0]         # top right
    assert img[0, 0, 0] == frames[3].rgb8()[0, 0, 0]


def test_views_are_checked():
    a = pl.Camera.look_at((0, 0, 5), (0, 0, 0), size=(64, 48))
    b = pl.Camera.look_at((0, 0, 5), (0, 0, 0), size=(32, 48))
    with pytest.raises(pl.SceneError, match="same size"):
        views.Views([a, b])
    with pytest.raises(pl.SceneError, match="at least one"):
        views.Views([])
    with pytest.raises(pl.SceneError, match="camera 1"):
        views.Views([a, "b"])
    with pytest.raises(pl.SceneError, match="more than 64"):
        views.Views([a] * 65)
    assert views.Views([a, a]).records().shape == (2 * 36,)
