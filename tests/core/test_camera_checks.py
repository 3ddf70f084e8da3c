"""Cameras, transforms and parameters are checked when made: non-finite or float32-unplaceable
numbers and fractional sizes are refused with a message naming the field; a frame that draws
nothing says why (stats["nothing_drawn"] and a warning)."""
import numpy as np
import pytest

import paramlod as pl
from paramlod.core.transforms import PLACE_LIMIT
from paramlod.scene.framing import framing_camera

BAD_NUMBERS = [np.nan, np.inf, -np.inf, 10 * PLACE_LIMIT]
EYE, TARGET = (0.0, 0.5, 3.0), (0.0, 0.0, 0.0)
SIZE = (48, 36)


def with_bad(vec, k, bad):
    v = list(vec)
    v[k] = bad
    return tuple(v)


@pytest.mark.parametrize("bad", BAD_NUMBERS)
@pytest.mark.parametrize("field", ["eye", "target", "up"])
@pytest.mark.parametrize("k", [0, 2])
def test_look_at_refuses_every_bad_vector_component(field, k, bad):
    args = {"eye": EYE, "target": TARGET, "up": (0.0, 1.0, 0.0)}
    args[field] = with_bad(args[field], k, bad)
    with pytest.raises(pl.SceneError, match=f"camera: {field} "):
        pl.Camera.look_at(size=SIZE, **args)


@pytest.mark.parametrize("field,value", [("fov_y", np.nan), ("fov_y", np.inf), ("fov_y", 0.0), ("fov_y", 180.0),
                                         ("near", np.nan), ("near", 0.0), ("far", np.inf), ("far", np.nan),
                                         ("far", 10 * PLACE_LIMIT), ("near", 2000.0)])
def test_look_at_refuses_bad_lens(field, value):
    with pytest.raises(pl.SceneError, match=f"camera: .*{field}"):
        pl.Camera.look_at(EYE, TARGET, size=SIZE, **{field: value})


@pytest.mark.parametrize("size", [(10.5, 10), (10, 9.999), (0, 10), (10, -1), (16385, 10), (True, 10),
                                  ("10", 10), (np.nan, 10), (10,), 10])
def test_look_at_refuses_sizes_that_are_not_whole_pixels(size):
    with pytest.raises(pl.SceneError, match="camera: size"):
        pl.Camera.look_at(EYE, TARGET, size=size)


def test_whole_pixel_sizes_of_any_number_type_are_taken():
    for size in [(48, 36), (48.0, 36.0), (np.int64(48), np.uint16(36))]:
        cam = pl.Camera.look_at(EYE, TARGET, size=size)
        assert cam.size == (48, 36) and all(type(x) is int for x in cam.size)


def _view(k, value):
    v = np.eye(4)
    v.flat[k] = value
    return v


@pytest.mark.parametrize("view", [np.full((4, 4), np.nan), _view(0, np.inf), np.eye(3), _view(3, 1e20), "eye"])
def test_the_constructor_checks_as_look_at_does(view):
    with pytest.raises(pl.SceneError, match="camera: view"):
        pl.Camera(view, 45.0, SIZE)


def test_with_size_is_checked_too():
    cam = pl.Camera.look_at(EYE, TARGET, size=SIZE)
    with pytest.raises(pl.SceneError, match="camera: size"):
        cam.with_size((10.5, 10))
    assert cam.with_size((96, 72)).size == (96, 72)


@pytest.mark.parametrize("make,what", [
    (lambda b: pl.translate(0, 0, b), "translate"),
    (lambda b: pl.translate([b, 0, 0]), "translate"),
    (lambda b: pl.scale(b), "scale"),
    (lambda b: pl.scale(1, b, 1), "scale"),
    (lambda b: pl.rotate(b, (0, 0, 1)), "rotate angle"),
    (lambda b: pl.rotate(30, (0, b, 1)), "rotate axis"),
    (lambda b: pl.matrix(np.diag([1, 1, b, 1.0])), "a transform"),
])
@pytest.mark.parametrize("bad", BAD_NUMBERS)
def test_transform_helpers_refuse_bad_numbers(make, what, bad):
    with pytest.raises(pl.SceneError, match=what):
        make(bad)


