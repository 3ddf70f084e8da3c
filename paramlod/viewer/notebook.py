"""``pl.show(scene)`` in Jupyter: a jupyter_rfb RemoteFrameBuffer widget drawing the frame pipeline,
with the viewer's camera controls (paramlod.viewer.controls) driven by the widget's event dicts
(drag: look / orbit, wheel: speed / zoom, W/A/S/D/Q/E held: fly, Tab: fly <-> orbit, F: frame
the scene, R: reset). Without a widget frontend (no kernel, no ipywidgets or jupyter_rfb) ``show``
gives a static image (IPython.display.Image) of the same frame instead."""
from __future__ import annotations

import io
import time

import numpy as np

from paramlod.core.camera import Camera
from paramlod.errors import ParamlodError
from paramlod.pipeline.driver import render
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.framing import framing_camera, scene_box
from paramlod.scene.scene import Scene
from paramlod.viewer.controls import ACTION_KEYS, Controls

# browser key names (KeyboardEvent.key, as jupyter_rfb passes them) -> the viewer's key names
BROWSER_KEYS = {"[": "LEFT_BRACKET", "]": "RIGHT_BRACKET", ",": "COMMA", ".": "PERIOD", " ": "SPACE",
                "Tab": "TAB", "Escape": "ESCAPE"}
WIDGET_ACTIONS = {"mode", "frame", "reset"}     # the camera keys; the rest are the window's
WHEEL_PIXELS = 100.0                            # browsers report about 100 per wheel step


def key_name(key: str) -> str:
    return BROWSER_KEYS.get(key, key.upper() if len(key) == 1 else key.upper())


class FrameDriver:
    """The widget's state without the widget: controls, size, the last frame; ``handle_event``
    takes jupyter_rfb's event dicts and ``frame()`` draws. Tested without a frontend."""

    def __init__(self, scene: Scene, camera: Camera | None = None, size=(640, 480), variant=None, settings=None):
        if not isinstance(scene, Scene):
            raise ParamlodError(f"show needs a paramlod.Scene, got {type(scene).__name__}")
        camera = camera or framing_camera(scene, size=tuple(size))
        lo, hi = scene_box(scene)
        self.scene, self.variant = scene, variant
        self.settings = settings or RenderSettings()
        self.controls = Controls.for_box(camera, lo, hi)
        self.size = tuple(camera.size)
        self.pointer = None
        self.last = time.perf_counter()
        self.stats = None

    def handle_event(self, event: dict) -> bool:
        """One jupyter_rfb event; True when the view changed (a redraw is due)."""
        kind = event.get("event_type")
        if kind == "resize":
            w, h = int(event.get("width", 0)), int(event.get("height", 0))
            if w > 0 and h > 0:
                self.size = (w, h)
                return True
        elif kind == "pointer_down":
            self.pointer = (float(event["x"]), float(event["y"]))
        elif kind == "pointer_up":
            self.pointer = None
        elif kind == "pointer_move" and self.pointer is not None and event.get("buttons"):
            x, y = float(event["x"]), float(event["y"])
            self.controls.mouse_look(x - self.pointer[0], y - self.pointer[1])
            self.pointer = (x, y)
            return True
        elif kind == "wheel":
            self.controls.wheel(-float(event.get("dy", 0.0)) / WHEEL_PIXELS)
            return True
        elif kind in ("key_down", "key_up"):
            name = key_name(str(event.get("key", "")))
            action = self.controls.key(name, kind == "key_down")
            self.controls.camera_action(action)
            self.last = time.perf_counter()
            return action in WIDGET_ACTIONS or name not in ACTION_KEYS
        return False

    def frame(self, dt: float | None = None) -> np.ndarray:
        """Advance held keys by ``dt`` (default: the time since the last frame) and draw; rgb8."""
        now = time.perf_counter()
        self.controls.step(min(now - self.last, 0.25) if dt is None else dt)
        self.last = now
        f = render(self.scene, self.controls.camera(self.size), self.variant, self.settings)
        self.stats = f.stats
        return f.rgb8()

    @property
    def moving(self) -> bool:
        return bool(self.controls.held)


def widget_class():
    """The RemoteFrameBuffer subclass (jupyter_rfb imported late: an optional dependency)."""
    try:
        from jupyter_rfb import RemoteFrameBuffer
    except ImportError:
        raise ParamlodError("pl.show's widget needs jupyter_rfb and ipywidgets: pip install paramlod[viewer]") from None

    class SceneWidget(RemoteFrameBuffer):
        """The scene in a notebook cell, redrawn on every camera event (and while a key is held)."""

        def __init__(self, driver: FrameDriver, **kw):
            super().__init__(**kw)
            self.driver = driver
            self.css_width, self.css_height = f"{driver.size[0]}px", f"{driver.size[1]}px"

        def handle_event(self, event):
            if self.driver.handle_event(event):
                self.request_draw()

        def get_frame(self):
            img = self.driver.frame()
            if self.driver.moving:   # keep flying while a key is held
                self.request_draw()
            return img

    return SceneWidget


def has_frontend() -> bool:
    """A Jupyter kernel that can show widgets (ipywidgets and jupyter_rfb importable)."""
    try:
        import ipywidgets  # noqa: F401
        import jupyter_rfb  # noqa: F401
        from IPython import get_ipython
    except ImportError:
        return False
    ip = get_ipython()
    return ip is not None and getattr(ip, "kernel", None) is not None


def show(scene: Scene, camera: Camera | None = None, size=(640, 480), variant=None, settings=None,
         widget: bool | None = None):
    """The scene in a notebook: an interactive widget (drag, wheel, W/A/S/D/Q/E, Tab, F, R), or
    with ``widget=False`` or no widget frontend, an IPython Image of one frame."""
    driver = FrameDriver(scene, camera, size, variant, settings)
    if widget is None:
        widget = has_frontend()
    if widget:
        return widget_class()(driver)
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(driver.frame(0.0), "RGB").save(buf, format="PNG")
    try:
        from IPython.display import Image as IPImage
    except ImportError:   # outside IPython: the PNG's bytes
        return buf.getvalue()
    return IPImage(data=buf.getvalue(), format="png")
