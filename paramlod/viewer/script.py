"""The viewer's scripted mode (``paramlod view ... --script FILE [--record DIR] [--frames N]``):
camera keyframes and key / mouse events in a TOML file, played frame by frame at a fixed time
step, so that a run is repeatable (tests, videos). Format (docs/viewer.md):

    fps = 30                 # frames per second of scene time and of the video (default 30)
    frames = 90              # optional; default: one past the last keyframe or event

    [[camera]]               # keyframes: eye and target linearly interpolated between them
    frame = 0
    eye = [0, 0, 4]
    target = [0, 0, 0]

    [[event]]                # what a user would do, through the same handlers as the window's
    frame = 10
    key = "W"                # a key of docs/viewer.md, by its name
    action = "press"         # press | release | tap (press, and release on the next frame)

    [[event]]
    frame = 20
    drag = [40, 0]           # mouse moved (dx, dy) pixels with a button held
    # or: scroll = 1         # wheel steps

Between keyframes the script's camera wins over the keys; outside them the keys move it. Recorded
frames are ``DIR/frame_00000.png`` ..., each written atomically (paramlod.core.files)."""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paramlod.app.args import check_folder
from paramlod.core.files import write_atomically
from paramlod.errors import ParamlodError
from paramlod.viewer.controls import KEYS

TOP_KEYS = {"fps", "frames", "camera", "event"}
CAMERA_KEYS = {"frame", "eye", "target"}
EVENT_KEYS = {"frame", "key", "action", "drag", "scroll"}
ACTIONS = ("press", "release", "tap")
MAX_FRAMES = 100_000


@dataclass
class Event:
    frame: int
    kind: str            # "key", "drag", "scroll"
    key: str = ""
    pressed: bool = True
    value: tuple = ()


@dataclass
class Script:
    fps: float = 30.0
    frames: int = 1
    keyframes: list = field(default_factory=list)   # (frame, eye, target), sorted by frame
    events: list = field(default_factory=list)      # Event, sorted by frame
    path: Path | None = None

    def events_at(self, frame: int) -> list[Event]:
        return [e for e in self.events if e.frame == frame]

    def camera_at(self, frame: int):
        """(eye, target) of the keyframes at ``frame``, or None outside them."""
        ks = self.keyframes
        if not ks or frame < ks[0][0] or frame > ks[-1][0]:
            return None
        for (f0, e0, t0), (f1, e1, t1) in zip(ks, ks[1:]):
            if f0 <= frame <= f1:
                a = (frame - f0) / (f1 - f0)
                return e0 + (e1 - e0) * a, t0 + (t1 - t0) * a
        return ks[0][1], ks[0][2]


def _fail(path, where: str, msg: str):
    raise ParamlodError(f"script {path}: {where}: {msg}")


def _vec3(path, where, v):
    if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                        and math.isfinite(x) for x in v)):
        _fail(path, where, f"must be a list of 3 numbers, got {v!r}")
    return np.array(v, np.float64)


def _frame(path, where, d):
    f = d.get("frame")
    if not isinstance(f, int) or isinstance(f, bool) or not 0 <= f < MAX_FRAMES:
        _fail(path, f"{where}.frame", f"must be an integer in 0..{MAX_FRAMES - 1}, got {f!r}")
    return f


