"""The viewer's cameras and key map (paramlod.viewer.controls), without a window."""
import math

import numpy as np
import pytest

import paramlod as pl
from paramlod.viewer.controls import FLY_RADII_PER_SECOND, KEYS, MAX_PITCH, WHEEL_FACTOR, Controls


def controls(eye=(0.0, 0.0, 5.0), radius=2.0):
    start = pl.Camera.look_at(eye, (0, 0, 0), size=(64, 48))
    return Controls.for_box(start, (-radius,) * 3, (radius,) * 3)


def test_start_view_is_the_start_camera():
    c = controls()
    cam = c.camera()
    assert np.allclose(cam.eye, [0, 0, 5])
    assert np.allclose(cam.view[:3, :3], c.start.view[:3, :3])
    assert cam.size == (64, 48)


def test_speed_scales_with_the_scene():
    small, big = controls(radius=1.0), controls(radius=100.0, eye=(0, 0, 500))
    assert big.fly.speed == pytest.approx(100 * small.fly.speed)
    assert small.fly.speed == pytest.approx(FLY_RADII_PER_SECOND * math.sqrt(3))   # the box's half diagonal


@pytest.mark.parametrize("key,direction", [("W", (0, 0, -1)), ("S", (0, 0, 1)), ("A", (-1, 0, 0)),
                                           ("D", (1, 0, 0)), ("E", (0, 1, 0)), ("Q", (0, -1, 0))])
def test_held_keys_fly_along_the_view(key, direction):
    c = controls()
    assert c.key(key, True) is None
    assert c.step(0.5)
    c.key(key, False)
    assert not c.step(0.5)   # released: no motion
    expect = np.array([0, 0, 5.0]) + np.array(direction) * c.fly.speed * 0.5
    assert np.allclose(c.fly.eye, expect)


def test_mouse_look_turns_and_stops_short_of_the_poles():
    c = controls()
    c.mouse_look(100, 0)   # right
    assert c.fly.forward[0] > 0.3
    for _ in range(100):
        c.mouse_look(0, -500)   # far up
    assert math.asin(c.fly.forward @ c.up) == pytest.approx(MAX_PITCH, abs=1e-6)
    c.camera()   # still a valid camera (not looking along up)


def test_wheel_changes_fly_speed_and_orbit_distance():
    c = controls()
    s0 = c.fly.speed
    c.wheel(2)
    assert c.fly.speed == pytest.approx(s0 * WHEEL_FACTOR ** 2)
    c.toggle_mode()
    d0 = c.orbit.distance
    c.wheel(1)
    assert c.orbit.distance == pytest.approx(d0 / WHEEL_FACTOR)


def test_orbit_drag_keeps_the_distance_and_the_target():
    c = controls()
    assert c.toggle_mode() == "orbit"
    before = c.camera()
    c.mouse_look(150, 40)
    cam = c.camera()
    assert np.linalg.norm(cam.eye - c.orbit.centre) == pytest.approx(5.0)
    assert not np.allclose(cam.eye, before.eye)
    assert np.allclose(-cam.view[2, :3], (c.orbit.centre - cam.eye) / 5.0)   # still looking at the centre


def test_mode_switch_keeps_the_view():
    c = controls()
    c.mouse_look(80, 20)
    c.key("W", True)
    c.step(0.3)
    c.key("W", False)
    before = c.camera()
    c.toggle_mode()
    after = c.camera()
    assert np.allclose(before.view, after.view, atol=1e-9)
    c.toggle_mode()
    assert np.allclose(c.camera().view, before.view, atol=1e-9)


def test_frame_and_reset():
    c = controls()
    c.key("S", True)
    c.step(10.0)   # fly far away
    c.key("S", False)
    c.frame_scene()
    cam = c.camera()
    d = np.linalg.norm(cam.eye)
    assert d < 10.0 and d > c.radius   # near the scene, outside its sphere
    assert np.allclose(-cam.view[2, :3], -cam.eye / d)   # looking at the centre
    c.reset()
    assert np.allclose(c.camera().view, c.start.view)


def test_one_shot_keys_act_on_press_only():
    c = controls()
    assert c.key("V", True) == "variant"
    assert c.key("V", False) is None
    assert c.key("UNKNOWN", True) is None
    assert {"W", "A", "S", "D", "Q", "E", "TAB", "F", "R", "LEFT_BRACKET", "RIGHT_BRACKET", "P"} <= set(KEYS)


def test_far_plane_follows_the_camera():
    c = controls()
    c.key("S", True)
    c.step(5000.0 / c.fly.speed)   # 5000 units back
    cam = c.camera()
    assert cam.far > np.linalg.norm(cam.eye) + c.radius
