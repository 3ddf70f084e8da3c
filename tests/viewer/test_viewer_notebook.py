"""``pl.show``: the jupyter_rfb widget's event handling and frames without a frontend, and the
static image it gives outside a kernel."""
import io

import numpy as np
import pytest
from PIL import Image

import paramlod as pl
from paramlod.viewer.notebook import FrameDriver, has_frontend, widget_class

SIZE = (64, 48)


@pytest.fixture
def scene():
    s = pl.Scene()
    s.add("torus")
    return s


def test_outside_a_kernel_show_gives_a_static_image(scene):
    assert not has_frontend()   # pytest runs no Jupyter kernel
    img = pl.show(scene, size=SIZE)
    from IPython.display import Image as IPImage

    assert isinstance(img, IPImage)
    got = np.asarray(Image.open(io.BytesIO(img.data)).convert("RGB"))
    cam = pl.scene.framing.framing_camera(scene, size=SIZE)
    assert np.array_equal(got, pl.render(scene, cam).rgb8())


def test_the_widget_follows_its_events(scene):
    d = FrameDriver(scene, size=SIZE)
    w = widget_class()(d)
    first = w.get_frame()
    assert first.shape == (48, 64, 3)
    eye = d.controls.camera().eye
    w.handle_event({"event_type": "pointer_down", "x": 10, "y": 10, "button": 1, "buttons": [1], "modifiers": []})
    w.handle_event({"event_type": "pointer_move", "x": 50, "y": 14, "buttons": [1], "modifiers": []})
    w.handle_event({"event_type": "pointer_up", "x": 50, "y": 14, "button": 1, "buttons": [], "modifiers": []})
    turned = w.get_frame()
    assert not np.array_equal(first, turned)
    assert np.allclose(d.controls.camera().eye, eye)   # fly mode: looking, not moving
    w.handle_event({"event_type": "pointer_move", "x": 90, "y": 14, "buttons": [], "modifiers": []})
    assert np.array_equal(w.get_frame(), turned)        # no button held: nothing happens
    # a held key flies for the time between frames; the widget keeps drawing while it is held
    assert d.handle_event({"event_type": "key_down", "key": "w", "modifiers": []})
    assert d.moving
    d.frame(dt=0.5)
    assert d.handle_event({"event_type": "key_up", "key": "w", "modifiers": []}) and not d.moving
    assert np.allclose(d.controls.camera().eye, eye + d.controls.fly.forward * d.controls.fly.speed * 0.5)
    # Tab: orbit; the wheel zooms; resize changes the frame size
    d.handle_event({"event_type": "key_down", "key": "Tab", "modifiers": []})
    assert d.controls.mode == "orbit"
    dist = d.controls.orbit.distance
    assert d.handle_event({"event_type": "wheel", "dx": 0, "dy": -100, "x": 5, "y": 5, "modifiers": []})
    assert d.controls.orbit.distance < dist
    assert d.handle_event({"event_type": "resize", "width": 40, "height": 30, "pixel_ratio": 1.0})
    assert w.get_frame().shape == (30, 40, 3)


def test_show_refuses_what_is_not_a_scene():
    with pytest.raises(pl.ParamlodError, match="show needs a paramlod.Scene"):
        pl.show("sphere")


def test_show_can_ask_for_the_widget(scene):
    w = pl.show(scene, size=SIZE, widget=True)
    assert w.get_frame().shape == (48, 64, 3)
    assert w.css_width == "64px"