def load_script(path) -> Script:
    """Read and check a script file; ParamlodError naming the file and the field otherwise."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ParamlodError(f"--script {path}: the file does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ParamlodError(f"--script {path}: cannot read it: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ParamlodError(f"script {path}: not valid TOML: {exc}") from None
    extra = sorted(set(data) - TOP_KEYS)
    if extra:
        _fail(path, extra[0], f"unknown field (allowed: {', '.join(sorted(TOP_KEYS))})")
    fps = data.get("fps", 30)
    if not isinstance(fps, (int, float)) or isinstance(fps, bool) or not 0 < fps <= 1000:
        _fail(path, "fps", f"must be a number in (0, 1000], got {fps!r}")
    s = Script(fps=float(fps), path=path)
    for k, d in enumerate(_tables(path, data, "camera")):
        where = f"camera[{k}]"
        extra = sorted(set(d) - CAMERA_KEYS)
        if extra:
            _fail(path, f"{where}.{extra[0]}", f"unknown field (allowed: {', '.join(sorted(CAMERA_KEYS))})")
        for key in ("eye", "target"):
            if key not in d:
                _fail(path, f"{where}.{key}", "is required")
        eye, target = _vec3(path, f"{where}.eye", d["eye"]), _vec3(path, f"{where}.target", d["target"])
        if not np.linalg.norm(target - eye):
            _fail(path, where, "eye and target are the same point")
        s.keyframes.append((_frame(path, where, d), eye, target))
    s.keyframes.sort(key=lambda k: k[0])
    frames = [k[0] for k in s.keyframes]
    if len(set(frames)) != len(frames):
        _fail(path, "camera", "two keyframes share a frame")
    for k, d in enumerate(_tables(path, data, "event")):
        where = f"event[{k}]"
        extra = sorted(set(d) - EVENT_KEYS)
        if extra:
            _fail(path, f"{where}.{extra[0]}", f"unknown field (allowed: {', '.join(sorted(EVENT_KEYS))})")
        f = _frame(path, where, d)
        kinds = [x for x in ("key", "drag", "scroll") if x in d]
        if len(kinds) != 1:
            _fail(path, where, "needs exactly one of key, drag or scroll")
        if kinds[0] == "key":
            key = d["key"]
            if not isinstance(key, str) or key.upper() not in KEYS:
                _fail(path, f"{where}.key", f"unknown key {key!r} (keys: {', '.join(sorted(KEYS))})")
            action = d.get("action", "tap")
            if action not in ACTIONS:
                _fail(path, f"{where}.action", f"must be one of {', '.join(ACTIONS)}, got {action!r}")
            if action in ("press", "tap"):
                s.events.append(Event(f, "key", key.upper(), True))
            if action in ("release", "tap"):
                s.events.append(Event(f + (action == "tap"), "key", key.upper(), False))
        elif "action" in d:
            _fail(path, f"{where}.action", "is for key events")
        elif kinds[0] == "drag":
            v = d["drag"]
            if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                               and math.isfinite(x) for x in v)):
                _fail(path, f"{where}.drag", f"must be [dx, dy] in pixels, got {v!r}")
            s.events.append(Event(f, "drag", value=(float(v[0]), float(v[1]))))
        else:
            v = d["scroll"]
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                _fail(path, f"{where}.scroll", f"must be a number of wheel steps, got {v!r}")
            s.events.append(Event(f, "scroll", value=(float(v),)))
    s.events.sort(key=lambda e: e.frame)   # stable: a tap's press comes before its release
    last = max([k[0] for k in s.keyframes] + [e.frame for e in s.events] + [0])
    n = data.get("frames", last + 1)
    if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= MAX_FRAMES:
        _fail(path, "frames", f"must be an integer in 1..{MAX_FRAMES}, got {n!r}")
    s.frames = n
    return s


def _tables(path, data, name) -> list:
    t = data.get(name, [])
    if not isinstance(t, list) or not all(isinstance(d, dict) for d in t):
        _fail(path, name, f"must be tables [[{name}]]")
    return t


class Recorder:
    """Numbered PNGs in a folder, each written atomically; the folder is checked before the first
    frame is drawn, and existing frames are not overwritten unless ``overwrite``."""

    def __init__(self, folder, overwrite: bool = False):
        self.folder = check_folder(Path(folder), "--record", create=True)
        self.paths: list[Path] = []
        if not overwrite and any(self.folder.glob("frame_*.png")):
            raise ParamlodError(f"--record {folder}: the folder already holds frame_*.png files; empty it or "
                                "pass --overwrite")

    def write(self, rgb8: np.ndarray) -> Path:
        from PIL import Image

        path = self.folder / f"frame_{len(self.paths):05d}.png"
        img = Image.fromarray(np.ascontiguousarray(rgb8), "RGB")
        write_atomically(path, lambda tmp: img.save(tmp, format="PNG"))
        self.paths.append(path)
        return path
