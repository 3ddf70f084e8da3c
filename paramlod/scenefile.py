"""TOML scene files: objects, camera and render settings, validated with messages that name the
field and its line. Format: docs/scene-format.md."""
from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .camera import Camera
from .errors import ParamlodError, SceneError
from .lod import LodSettings
from .points import PointSettings
from .render import VARIANTS, RenderSettings
from .scene import Material, Scene
from .transforms import matrix as as_matrix, rotate, scale, translate

TOP_KEYS = {"camera", "render", "objects"}
CAMERA_KEYS = {"eye", "target", "up", "fov_y", "size", "near", "far"}
RENDER_KEYS = {"variant", "background", "threshold", "max_steps", "initial_grid", "density", "max_patches"}
OBJECT_KEYS = {"function", "params", "color", "specular", "translate", "rotate", "scale", "matrix"}


@dataclass
class SceneFile:
    scene: Scene
    camera: Camera
    settings: RenderSettings
    variant: str
    path: Path


class _Locator:
    """Finds the line of a key in the TOML text, for error messages."""

    def __init__(self, text: str):
        self.lines = text.splitlines()

    def line(self, table: str, index: int | None, key: str | None) -> int | None:
        current, count = None, -1
        for i, raw in enumerate(self.lines, 1):
            s = raw.strip()
            m = re.match(r"^\[\[\s*([\w.]+)\s*\]\]", s) or re.match(r"^\[\s*([\w.]+)\s*\]", s)
            if m:
                current = m.group(1)
                if current == table and s.startswith("[["):
                    count += 1
                if key is None and current == table and (index is None or count == index):
                    return i
                continue
            if current == table and (index is None or count == index) and key is not None:
                if re.match(rf"^{re.escape(key)}\s*=", s):
                    return i
        return None


class _Checker:
    def __init__(self, path: Path, text: str):
        self.path, self.loc = path, _Locator(text)

    def fail(self, where: str, msg: str, table: str, index=None, key=None):
        line = self.loc.line(table, index, key) or self.loc.line(table, index, None)
        at = f"{self.path}:{line}" if line else str(self.path)
        raise SceneError(f"{at}: {where}: {msg}")

    def unknown(self, got: dict, allowed: set, where: str, table: str, index=None):
        extra = sorted(set(got) - allowed)
        if extra:
            self.fail(f"{where}.{extra[0]}", f"unknown field (allowed: {', '.join(sorted(allowed))})",
                      table, index, extra[0])

    def vec(self, d, key, n, where, table, index=None, default=None):
        if key not in d:
            if default is None:
                self.fail(f"{where}.{key}", "is required", table, index)
            return default
        v = d[key]
        ok = isinstance(v, list) and len(v) == n and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
        if not ok or not np.all(np.isfinite(v)):
            self.fail(f"{where}.{key}", f"must be a list of {n} numbers, got {v!r}", table, index, key)
        return [float(x) for x in v]

    def num(self, d, key, where, table, index=None, default=None, lo=None, hi=None, integer=False):
        if key not in d:
            return default
        v = d[key]
        kind = int if integer else (int, float)
        if not isinstance(v, kind) or isinstance(v, bool) or (lo is not None and v < lo) or (hi is not None and v > hi):
            rng = f" in [{lo}, {hi}]" if lo is not None else ""
            self.fail(f"{where}.{key}", f"must be {'an integer' if integer else 'a number'}{rng}, got {v!r}", table, index, key)
        return v


