"""The viewer's cameras and key map, pure (numpy only) so that they are unit-tested without a window.

``FlyCamera``: W/A/S/D along the view and its right, Q/E down/up along the scene's up axis, mouse
look (yaw about up, pitch about right, kept off the poles), the wheel changes the speed.
``OrbitCamera``: drag turns the eye round a target, the wheel zooms. Both start from a
``paramlod.Camera`` and give one back for any image size; speeds are in scene radii per second,
so a glyph field of 140 units and a unit sphere fly alike.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from paramlod.core.camera import Camera
from paramlod.errors import ParamlodError

# key name (moderngl-window's names, e.g. window.keys.W) -> action. Movement keys are held; the
# others act once per press.
MOVE_KEYS = {"W": "forward", "S": "back", "A": "left", "D": "right", "Q": "down", "E": "up"}
ACTION_KEYS = {
    "TAB": "mode",             # fly <-> orbit
    "F": "frame",              # frame the scene
    "R": "reset",              # back to the start camera
    "V": "variant",            # next render variant
    "B": "aa",                 # next anti-aliasing mode
    "LEFT_BRACKET": "coarser",   # LOD threshold x 1.25 (fewer patches / clusters)
    "RIGHT_BRACKET": "finer",    # LOD threshold / 1.25
    "C": "debug",              # debug colouring: off / per object / per cluster / per LOD level
    "SPACE": "pause",          # pause / run the animation time
    "COMMA": "time_back",      # scrub the animation time
    "PERIOD": "time_forward",
    "P": "screenshot",         # PNG + EXR (all outputs)
    "N": "next_function",      # the next function of a plugin file
    "H": "hud",                # heads-up display on / off
    "ESCAPE": "quit",
}
KEYS = {**MOVE_KEYS, **ACTION_KEYS}
LOOK_RADIANS_PER_PIXEL = 0.004
WHEEL_FACTOR = 1.25          # speed (fly) or distance (orbit) per wheel step
FLY_RADII_PER_SECOND = 0.5   # fly speed at the start, in scene radii per second
MAX_PITCH = math.radians(89.0)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    n = float(np.linalg.norm(v))
    if not n or not math.isfinite(n):
        raise ParamlodError(f"viewer: cannot normalise the vector {v.tolist()}")
    return v / n


def _rotate(v, axis, angle: float) -> np.ndarray:
    """``v`` turned by ``angle`` radians about the unit ``axis`` (Rodrigues)."""
    c, s = math.cos(angle), math.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * float(axis @ v) * (1 - c)


def _pitch(forward, up) -> float:
    return math.asin(max(-1.0, min(1.0, float(forward @ up))))


def _look(forward, up, dyaw: float, dpitch: float) -> np.ndarray:
    """``forward`` turned by ``dyaw`` about ``up`` and ``dpitch`` about its right, the pitch kept
    within +-89 degrees so that the view never lines up with ``up`` (look_at refuses that)."""
    f = _rotate(forward, up, -dyaw)
    p0 = _pitch(f, up)
    p1 = max(-MAX_PITCH, min(MAX_PITCH, p0 + dpitch))
    right = _unit(np.cross(f, up))
    return _unit(_rotate(f, right, p1 - p0))


@dataclass
class FlyCamera:
    eye: np.ndarray
    forward: np.ndarray
    up: np.ndarray
    speed: float                      # scene units per second

    def move(self, held: set, dt: float) -> bool:
        """Move for ``dt`` seconds with the movement actions in ``held``; True when it moved."""
        right = _unit(np.cross(self.forward, self.up))
        d = np.zeros(3)
        for action, vec in (("forward", self.forward), ("back", -self.forward), ("right", right),
                            ("left", -right), ("up", self.up), ("down", -self.up)):
            if action in held:
                d += vec
        if not d.any() or dt <= 0:
            return False
        self.eye = self.eye + _unit(d) * self.speed * dt
        return True

    def look(self, dx: float, dy: float) -> None:
        """Mouse look by (dx, dy) pixels (y down, as the window reports it)."""
        self.forward = _look(self.forward, self.up, dx * LOOK_RADIANS_PER_PIXEL, -dy * LOOK_RADIANS_PER_PIXEL)

    def wheel(self, steps: float) -> None:
        self.speed *= WHEEL_FACTOR ** steps

    def target(self) -> np.ndarray:
        return self.eye + self.forward


@dataclass
class OrbitCamera:
    centre: np.ndarray
    distance: float
    direction: np.ndarray             # unit vector from the centre to the eye
    up: np.ndarray

    def drag(self, dx: float, dy: float) -> None:
        # turning the eye round the centre is looking the other way from it
        self.direction = -_look(-self.direction, self.up, -dx * LOOK_RADIANS_PER_PIXEL, -dy * LOOK_RADIANS_PER_PIXEL)

    def wheel(self, steps: float) -> None:
        self.distance /= WHEEL_FACTOR ** steps

    @property
    def eye(self) -> np.ndarray:
        return self.centre + self.direction * self.distance


@dataclass
class Controls:
    """Both cameras, which one is live, the held movement keys and the scene's size; ``camera()``
    is what the frame is drawn with."""

    start: Camera
    centre: np.ndarray
    radius: float
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    mode: str = "fly"
    held: set = field(default_factory=set)

    def __post_init__(self):
        self.centre = np.asarray(self.centre, np.float64)
        self.radius = float(self.radius) if self.radius > 0 and math.isfinite(self.radius) else 1.0
        self.up = _unit(self.up)
        self.reset()

    @classmethod
    def for_box(cls, start: Camera, lo, hi, up=(0.0, 1.0, 0.0)) -> "Controls":
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        return cls(start, (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2, np.asarray(up, np.float64))

    def reset(self) -> None:
        """Back to the start camera (both cameras); speeds from the scene's size."""
        self.set_view(self.start.eye, -self.start.view[2, :3])
        self.fly.speed = FLY_RADII_PER_SECOND * self.radius

    def set_view(self, eye, forward) -> None:
        """Both cameras at ``eye`` looking along ``forward`` (the orbit round the point of the view
        nearest the scene's centre); the fly speed is kept."""
        eye, forward = np.asarray(eye, np.float64), _unit(forward)
        if abs(float(forward @ self.up)) > math.sin(MAX_PITCH):   # straight up or down: tip it off the pole
            side = np.cross(self.up, [1.0, 0.0, 0.0] if abs(self.up[0]) < 0.9 else [0.0, 0.0, 1.0])
            forward = _look(_unit(forward + 0.05 * _unit(side)), self.up, 0.0, 0.0)
        speed = getattr(getattr(self, "fly", None), "speed", FLY_RADII_PER_SECOND * self.radius)
        self.fly = FlyCamera(eye, forward, self.up, speed)
        along = max(float((self.centre - eye) @ forward), 1e-3 * self.radius)
        self.orbit = OrbitCamera(eye + forward * along, along, -forward, self.up)

    def frame_scene(self) -> None:
        """Look at the scene's centre from the current direction, from where its bounding sphere fills the view."""
        f = self.fly.forward if self.mode == "fly" else -self.orbit.direction
        half = math.radians(self.start.fov_y) / 2
        aspect = self.start.width / self.start.height
        fit = min(math.tan(half), math.tan(half) * aspect)
        dist = self.radius / math.sin(math.atan(fit)) * 1.05
        self.set_view(self.centre - f * dist, f)

    def toggle_mode(self) -> str:
        """Fly <-> orbit, the view kept where it is."""
        if self.mode == "fly":
            self.set_view(self.fly.eye, self.fly.forward)
            self.mode = "orbit"
        else:
            self.set_view(self.orbit.eye, -self.orbit.direction)
            self.mode = "fly"
        return self.mode

    # --- events ------------------------------------------------------------------------------
    def key(self, name: str, pressed: bool) -> str | None:
        """A key by its name; the held movement keys are kept; returns the one-shot action of a
        press (or None)."""
        move = MOVE_KEYS.get(name)
        if move:
            (self.held.add if pressed else self.held.discard)(move)
            return None
        return ACTION_KEYS.get(name) if pressed else None

    def camera_action(self, action: str | None) -> bool:
        """Carry out a camera action of ``key`` ("mode", "frame", "reset"); False for any other."""
        do = {"mode": self.toggle_mode, "frame": self.frame_scene, "reset": self.reset}.get(action)
        if do is not None:
            do()
        return do is not None

    def step(self, dt: float) -> bool:
        """Advance the held keys by ``dt`` seconds (fly mode; in orbit mode W/S zoom)."""
        if self.mode == "fly":
            return self.fly.move(self.held, dt)
        zoom = ("forward" in self.held) - ("back" in self.held)
        if zoom and dt > 0:
            self.orbit.distance *= math.exp(-zoom * dt)
            return True
        return False

    def mouse_look(self, dx: float, dy: float) -> None:
        """Mouse moved with a button held: look (fly) or turn round the target (orbit)."""
        if self.mode == "fly":
            self.fly.look(dx, dy)
        else:
            self.orbit.drag(dx, dy)

    def wheel(self, steps: float) -> None:
        (self.fly if self.mode == "fly" else self.orbit).wheel(steps)

    # --- the camera -----------------------------------------------------------------------------
    def eye_target(self) -> tuple[np.ndarray, np.ndarray]:
        if self.mode == "fly":
            return self.fly.eye, self.fly.target()
        return self.orbit.eye, self.orbit.centre

    def camera(self, size=None) -> Camera:
        """The live camera at ``size`` (default the start camera's): near and far from the
        distance to the scene, so that nothing is clipped while flying through it."""
        eye, target = self.eye_target()
        size = tuple(size or self.start.size)
        reach = float(np.linalg.norm(eye - self.centre)) + 2 * self.radius
        far = max(self.start.far, reach * 1.5)
        near = min(self.start.near, far * 1e-5)
        return Camera.look_at(eye, target, self.up, self.start.fov_y, size, near=near, far=far)