def test_scene_names_the_object_and_field_of_a_bad_transform():
    s = pl.Scene()
    far = np.eye(4)
    far[2, 3] = 1e20
    with pytest.raises(pl.SceneError, match="'sphere': transform has a value of magnitude 1e\\+20"):
        s.add("sphere", transform=far)
    with pytest.raises(pl.SceneError, match="'sphere': transform must be invertible"):
        s.add("sphere", transform=np.diag([1e-30, 1e-30, 1e-30, 1.0]))
    many = np.tile(np.eye(4), (3, 1, 1))
    many[1, 0, 3] = np.nan
    with pytest.raises(pl.SceneError, match=r"'sphere': transforms \[1\] must be finite, got \[ *1\. +0\. +0\. +nan"):
        s.add_instances("sphere", 3, transforms=many)   # the bad matrix named and shown alone
    # each within the limit, together beyond it
    many = np.tile(pl.translate(0, 0, 0.9 * PLACE_LIMIT), (3, 1, 1))
    with pytest.raises(pl.SceneError, match="'sphere': transform @ transforms"):
        s.add_instances("sphere", 3, transforms=many, transform=pl.translate(0, 0, 0.9 * PLACE_LIMIT))
    with pytest.raises(pl.SceneError, match="add_surfels: transform must be finite"):
        s.add_surfels("unused.surfels", transform=np.full((4, 4), np.nan))
    # the renderers apply the top three rows: a projective bottom row was silently ignored
    projective = np.eye(4)
    projective[3] = (0, 0, 1, 0)
    with pytest.raises(pl.SceneError, match=r"'sphere': transform must be affine: its bottom row must be "
                                            r"\[0, 0, 0, 1\], got \[0., 0., 1., 0.\]"):
        s.add("sphere", transform=projective)
    many = np.tile(np.eye(4), (3, 1, 1))
    many[2, 3, 3] = 2.0
    with pytest.raises(pl.SceneError, match=r"'sphere': transforms \[2\] must be affine"):
        s.add_instances("sphere", 3, transforms=many)
    assert s.object_count == 0
    s.add("sphere", transform=pl.rotate(30, (1, 1, 0)) @ pl.translate(1, 2, 3) @ pl.scale(0.3))   # products stay affine


@pytest.mark.parametrize("part, placed, error", [
    (pl.translate(0.9 * PLACE_LIMIT, 0, 0), pl.translate(0.9 * PLACE_LIMIT, 0, 0), r"\[1\] has a value of magnitude 1\.8e\+15"),
    (pl.scale(1e-10), pl.scale(1e-10), r"\[1\] must be invertible with a scale above 1e-15"),
])
def test_parts_placed_on_parts_beyond_the_limits_are_refused(part, placed, error):
    # each transform is within the limits, the part's composed with its parent's is not: the
    # frame's instance buffers name the function and the instance
    @pl.parametric(parts=[pl.Part("sphere", at=(0.5, 0.5), transform=part)])
    def stand(u, v):
        return u, v, 0

    s = pl.Scene()
    s.add_instances(stand, 2, transforms=np.stack([np.eye(4), placed]))
    with pytest.raises(pl.SceneError, match=r"'sphere': the instances' transforms \(parts' and instances' "
                                            r"multiplied\) " + error):
        s.instance_buffers()


def test_parameters_beyond_float32_are_refused():
    s = pl.Scene()
    with pytest.raises(pl.FunctionError, match="parameter 'radius' is beyond float32"):
        s.add("sphere", params={"radius": 1e39})
    with pytest.raises(pl.FunctionError, match="parameter 'radius'"):
        s.add("sphere", params={"radius": np.nan})


def test_framing_camera_names_a_box_float32_cannot_place():
    import sympy as sp

    @pl.parametric(u=(0, 1), v=(0, 1), name="huge_sheet_h19")
    def huge(u, v):
        return u * 1e30, v, sp.Integer(0)

    s = pl.Scene()
    s.add(huge)
    with pytest.raises(pl.SceneError, match="framing camera: the scene's bounding box reaches 1e\\+30"):
        framing_camera(s, size=SIZE)


@pytest.mark.parametrize("variant", ["points", "tess"])
def test_a_frame_that_draws_nothing_says_why(variant):
    cam = pl.Camera.look_at(EYE, TARGET, size=SIZE)
    seen = pl.Scene()
    seen.add("sphere")
    f = pl.render(seen, cam, variant=variant)
    assert f.stats["pixels_written"] > 0 and f.stats["nothing_drawn"] is None
    assert not any("nothing drawn" in w for w in f.stats["warnings"])

    behind = pl.Scene()
    behind.add("sphere", transform=pl.translate(0, 0, 50))   # behind the camera
    f = pl.render(behind, cam, variant=variant)
    assert f.stats["pixels_written"] == 0
    assert "culled every patch" in f.stats["nothing_drawn"]
    assert f.stats["nothing_drawn"] in f.stats["warnings"]

    # a function that is NaN everywhere (its patches culled too) is named, not taken for out of view
    import sympy as sp

    @pl.parametric(u=(0, 1), v=(0, 1), name=f"sqrt_negative_{variant}")
    def undefined(u, v):
        return sp.sqrt(-1 - u), v, u

    nan = pl.Scene()
    nan.add(undefined)
    f = pl.render(nan, pl.Camera.look_at((0.5, 0.5, 3), (0.5, 0.5, 0), size=SIZE), variant=variant)
    assert f.stats["pixels_written"] == 0
    assert f.stats["nothing_drawn"].startswith(f"nothing drawn: 'sqrt_negative_{variant}' evaluates to NaN")

    # framed from 1e10 away the sphere is in view in float64, and a float32 blur on the device
    far = pl.Scene()
    far.add("sphere", transform=pl.translate(0, 0, 1e10))
    f = pl.render(far, framing_camera(far, size=SIZE), variant=variant)
    assert f.stats["pixels_written"] == 0
    assert "float32" in f.stats["nothing_drawn"] and f.stats["nothing_drawn"] in f.stats["warnings"]


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e39])
def test_per_instance_parameters_beyond_float32_are_refused(bad):
    s = pl.Scene()
    radius = np.ones(3)
    radius[1] = bad
    with pytest.raises(pl.SceneError, match="'sphere': per-instance 'radius' has non-finite values"):
        s.add_instances("sphere", 3, per_instance={"radius": radius})
