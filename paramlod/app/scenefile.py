"""TOML scene files: objects, camera and render settings, validated with messages that name the
field and its line. Format: docs/scene-format.md. Driven by ``paramlod render`` and the gallery.
Scene files are data: the only code they name is an instance builder, and that must be one a loaded
function or plugin registered (paramlod.function.registry.register_builder), unless the user trusts
the scene (``--trust-scene`` or PARAMLOD_TRUST_SCENE=1), which lets it import any module:function."""
from __future__ import annotations

import importlib
import math
import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paramlod import dmri, meshlod  # noqa: F401  (meshlod registers the "mesh" loader and renderers)
from paramlod.app.args import MAX_SIDE
from paramlod.core.camera import Camera
from paramlod.core.transforms import matrix as as_matrix, rotate, scale, translate
from paramlod.errors import FunctionError, MeshError, ParamlodError, SceneError
from paramlod.function import registry
from paramlod.lod.stage import LodSettings
from paramlod.pipeline.settings import RenderSettings
from paramlod.renderers.registry import KINDS, variants
from paramlod.renderers.points import PointSettings
from paramlod.renderers.tess import TessSettings
from paramlod.meshlod.format import SUFFIX as MESHLOD_SUFFIX
from paramlod.scene.framing import framing_camera
from paramlod.scene.handoff import DEFAULT_BLEND
from paramlod.scene.meshes import MESH_TYPES
from paramlod.scene.scene import Material, Scene
from paramlod.surfels.render import FixedCount, FixedSize

TOP_KEYS = {"camera", "render", "objects", "meta", "animation", "camera_path"}   # camera_path: docs/scale-out.md
CAMERA_KEYS = {"eye", "target", "up", "fov_y", "size", "near", "far", "direction", "margin"}
RENDER_KEYS = {"variant", "background", "threshold", "max_steps", "initial_grid", "density", "max_patches", "patch_budget",
               "detail_angle", "spot_angle", "spot_share", "color_by", "coverage", "thin_tubes",
               "aa", "levels", "l_min", "l_max", "spacing", "msaa_lod", "chord_px", "tessellator", "inner_measure",
               "mesh_threshold", "mesh_color_by"}
OBJECT_KEYS = {"function", "params", "color", "specular", "two_sided", "translate", "rotate", "scale", "matrix", "variant",
               "instances", "sh_field", "surfels", "mesh", "lod", "skinned", "animation", "time"}
SOURCE_KEYS = ("function", "mesh", "surfels", "sh_field")   # what an object is made of: one of them (or skinned)
SKINNED_KEYS = ("animation", "time")   # only with skinned = "x.glb"
# fields of a function object that other sources take none of (skinned meshes: _check_skinned_keys)
NOT_FOR = {"surfels": {"params", "instances", "variant"}, "sh_field": {"params", "instances"}}
SH_FIELD_KEYS = {"scale", "normalize", "color_by", "subtract_min"}   # ShField.to_scene's, with path
MESH_LODS = ("dag", "full", "chain")
ANIMATION_KEYS = {"frames", "t0", "t1", "fps"}
META_KEYS = {"title", "caption", "needs", "prepare"}   # needs, prepare: paramlod.app.gallery
TRUST_ENV = "PARAMLOD_TRUST_SCENE"   # "1": scene files may import and run any module:function (a builder)


def trusted() -> bool:
    return os.environ.get(TRUST_ENV, "") == "1"