def load_scene(path) -> SceneFile:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(f"scene file {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"cannot read scene file {path}: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML: {exc}") from None
    ck = _Checker(path, text)
    ck.unknown(data, TOP_KEYS, "scene", "", None)

    cam_d = data.get("camera", {})
    if not isinstance(cam_d, dict):
        ck.fail("camera", "must be a table [camera]", "camera")
    ck.unknown(cam_d, CAMERA_KEYS, "camera", "camera")
    size = cam_d.get("size", [960, 540])
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(x, int) and 0 < x <= 16384 for x in size)):
        ck.fail("camera.size", f"must be [width, height] in pixels, got {size!r}", "camera", None, "size")
    try:
        camera = Camera.look_at(
            ck.vec(cam_d, "eye", 3, "camera", "camera", default=[0.0, 0.0, 5.0]),
            ck.vec(cam_d, "target", 3, "camera", "camera", default=[0.0, 0.0, 0.0]),
            ck.vec(cam_d, "up", 3, "camera", "camera", default=[0.0, 1.0, 0.0]),
            fov_y=ck.num(cam_d, "fov_y", "camera", "camera", default=45.0, lo=1, hi=179),
            size=size, near=ck.num(cam_d, "near", "camera", "camera", default=0.01, lo=1e-6),
            far=ck.num(cam_d, "far", "camera", "camera", default=1000.0, lo=1e-6))
    except SceneError as exc:
        ck.fail("camera", str(exc).removeprefix("camera: "), "camera")

    r = data.get("render", {})
    if not isinstance(r, dict):
        ck.fail("render", "must be a table [render]", "render")
    ck.unknown(r, RENDER_KEYS, "render", "render")
    variant = r.get("variant", "points")
    if variant not in VARIANTS:
        ck.fail("render.variant", f"unknown variant {variant!r} (available: {', '.join(VARIANTS)})", "render", None, "variant")
    th = r.get("threshold", 84.0)
    if isinstance(th, (int, float)) and not isinstance(th, bool):
        th = [th, th]
    if not (isinstance(th, list) and len(th) == 2 and all(isinstance(x, (int, float)) and x > 0 for x in th)):
        ck.fail("render.threshold", f"must be a positive number of pixels or [t_u, t_v], got {r.get('threshold')!r}", "render", None, "threshold")
    grid = r.get("initial_grid", [1, 1])
    if not (isinstance(grid, list) and len(grid) == 2 and all(isinstance(x, int) and 1 <= x <= 64 for x in grid)):
        ck.fail("render.initial_grid", f"must be [gu, gv] with integers in 1..64, got {grid!r}", "render", None, "initial_grid")
    settings = RenderSettings(
        lod=LodSettings(threshold=(float(th[0]), float(th[1])),
                        max_steps=ck.num(r, "max_steps", "render", "render", default=12, lo=1, hi=15, integer=True),
                        initial_grid=tuple(grid),
                        max_patches=ck.num(r, "max_patches", "render", "render", default=1 << 24, lo=1, integer=True)),
        points=PointSettings(density=ck.num(r, "density", "render", "render", default=PointSettings.density, lo=0.1, hi=16)))
    background = ck.vec(r, "background", 3, "render", "render", default=[0.12, 0.12, 0.14])

    scene = Scene(background=background)
    objects = data.get("objects", [])
    if not isinstance(objects, list) or not objects:
        ck.fail("objects", "the scene needs at least one [[objects]] table", "objects")
    for i, o in enumerate(objects):
        where = f"objects[{i}]"
        ck.unknown(o, OBJECT_KEYS, where, "objects", i)
        if "function" not in o or not isinstance(o["function"], str):
            ck.fail(f"{where}.function", "is required (a function name, see `paramlod functions`)", "objects", i)
        params = o.get("params", {})
        if not isinstance(params, dict):
            ck.fail(f"{where}.params", "must be a table of name = value", "objects", i, "params")
        try:
            m = _transform(o, ck, where, i)
            mat = Material(color=tuple(ck.vec(o, "color", 3, where, "objects", i, default=[0.8, 0.8, 0.8])),
                           specular=ck.num(o, "specular", where, "objects", i, default=0.25, lo=0, hi=1))
            scene.add(o["function"], params=params, transform=m, material=mat)
        except SceneError as exc:
            if str(exc).startswith(str(path)):
                raise
            ck.fail(where, str(exc), "objects", i)
        except ParamlodError as exc:
            key = "params" if "parameter" in str(exc) else "function"
            ck.fail(f"{where}.{key}", str(exc), "objects", i, key)
    return SceneFile(scene, camera, settings, variant, path)


def _transform(o, ck: _Checker, where, i) -> np.ndarray:
    if "matrix" in o:
        if any(k in o for k in ("translate", "rotate", "scale")):
            ck.fail(f"{where}.matrix", "give either matrix or translate/rotate/scale, not both", "objects", i, "matrix")
        try:
            return as_matrix(o["matrix"])
        except (SceneError, ValueError, TypeError) as exc:
            ck.fail(f"{where}.matrix", str(exc), "objects", i, "matrix")
    m = np.eye(4)
    if "translate" in o:
        m = m @ translate(ck.vec(o, "translate", 3, where, "objects", i))
    if "rotate" in o:
        rot = o["rotate"]
        ok = (isinstance(rot, list) and len(rot) == 2 and isinstance(rot[0], (int, float))
              and isinstance(rot[1], list) and len(rot[1]) == 3)
        if not ok:
            ck.fail(f"{where}.rotate", f"must be [angle_degrees, [x, y, z]], got {rot!r}", "objects", i, "rotate")
        m = m @ rotate(rot[0], rot[1])
    if "scale" in o:
        s = o["scale"]
        if isinstance(s, (int, float)) and not isinstance(s, bool) and s > 0:
            m = m @ scale(s)
        else:
            m = m @ scale(*ck.vec(o, "scale", 3, where, "objects", i))
    return m