@dataclass
class SceneFile:
    scene: Scene
    camera: Camera
    settings: RenderSettings
    variant: str
    path: Path
    object_variants: list | None = None   # per object, when any object names its own variant
    meta: dict | None = None               # [meta]: title, caption (the gallery uses them)
    animation: dict | None = None          # [animation]: frames, t0, t1, fps


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
        if not isinstance(got, dict):
            self.fail(where, f"must be a table (fields {', '.join(sorted(allowed))}), got {got!r}", table, index)
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

    def flag(self, d, key, where, table, index=None, default=None):
        v = d.get(key, default)
        if not isinstance(v, bool):
            self.fail(f"{where}.{key}", f"must be true or false, got {v!r}", table, index, key)
        return v

    def num(self, d, key, where, table, index=None, default=None, lo=None, hi=None, integer=False):
        if key not in d:
            return default
        v = d[key]
        kind = int if integer else (int, float)
        if not isinstance(v, kind) or isinstance(v, bool) or not math.isfinite(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
            rng = f" in [{lo}, {hi}]" if lo is not None else ""
            self.fail(f"{where}.{key}", f"must be {'an integer' if integer else 'a number'}{rng}, got {v!r}", table, index, key)
        return v


FILE_OBJECT_NAMES = {"mesh": "mesh file", "surfels": "surfel file"}   # file_object_kind -> words


def file_object_kind(path) -> str | None:
    """"mesh" (a mesh file or a built .meshlod) or "surfels" (a .surfels file) for a file that
    is drawn alone where a scene file is expected; None for anything else (a scene file)."""
    suffix = Path(path).suffix.lower()
    if suffix in MESH_TYPES or suffix == MESHLOD_SUFFIX:
        return "mesh"
    return "surfels" if suffix == ".surfels" else None


def _file_object_scene(path: Path, kind: str, size) -> SceneFile:
    """A mesh or surfel file alone: its default material and LOD, framed, at ``size`` or 960x540;
    meshes drawn by meshlets."""
    if not path.is_file():
        what = FILE_OBJECT_NAMES[kind]
        raise SceneError(f"{what} {path} does not exist" if not path.exists() else f"{what} {path} is not a file")
    scene = Scene()
    if kind == "mesh":
        scene.add_mesh(str(path))
    else:
        scene.add_surfels(str(path))
    camera = framing_camera(scene, size=tuple(size) if size else (960, 540))
    return SceneFile(scene, camera, RenderSettings(), "meshlets" if kind == "mesh" else "points", path)


def load_scene(path, size=None) -> SceneFile:
    """Read and validate a scene file; ``size`` (w, h) overrides the camera's size (a framing
    camera is then framed for that size). A mesh file (OBJ, PLY, STL, OFF, glTF, GIfTI, .meshlod)
    or a .surfels file is a scene of that one object, framed."""
    path = Path(path)
    kind = file_object_kind(path)
    if kind is not None:
        return _file_object_scene(path, kind, size)
    hint = (f" (a scene file is TOML; a mesh ({', '.join(s[1:].upper() for s in MESH_TYPES)}, .meshlod) or "
            ".surfels file is drawn as it is, by its suffix)" if path.suffix.lower() != ".toml" else "")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(f"scene file {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"cannot read scene file {path}: {exc}{hint}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML: {exc}{hint}") from None
    ck = _Checker(path, text)
    ck.unknown(data, TOP_KEYS, "scene", "", None)

    cam_d = data.get("camera", {})
    if not isinstance(cam_d, dict):
        ck.fail("camera", "must be a table [camera]", "camera")
    ck.unknown(cam_d, CAMERA_KEYS, "camera", "camera")
    override = size is not None
    size = list(size) if override else cam_d.get("size", [960, 540])
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(x, int) and not isinstance(x, bool) and 0 < x <= MAX_SIDE for x in size)):
        if override:   # the command's --size, not the file's field
            raise SceneError(f"--size: must be WxH with each side 1..{MAX_SIDE}, got {size!r}")
        ck.fail("camera.size", f"must be [width, height] in pixels, got {size!r}", "camera", None, "size")
    r = data.get("render", {})
    if not isinstance(r, dict):
        ck.fail("render", "must be a table [render]", "render")
    ck.unknown(r, RENDER_KEYS, "render", "render")
    VARIANTS = variants("parametric")
    variant = r.get("variant", "points")
    if variant not in variants():   # the frame's variant: for the objects of its kind
        ck.fail("render.variant", f"unknown variant {variant!r} (available: {', '.join(variants())})", "render", None, "variant")
    th = r.get("threshold", 84.0)
    if _number(th):
        th = [th, th]
    if not (isinstance(th, list) and len(th) == 2 and all(_number(x) and x > 0 for x in th)):
        ck.fail("render.threshold", f"must be a positive number of pixels or [t_u, t_v], got {r.get('threshold')!r}", "render", None, "threshold")
    grid = r.get("initial_grid", [1, 1])
    if not (isinstance(grid, list) and len(grid) == 2 and all(_number(x) and isinstance(x, int) and 1 <= x <= 64 for x in grid)):
        ck.fail("render.initial_grid", f"must be [gu, gv] with integers in 1..64, got {grid!r}", "render", None, "initial_grid")
    settings = RenderSettings(
        lod=LodSettings(threshold=(float(th[0]), float(th[1])),
                        max_steps=ck.num(r, "max_steps", "render", "render", default=12, lo=1, hi=15, integer=True),
                        initial_grid=tuple(grid),
                        max_patches=ck.num(r, "max_patches", "render", "render", default=1 << 24, lo=1, integer=True),
                        patch_budget=ck.num(r, "patch_budget", "render", "render", default=LodSettings.patch_budget,
                                            lo=1, integer=True),
                        detail_angle=ck.num(r, "detail_angle", "render", "render", default=LodSettings.detail_angle,
                                            lo=1, hi=180),
                        spot_angle=ck.num(r, "spot_angle", "render", "render", default=LodSettings.spot_angle,
                                          lo=1, hi=179),
                        spot_share=ck.num(r, "spot_share", "render", "render", default=LodSettings.spot_share,
                                          lo=0.001, hi=1)),
        points=PointSettings(density=ck.num(r, "density", "render", "render", default=PointSettings.density, lo=0.1, hi=16)))
    background = ck.vec(r, "background", 3, "render", "render", default=[0.12, 0.12, 0.14])
    settings.tess = _tess_settings(r, ck)
    settings.mesh.threshold_px = ck.num(r, "mesh_threshold", "render", "render", default=settings.mesh.threshold_px,
                                        lo=0, hi=1e6)
    settings.points.thin_tubes = ck.flag(r, "thin_tubes", "render", "render", default=PointSettings.thin_tubes)
    for key in ("color_by", "coverage"):   # the point variant's debug colouring, its pixel coverage
        if key in r:
            setattr(settings.points, key, r[key])
            try:
                settings.points.validate()
            except ParamlodError as exc:
                ck.fail(f"render.{key}", str(exc), "render", None, key)
    if "mesh_color_by" in r:
        settings.mesh.color_by = r["mesh_color_by"]
        try:
            settings.mesh.validate()
        except ParamlodError as exc:
            ck.fail("render.mesh_color_by", str(exc), "render", None, "mesh_color_by")

    scene = Scene(background=background)
    objects = data.get("objects", [])
    if not isinstance(objects, list) or not objects:
        ck.fail("objects", "the scene needs at least one [[objects]] table", "objects")
    for i, o in enumerate(objects):
        where = f"objects[{i}]"
        if not isinstance(o, dict):
            ck.fail(where, "must be a table [[objects]]", "objects", i)
        ck.unknown(o, OBJECT_KEYS, where, "objects", i)
        sources = [k for k in SOURCE_KEYS if k in o]
        if len(sources) > 1:
            ck.fail(f"{where}.{sources[1]}", f"an object is one of {', '.join(SOURCE_KEYS)}; it has both "
                    f"{sources[0]} and {sources[1]}", "objects", i, sources[1])
        if "skinned" in o and sources:
            ck.fail(f"{where}.skinned", f"a skinned mesh is an object of its own; this one has {sources[0]} too",
                    "objects", i, "skinned")
        if not {"sh_field", "surfels", "mesh", "skinned"} & set(o) and ("function" not in o or not isinstance(o["function"], str)):
            ck.fail(f"{where}.function", "is required (a function name, see `paramlod functions`; "
                    "or mesh = \"file.ply\", or skinned = \"file.glb\")", "objects", i)
        params = o.get("params", {})
        if not isinstance(params, dict):
            ck.fail(f"{where}.params", "must be a table of name = value", "objects", i, "params")
        for name, value in params.items():   # numbers only: TOML's true would pass as 1
            if not _is_param_value(value):
                ck.fail(f"{where}.params.{name}", f"must be a number or a list of numbers, got {value!r}",
                        "objects", i, "params")
        for source, keys in NOT_FOR.items():   # fields that would be silently ignored
            for k in (keys & set(o) if source in o else ()):
                ck.fail(f"{where}.{k}", f"does not apply to a {source} object", "objects", i, k)
        if "skinned" in o:
            _check_skinned_keys(o, ck, where, i)
        else:
            for k in SKINNED_KEYS:
                if k in o:
                    ck.fail(f"{where}.{k}", 'is for skinned meshes (skinned = "file.glb")', "objects", i, k)
        if "mesh" in o:
            _check_mesh_keys(o, ck, where, i)
        elif "lod" in o:
            ck.fail(f"{where}.lod", "is for mesh objects (mesh = \"file.ply\")", "objects", i, "lod")
        ov = o.get("variant")
        if ov is not None and {"mesh", "skinned"} & set(o):
            MESH_VARIANTS = variants("mesh")
            if not (isinstance(ov, str) and ov.partition(":")[0] in MESH_VARIANTS):
                ck.fail(f"{where}.variant", f"unknown variant {ov!r} for a mesh (available: "
                        f"{', '.join(MESH_VARIANTS) or 'none registered'}, or '<variant>:<AA mode>')",
                        "objects", i, "variant")
        elif ov is not None and not (ov in VARIANTS or (isinstance(ov, str) and ov.startswith("tess:"))):
            ck.fail(f"{where}.variant", f"unknown variant {ov!r} (available: {', '.join(VARIANTS)}, "
                    "or 'tess:<AA mode>')", "objects", i, "variant")
        try:
            m = _transform(o, ck, where, i)
            mat = Material(color=tuple(ck.vec(o, "color", 3, where, "objects", i, default=[0.8, 0.8, 0.8])),
                           specular=ck.num(o, "specular", where, "objects", i, default=0.25, lo=0, hi=1),
                           two_sided=ck.flag(o, "two_sided", where, "objects", i, default=True))
            if "mesh" in o:
                _add_mesh(scene, o, path, m, mat, ck, where, i)
            elif "skinned" in o:
                _add_skinned(scene, o, path, m, mat)
            elif "surfels" in o:
                _add_surfels(scene, o["surfels"], path, m, mat, ck, where, i, has_color="color" in o)
            elif "sh_field" in o:
                _add_sh_field(scene, o["sh_field"], path, m, mat, ck, where, i)
            elif "instances" in o:
                _add_instances(scene, o, params, path, m, mat, ck, where, i)
            else:
                scene.add(o["function"], params=params, transform=m, material=mat)
            if ov is not None and not {"surfels", "mesh", "skinned"} & set(o):   # the object's own renderer and AA mode
                obj = scene.objects[-1]
                obj.variant, _, aa = ov.partition(":")
                obj.aa = aa or None
        except MeshError as exc:   # the mesh file: its message names it
            key = "animation" if "skinned" in o and "animation" in str(exc) and "animation" in o else \
                ("skinned" if "skinned" in o else "mesh")
            ck.fail(f"{where}.{key}", str(exc), "objects", i, key)
        except SceneError as exc:
            if str(exc).startswith(str(path)):
                raise
            ck.fail(where, str(exc), "objects", i)
        except ParamlodError as exc:   # named after what the object is made of, not always "function"
            key = "params" if "parameter" in str(exc) else (sources[0] if sources else "function")
            ck.fail(f"{where}.{key}", str(exc), "objects", i, key)
    camera = _camera(cam_d, size, scene, ck)
    mesh_default = KINDS["mesh"].variant_for(variant) if "mesh" in KINDS else "meshlets"   # what draws a mesh here
    per = [o.get("variant", mesh_default if {"mesh", "skinned"} & set(o) else variant) for o in objects]
    mixed = per if any("variant" in o for o in objects) and len(set(per)) > 1 else None
    object_aa = ""
    if mixed is None and any("variant" in o for o in objects):   # every object's 'variant[:AA]' is the frame's
        variant, _, object_aa = per[0].partition(":")
        settings.tess.aa = object_aa or settings.tess.aa
    try:   # `aa` holds for the point variant too, which supersamples only
        # the frame's variant is named only when the file sets aa (a points-ssaa file without aa keeps its ss)
        settings.apply_aa(settings.tess.aa, points_only=mixed is None and variant == "points",
                          variant=variant if mixed is None and ("aa" in r or object_aa) else None)
    except SceneError as exc:
        if object_aa:
            ck.fail("objects[0].variant", str(exc), "objects", 0, "variant")
        ck.fail("render.aa", str(exc), "render", None, "aa")
    meta = data.get("meta", {})
    if not isinstance(meta, dict):
        ck.fail("meta", "must be a table [meta] (title, caption)", "meta")
    ck.unknown(meta, META_KEYS, "meta", "meta")
    for key in ("title", "caption", "prepare"):
        if key in meta and not isinstance(meta[key], str):
            ck.fail(f"meta.{key}", f"must be a string, got {meta[key]!r}", "meta", None, key)
    if "needs" in meta and not (isinstance(meta["needs"], list) and all(isinstance(n, str) for n in meta["needs"])):
        ck.fail("meta.needs", f"must be a list of file names, got {meta['needs']!r}", "meta", None, "needs")
    anim = data.get("animation")
    if anim is not None:
        ck.unknown(anim, ANIMATION_KEYS, "animation", "animation")
        anim = {"frames": ck.num(anim, "frames", "animation", "animation", default=8, lo=1, hi=240, integer=True),
                "t0": ck.num(anim, "t0", "animation", "animation", default=0.0),
                "t1": ck.num(anim, "t1", "animation", "animation", default=1.0),
                "fps": ck.num(anim, "fps", "animation", "animation", default=8, lo=1, hi=60)}
        if anim["t1"] == anim["t0"]:
            ck.fail("animation.t1", f"must differ from t0 = {anim['t0']:g}: time would not move "
                    "(t1 < t0 plays the animation backwards)", "animation", None, "t1")
    return SceneFile(scene, camera, settings, variant, path, mixed, meta, anim)


def _camera(cam_d: dict, size, scene, ck: _Checker) -> Camera:
    """The [camera] table; without ``eye`` the camera frames the scene from ``direction``."""
    fov = ck.num(cam_d, "fov_y", "camera", "camera", default=45.0, lo=1, hi=179)
    up = ck.vec(cam_d, "up", 3, "camera", "camera", default=[0.0, 1.0, 0.0])
    try:
        if "eye" not in cam_d:
            if "target" in cam_d or "near" in cam_d or "far" in cam_d:
                ck.fail("camera", "target, near and far need an eye; without eye the camera frames the scene",
                        "camera")
            return framing_camera(
                scene, ck.vec(cam_d, "direction", 3, "camera", "camera", default=[0.6, 0.45, 1.0]), up, fov, size,
                ck.num(cam_d, "margin", "camera", "camera", default=1.1, lo=0.1, hi=10))
        if "direction" in cam_d or "margin" in cam_d:
            ck.fail("camera", "direction and margin are for a framing camera (no eye)", "camera")
        return Camera.look_at(
            ck.vec(cam_d, "eye", 3, "camera", "camera"),
            ck.vec(cam_d, "target", 3, "camera", "camera", default=[0.0, 0.0, 0.0]), up,
            fov_y=fov, size=size, near=ck.num(cam_d, "near", "camera", "camera", default=0.01, lo=1e-6),
            far=ck.num(cam_d, "far", "camera", "camera", default=1000.0, lo=1e-6))
    except SceneError as exc:
        if str(exc).startswith(str(ck.path)):
            raise
        ck.fail("camera", str(exc).removeprefix("camera: "), "camera")


def _number(x) -> bool:
    """A finite TOML number; not a boolean (Python's True is an int, TOML's true is no number)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _is_param_value(v) -> bool:
    return _number(v) or (isinstance(v, list) and all(_number(x) for x in v))


def _builder(spec):
    """The callable a scene file names as ``builder``: a registered one; any importable
    ``module:function`` only when the scene is trusted (that runs code the file names)."""
    if not isinstance(spec, str):
        raise SceneError(f"a builder is named by a string, got {spec!r}")
    try:
        return registry.get_builder(spec)
    except FunctionError as exc:
        if not trusted():
            raise SceneError(str(exc)) from None
    return _import(spec)


def _import(spec: str):
    """``"package.module:function"`` -> the function."""
    mod, _, name = spec.partition(":")
    if not mod or not name:
        raise SceneError(f"a builder is named 'package.module:function', got {spec!r}")
    try:
        return getattr(importlib.import_module(mod), name)
    except (ImportError, AttributeError) as exc:
        raise SceneError(f"cannot load builder {spec!r}: {exc}") from None


INSTANCES_FORMS = ('{ builder = "module:function", args = { ... } } or '
                   '{ grid = [nx, ny, nz], spacing = s or [sx, sy, sz] }')


def _instances(o, ck, where, i, allowed: set) -> dict:
    """The instance arrays of ``instances``: from a builder (``builder = "module:function"``,
    ``args``), which returns a dict (count, transforms, colors, and for functions params and
    per_instance), or a grid of copies centred on the origin (``grid``, ``spacing``)."""
    spec = o["instances"]
    if isinstance(spec, dict) and "grid" in spec:
        if set(spec) - {"grid", "spacing"}:
            ck.fail(f"{where}.instances", f"must be {INSTANCES_FORMS}", "objects", i, "instances")
        g = spec["grid"]
        if not (isinstance(g, list) and len(g) == 3 and all(isinstance(x, int) and not isinstance(x, bool)
                                                            and x >= 1 for x in g)) or math.prod(g) > 1 << 24:
            ck.fail(f"{where}.instances", f"grid must be [nx, ny, nz], integers >= 1 (at most 2^24 copies), got {g!r}",
                    "objects", i, "instances")
        sp = spec.get("spacing", 1.0)
        sp = [sp] * 3 if isinstance(sp, (int, float)) and not isinstance(sp, bool) else sp
        if not (isinstance(sp, list) and len(sp) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                              and np.isfinite(x) and x > 0 for x in sp)):
            ck.fail(f"{where}.instances", f"spacing must be a positive number or [sx, sy, sz], got {spec['spacing']!r}",
                    "objects", i, "instances")
        idx = np.stack(np.meshgrid(*[np.arange(n) for n in g], indexing="ij"), axis=-1).reshape(-1, 3)
        tr = np.repeat(np.eye(4)[None], len(idx), axis=0)
        tr[:, :3, 3] = (idx - (np.asarray(g) - 1) / 2) * np.asarray(sp, float)
        return {"count": len(idx), "transforms": tr}
    if not isinstance(spec, dict) or "builder" not in spec or set(spec) - {"builder", "args"}:
        ck.fail(f"{where}.instances", f"must be {INSTANCES_FORMS}", "objects", i, "instances")
    if not isinstance(spec.get("args", {}), dict):
        ck.fail(f"{where}.instances", "args must be a table of name = value", "objects", i, "instances")
    try:
        builder = _builder(spec["builder"])
    except SceneError as exc:
        ck.fail(f"{where}.instances", str(exc), "objects", i, "instances")
    try:
        res = builder(**spec.get("args", {}))
    except (TypeError, ValueError, OverflowError, ParamlodError) as exc:   # an argument of the wrong kind or size
        ck.fail(f"{where}.instances", f"builder {spec['builder']} failed: {exc}", "objects", i, "instances")
    if not isinstance(res, dict) or "count" not in res or set(res) - allowed:
        got = sorted(res) if isinstance(res, dict) else type(res).__name__
        ck.fail(f"{where}.instances", f"builder {spec['builder']} must return a dict with count and optionally "
                f"{', '.join(sorted(allowed - {'count'}))}; got {got}", "objects", i, "instances")
    return res


def _add_instances(scene, o, params, path, m, mat, ck, where, i):
    """``instances = ...`` (see ``_instances``) of a function object: ``Scene.add_instances``."""
    res = _instances(o, ck, where, i, {"count", "params", "per_instance", "transforms", "colors"})
    scene.add_instances(o["function"], res["count"], params={**res.get("params", {}), **params},
                        per_instance=res.get("per_instance"), transforms=res.get("transforms"),
                        transform=m, material=mat, colors=res.get("colors"))


def _check_mesh_keys(o, ck, where, i):
    if not isinstance(o["mesh"], str) or not o["mesh"].strip():
        ck.fail(f"{where}.mesh", f'must be a file name such as "bunny.ply" (relative to the scene file), '
                f"got {o['mesh']!r}", "objects", i, "mesh")
    if "params" in o:
        ck.fail(f"{where}.params", "a mesh takes no params (they are for function objects)", "objects", i, "params")
    if o.get("lod", "dag") not in MESH_LODS:
        ck.fail(f"{where}.lod", f"must be one of {', '.join(map(repr, MESH_LODS))} (\"dag\": level of detail "
                f"per frame, \"full\": every triangle, \"chain\": one whole-mesh level per frame), got {o['lod']!r}", "objects", i, "lod")


def _check_skinned_keys(o, ck, where, i):
    if not isinstance(o["skinned"], str) or not o["skinned"].strip():
        ck.fail(f"{where}.skinned", f'must be a glTF/GLB file name such as "worm.glb" (relative to the scene file), '
                f"got {o['skinned']!r}", "objects", i, "skinned")
    for k in ("params", "lod", "instances"):
        if k in o:
            ck.fail(f"{where}.{k}", "a skinned mesh takes no " + k + " (every meshlet is drawn at full detail, once)",
                    "objects", i, k)
    a = o.get("animation")
    if a is not None and (isinstance(a, bool) or not isinstance(a, (str, int)) or (isinstance(a, int) and a < 0)):
        ck.fail(f"{where}.animation", f"must be the animation's name or index (>= 0), got {a!r}", "objects", i, "animation")
    if "time" in o:
        ck.num(o, "time", where, "objects", i)


def _add_skinned(scene, o, path, m, mat):
    """``skinned = "x.glb"`` (relative to the scene file), optionally ``animation`` (name or index;
    default the first), ``time`` (seconds; default: the scene's time, e.g. ``--time``) and
    ``variant = "meshlets"`` or ``"meshlets-gl:<AA mode>"``."""
    file = (path.parent / o["skinned"]).resolve()
    variant, _, aa = o["variant"].partition(":") if "variant" in o else (None, "", "")
    scene.add_skinned_mesh(file, animation=o.get("animation"), time=o.get("time"), transform=m, material=mat,
                           variant=variant, aa=aa or None)


def _add_mesh(scene, o, path, m, mat, ck, where, i):
    """``mesh = "x.ply"`` (relative to the scene file), ``lod``, and optionally ``instances``
    (count, transforms and colors) and ``variant = "meshlets"`` or ``"meshlets:<AA mode>"``."""
    file = (path.parent / o["mesh"]).resolve()
    variant, _, aa = o["variant"].partition(":") if "variant" in o else (None, "", "")
    lod = o.get("lod", "dag")
    if "instances" in o:
        res = _instances(o, ck, where, i, {"count", "transforms", "colors"})
        scene.add_mesh_instances(file, res["count"], transforms=res.get("transforms"), transform=m, material=mat,
                                 colors=res.get("colors"), lod=lod, variant=variant, aa=aa or None)
    else:
        scene.add_mesh(file, lod=lod, transform=m, material=mat, variant=variant, aa=aa or None)


SURFEL_KEYS = {"path", "px", "count", "mesh", "blend"}


def _add_surfels(scene, spec, path, m, mat, ck, where, i, has_color=False):
    """``surfels = { path = "x.surfels", px = 2 }`` (surfel size in pixels) or ``count = N``, and
    optionally ``mesh = "x.ply"`` (the mesh that takes over past the stored prefix, relative to
    the scene file) with ``blend = 0.5`` (paramlod.scene.handoff); the object's ``color``, when
    given, colours that mesh."""
    if not isinstance(spec, dict) or "path" not in spec or set(spec) - SURFEL_KEYS \
            or ("px" in spec and "count" in spec):
        ck.fail(f"{where}.surfels", 'must be { path = "x.surfels", px = 2 } or { path = ..., count = N }, '
                'optionally with mesh = "x.ply" and blend = 0.5', "objects", i, "surfels")
    mesh = spec.get("mesh")
    if mesh is not None and (not isinstance(mesh, str) or not mesh.strip()):
        ck.fail(f"{where}.surfels.mesh", f'must be a file name such as "bunny.ply" (relative to the scene file), '
                f"got {mesh!r}", "objects", i, "surfels")
    if "blend" in spec:
        b = spec["blend"]
        if mesh is None:
            ck.fail(f"{where}.surfels.blend", 'is the range of the hand-off to a mesh; give mesh = "x.ply" too',
                    "objects", i, "surfels")
        if isinstance(b, bool) or not isinstance(b, (int, float)) or not math.isfinite(b) or b <= 0:
            ck.fail(f"{where}.surfels.blend", f"must be a number > 0 (e.g. 0.5: the mesh has taken over when the "
                    f"surfel law asks for 1.5 times the set), got {b!r}", "objects", i, "surfels")
    _check_file(path, spec["path"], ck, f"{where}.surfels.path", i, "surfels")
    def bad(v):
        return isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
    if "px" in spec and (bad(spec["px"]) or spec["px"] <= 0):
        ck.fail(f"{where}.surfels.px", f"must be a number of pixels > 0, got {spec['px']!r}", "objects", i, "surfels")
    if "count" in spec and (bad(spec["count"]) or not isinstance(spec["count"], int) or spec["count"] < 1):
        ck.fail(f"{where}.surfels.count", f"must be an integer >= 1, got {spec['count']!r}", "objects", i, "surfels")
    strategy = FixedCount(int(spec["count"])) if "count" in spec else FixedSize(float(spec.get("px", 2.0)))
    try:
        scene.add_surfels((path.parent / spec["path"]).resolve(), transform=m, strategy=strategy,
                          specular=mat.specular, mesh=None if mesh is None else (path.parent / mesh).resolve(),
                          blend=float(spec.get("blend", DEFAULT_BLEND)),
                          material=mat if mesh is not None and has_color else None)
    except MeshError as exc:   # the hand-off mesh's file: its message names it
        ck.fail(f"{where}.surfels.mesh", str(exc), "objects", i, "surfels")


def _add_sh_field(scene, spec, path, m, mat, ck, where, i):
    """``sh_field = { path = "x.npz" | "x.nii.gz", basis = ..., color_by = ..., ... }``: a glyph
    field from a file (paramlod.dmri), as one object of 'sh_glyph' instances."""
    if not isinstance(spec, dict) or "path" not in spec:
        ck.fail(f"{where}.sh_field", 'must be { path = "field.npz" or "sh.nii.gz", ... }', "objects", i, "sh_field")
    spec = dict(spec)
    _check_file(path, spec["path"], ck, f"{where}.sh_field.path", i, "sh_field")
    file = (path.parent / spec.pop("path")).resolve()
    load_keys = {"basis", "legacy", "stride"}
    load = {k: spec.pop(k) for k in list(spec) if k in load_keys}
    unknown = set(spec) - SH_FIELD_KEYS
    if unknown or (load and file.suffix == ".npz"):
        key = sorted(unknown or load)[0]
        ck.fail(f"{where}.sh_field.{key}", f"unknown field (sh_field takes path, {', '.join(sorted(SH_FIELD_KEYS))}, and for "
                f"a NIfTI volume {', '.join(sorted(load_keys))})" if unknown else
                f"is for NIfTI volumes: a .npz field is stored already sampled", "objects", i, "sh_field")
    try:
        if file.suffix == ".npz":
            field = dmri.load_field_npz(file)
        else:
            field = dmri.load_sh_volume(file, **load)
        field.to_scene(scene, transform=m, material=mat, **spec)
    except TypeError as exc:
        ck.fail(f"{where}.sh_field", str(exc), "objects", i, "sh_field")


def _check_file(scene_path: Path, name, ck, where: str, i: int, key: str) -> None:
    """A data file an object names exists, reported under the field that names it."""
    if not isinstance(name, str) or not name.strip():
        ck.fail(where, f"must be a file name (relative to the scene file), got {name!r}", "objects", i, key)
    file = (scene_path.parent / name).resolve()
    if not file.is_file():
        ck.fail(where, f"file {file} does not exist" if not file.exists() else f"{file} is not a file",
                "objects", i, key)


def _tess_settings(r: dict, ck: _Checker):
    ts = TessSettings()
    if "aa" in r:
        ts.aa = r["aa"]
    levels = r.get("levels", "adaptive")
    if levels in ("adaptive", "chord"):
        ts.mode = levels
    elif isinstance(levels, list) and len(levels) == 2 and all(_number(x) for x in levels):
        ts.mode, ts.levels = "fixed", (float(levels[0]), float(levels[1]))
    else:
        ck.fail("render.levels", f'must be "adaptive", "chord" or [inner, outer], got {levels!r}', "render", None,
                "levels")
    ts.chord_px = ck.num(r, "chord_px", "render", "render", default=ts.chord_px, lo=0.01, hi=100)
    for key in ("tessellator", "inner_measure"):
        if key in r:
            setattr(ts, key, r[key])
    ts.l_min = ck.num(r, "l_min", "render", "render", default=ts.l_min, lo=1, hi=64)
    ts.l_max = ck.num(r, "l_max", "render", "render", default=ts.l_max, lo=1, hi=64)
    if "spacing" in r:
        ts.spacing = r["spacing"]
    if "msaa_lod" in r:
        if not isinstance(r["msaa_lod"], bool):
            ck.fail("render.msaa_lod", f"must be true or false, got {r['msaa_lod']!r}", "render", None, "msaa_lod")
        ts.msaa_lod = r["msaa_lod"]
    try:
        ts.validate()
    except ParamlodError as exc:
        key = next((k for k in ("aa", "spacing", "l_min", "l_max", "tessellator", "inner_measure")
                    if k in r and k in str(exc)), "aa")
        ck.fail(f"render.{key}", str(exc), "render", None, key)
    return ts


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
        ok = (isinstance(rot, list) and len(rot) == 2 and _number(rot[0])
              and isinstance(rot[1], list) and len(rot[1]) == 3 and all(_number(x) for x in rot[1]))
        if not ok:
            ck.fail(f"{where}.rotate", f"must be [angle_degrees, [x, y, z]], got {rot!r}", "objects", i, "rotate")
        m = m @ rotate(rot[0], rot[1])
    if "scale" in o:
        s = o["scale"]
        if _number(s) and s > 0:
            m = m @ scale(s)
        elif _number(s):
            ck.fail(f"{where}.scale", f"a single scale must be a number > 0 (mirror with [-1, 1, 1]), got {s!r}",
                    "objects", i, "scale")
        else:
            m = m @ scale(*ck.vec(o, "scale", 3, where, "objects", i))
    return m
