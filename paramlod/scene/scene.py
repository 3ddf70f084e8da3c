"""Scenes: objects (a function, its parameters, a transform and a material), instance arrays,
composite parts, and the flat instance buffers the kernels read.

An object may stand for many instances (``add_instances``): per-instance parameters and
transforms are numpy arrays, so a 358,140-fiber curtain is built without a Python loop per
instance. Parts declared by a function (``parts=[Part(...)]``) become child instances placed on
the parent's surface frame, recomputed for the scene's ``time``.

Meshes (``add_mesh``, ``add_mesh_instances``) hold a MeshLod that the "mesh" loader of
``paramlod.scene.loaders`` makes (registered by ``paramlod.meshlod``, which this room does not
import); a source added twice to one scene is loaded once, so the device holds it once.

A surfel object may carry its mesh (``add_surfels(..., mesh=...)``): the scene then also holds a
MeshObject whose ``handoff`` is the SurfelObject (and whose object id is the surfel object's), and
the mesh takes over where the surfel prefix runs out (paramlod.scene.handoff).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from paramlod.errors import FunctionError, SceneError
from paramlod.function.define import ParametricFunction
from paramlod.function.registry import get_function
from paramlod.scene.handoff import DEFAULT_BLEND, check_blend
from paramlod.scene.loaders import load
from paramlod.scene.meshes import source_key, source_label
from paramlod.core.color import srgb_to_linear
from paramlod.core.layouts import INSTANCE_F, INSTANCE_U
from paramlod.core.transforms import check_transform, check_values, is_number, matrix as _as_matrix

# Per-instance float record (paramlod.core.layouts.INSTANCE_F, INST_* in the kernels' prelude):
# 4x4 model matrix (row-major), 3x4 normal matrix rows, domain (u0, u1, v0, v1).
INST_FLOATS = INSTANCE_F.length
# Per-instance uint record (INSTANCE_U): function index, parameter-block offset, object id, flags.
INST_UINTS = INSTANCE_U.length
MAX_OBJECTS = 4095   # object ids are carried in 12 bits of the aux key (docs/frame.md); all kinds together
MESH_LODS = ("dag", "full", "chain")
MAX_PART_DEPTH = 4
_versions = itertools.count(1)


@dataclass
class Material:
    color: tuple[float, float, float] = (0.8, 0.8, 0.8)  # linear RGB
    specular: float = 0.25
    # False: only the side df/du x df/dv points to is seen (a closed surface's outside, or a
    # one-sided sheet), so the LOD stage may cull back-facing patches (docs/lod.md)
    two_sided: bool = True

    def __post_init__(self):
        if not isinstance(self.two_sided, (bool, np.bool_)):
            raise SceneError(f"material two_sided must be true or false, got {self.two_sided!r}")
        try:
            c = np.asarray(self.color, dtype=np.float64)
        except (TypeError, ValueError):
            c = np.full(0, np.nan)
        if c.shape != (3,) or not np.all((c >= 0) & (c <= 1)):
            raise SceneError(f"material color must be three numbers in [0, 1], got {self.color!r}")
        if not (is_number(self.specular) and 0 <= self.specular <= 1):
            raise SceneError(f"material specular must be in [0, 1], got {self.specular!r}")
        self.color = tuple(float(x) for x in c)


@dataclass
class SceneObject:
    function: ParametricFunction
    params: dict                       # shared values (defaults for the rest)
    transform: np.ndarray              # 4x4, applied after the per-instance transforms
    material: Material
    object_id: int
    count: int = 1
    per_instance: dict = field(default_factory=dict)   # name -> array [count] or [count, size]
    transforms: np.ndarray | None = None               # [count, 4, 4] or None
    colors: np.ndarray | None = None                   # [count, 3] linear RGB, or None
    variant: str | None = None   # the renderer that draws it ("points", "tess", ...); None: the frame's
    aa: str | None = None        # its anti-aliasing mode ("4xSS", "4xSS+8xMS", ...); None: the frame's


@dataclass
class SurfelObject:
    """A blue-surfel set drawn as a view-dependent prefix (paramlod.surfels)."""

    surfels: object            # paramlod.surfels.SurfelSet
    transform: np.ndarray
    strategy: object           # FixedSize, FixedCount, FrameTimeAdaptive; None: FixedSize(2 px)
    object_id: int
    specular: float = 0.25
    # the MeshObject that takes over past the stored prefix (None: the surfels draw alone), and the
    # demand range of the blend (paramlod.scene.handoff.mesh_weight); not in repr/eq (they point at each other)
    mesh: object = field(default=None, repr=False, compare=False)
    blend: float = DEFAULT_BLEND


@dataclass
class MeshObject:
    """A triangle mesh with its level of detail (paramlod.meshlod.MeshLod), drawn ``count`` times."""

    mesh: object                       # paramlod.meshlod.format.MeshLod
    transform: np.ndarray              # 4x4, applied after the per-instance transforms
    material: Material
    object_id: int
    count: int = 1
    transforms: np.ndarray | None = None   # [count, 4, 4] or None
    colors: np.ndarray | None = None       # [count, 3] linear RGB, or None
    variant: str | None = None   # "meshlets" (OpenCL raster into the key buffers), "meshlets-gl"; None: the frame's
    aa: str | None = None
    # the SurfelObject this mesh takes over from (count 1, its transform and object id), or None
    handoff: object = field(default=None, repr=False, compare=False)


@dataclass
class SkinnedMeshObject(MeshObject):
    """A linear-blend-skinned mesh (paramlod.meshlod.skinned.SkinnedMesh) posed at ``time`` (None:
    the scene's time), drawn by the mesh renderers; made by ``Scene.add_skinned_mesh``."""

    time: float | None = None


F32_MAX = float(np.finfo(np.float32).max)


def _check_placed(m, transforms, who: str) -> None:
    """The composed model matrices of an object stay within what float32 can place."""
    if transforms is not None:
        check_values(m @ transforms, f"{who}: transform @ transforms")


def _check_material(who: str, material) -> None:
    if material is not None and not isinstance(material, Material):
        raise SceneError(f"{who}: material must be a paramlod.Material, got {type(material).__name__}")


def _check_count(who: str, count) -> int:
    """An object's instance count as an int; ``who`` names the object in messages."""
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise SceneError(f"{who}: instance count must be an integer of at least 1, got {count!r}")
    return int(count)


def _mesh_model(who: str, material, transform) -> np.ndarray:
    """A mesh object's model matrix, its material checked; ``who`` names the object in messages."""
    _check_material(who, material)
    try:
        return np.eye(4) if transform is None else _as_matrix(transform)
    except SceneError as exc:
        raise SceneError(f"{who}: {exc}") from None


def _check_names(variant, aa) -> None:
    for name, value in (("variant", variant), ("aa", aa)):
        if value is not None and not (isinstance(value, str) and value.strip()):
            raise SceneError(f"{name} must be a name such as 'points', 'tess', 'meshlets' or '4xSS', got {value!r}")


def _param_columns(fn: ParametricFunction) -> dict[str, slice]:
    cols, at = {}, 0
    for p in fn.params:
        cols[p.name] = slice(at, at + p.size)
        at += p.size
    return cols


def _blocks(fn: ParametricFunction, shared: dict, per_instance: dict, count: int, time: float) -> np.ndarray:
    """Parameter blocks [count, param_count] (float32)."""
    shared = dict(shared)
    if "t" in {p.name for p in fn.params} and "t" not in shared and "t" not in per_instance:
        shared["t"] = time
    base = fn.param_block(shared)
    blocks = np.broadcast_to(base, (count, base.size)).copy()
    cols = _param_columns(fn)
    for name, arr in per_instance.items():
        blocks[:, cols[name]] = arr.reshape(count, -1)
    return blocks


class Scene:
    """Objects to render. Renderers keep the scene's buffers on the device between frames and send
    them again when objects are added or ``time`` changes; after changing an object in place (its
    transform, params, ...), call ``touch()``."""

    def __init__(self, background=(0.12, 0.12, 0.14), time: float = 0.0):
        self.objects: list[SceneObject] = []
        self.surfels: list[SurfelObject] = []
        self.meshes: list[MeshObject] = []
        self._loaded_meshes: dict = {}   # (source key, lod) -> (the source, kept alive; its MeshLod)
        self.background = background
        self.time = time
        self._version = next(_versions)
        self._cache = None

    @property
    def background(self) -> tuple:
        """The colour of pixels no object covers: linear RGB, three finite numbers."""
        return self._background

    @background.setter
    def background(self, value):
        try:
            rgb = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            rgb = np.full(0, np.nan)
        if rgb.shape != (3,) or not np.all(np.isfinite(rgb)):
            raise SceneError(f"scene background must be three finite numbers (linear RGB), got {value!r}")
        self._background = tuple(float(x) for x in rgb)

    @property
    def time(self) -> float:
        """The scene's time: the implicit parameter ``t`` of functions that take one, and skinned poses."""
        return self._time

    @time.setter
    def time(self, value):
        if not (is_number(value) and np.isfinite(value)):
            raise SceneError(f"scene time must be a finite number, got {value!r}")
        self._time = float(value)

    def add(self, fn_or_name, params: dict | None = None, transform=None, material: Material | None = None,
            variant: str | None = None, aa: str | None = None) -> SceneObject:
        """Add one object; ``params`` override the function's defaults; ``variant`` and ``aa`` pick
        its renderer and anti-aliasing (default: those of the frame)."""
        return self.add_instances(fn_or_name, 1, params=params, transform=transform, material=material,
                                  variant=variant, aa=aa)

    def add_instances(self, fn_or_name, count: int, params: dict | None = None, per_instance: dict | None = None,
                      transforms=None, transform=None, material: Material | None = None,
                      colors=None, variant: str | None = None, aa: str | None = None) -> SceneObject:
        """Add ``count`` instances of one function as one object (one object id, one material).

        ``per_instance`` maps parameter names to arrays with ``count`` rows; ``transforms`` is an
        optional [count, 4, 4] array applied before ``transform``; ``colors`` an optional
        [count, 3] array of linear RGB in [0, 1] that replaces the material colour per instance.
        ``variant`` and ``aa``: as in ``add``.
        """
        _check_names(variant, aa)
        fn = get_function(fn_or_name)
        self._check_room("use add_instances for many copies of one function")
        count = _check_count(f"'{fn.name}'", count)
        _check_material(f"'{fn.name}'", material)
        params = dict(params or {})
        for name, val in params.items():
            try:
                np.asarray(val, dtype=np.float64)
            except (TypeError, ValueError):
                raise FunctionError(f"function '{fn.name}': parameter '{name}' must be a number or a list "
                                    f"of numbers, got {val!r}") from None
        for name, val in params.items():   # the kernels read parameters as float32
            if np.any(np.abs(np.asarray(val, dtype=np.float64)) > F32_MAX):
                raise FunctionError(f"function '{fn.name}': parameter '{name}' is beyond float32's range "
                                    f"(|value| <= {F32_MAX:.3g}): {val!r}")
        fn.param_block(params)  # validates names, shapes and finiteness of the shared values
        per = {}
        known = {p.name: p for p in fn.params}
        for name, arr in (per_instance or {}).items():
            if name not in known:
                raise SceneError(f"'{fn.name}' has no parameter '{name}' (its parameters: {', '.join(known) or 'none'})")
            a = np.asarray(arr, dtype=np.float64)
            want = (count,) if not known[name].is_array else (count, known[name].size)
            if a.shape != want:
                raise SceneError(f"'{fn.name}': per-instance '{name}' must have shape {want}, got {a.shape}")
            if not np.all(np.isfinite(a)) or np.any(np.abs(a) > F32_MAX):   # checked before float32 rounds it
                raise SceneError(f"'{fn.name}': per-instance '{name}' has non-finite values or values beyond "
                                 f"float32's range (|value| <= {F32_MAX:.3g})")
            a = a.astype(np.float32)
            per[name] = a
        if transforms is not None:
            transforms = np.asarray(transforms, dtype=np.float64)
            if transforms.shape != (count, 4, 4):
                raise SceneError(f"'{fn.name}': transforms must be a finite [{count}, 4, 4] array, got {transforms.shape}")
            transforms = check_transform(transforms, f"'{fn.name}': transforms")
        if colors is not None:
            colors = np.asarray(colors, dtype=np.float32)
            if colors.shape != (count, 3) or not np.all((colors >= 0) & (colors <= 1)):
                raise SceneError(f"'{fn.name}': colors must be a [{count}, 3] array of values in [0, 1]")
        m = np.eye(4) if transform is None else _as_matrix(transform, f"'{fn.name}': transform")
        _check_placed(m, transforms, f"'{fn.name}'")
        obj = SceneObject(fn, params, m, material or Material(), self.object_count + 1, count, per, transforms,
                          colors, variant, aa)
        self.objects.append(obj)
        self.touch()
        return obj

    def add_mesh(self, source, lod: str = "dag", transform=None, material: Material | None = None,
                 variant: str | None = None, aa: str | None = None) -> MeshObject:
        """Add a triangle mesh: a file path (OBJ, PLY, STL, OFF, GLB/glTF, GIfTI ``.surf.gii``), a
        ``trimesh.Trimesh`` or a ``(vertices, faces)`` pair. ``lod``: "dag" (a cluster DAG, drawn
        at the detail the camera needs) or "full" (always every triangle). ``variant`` and ``aa``
        pick its renderer ("meshlets", "meshlets-gl") and anti-aliasing (default: the frame's)."""
        return self.add_mesh_instances(source, 1, transform=transform, material=material, lod=lod,
                                       variant=variant, aa=aa)

    def add_mesh_instances(self, source, count: int, transforms=None, transform=None,
                           material: Material | None = None, colors=None, lod: str = "dag",
                           variant: str | None = None, aa: str | None = None) -> MeshObject:
        """Add ``count`` copies of one mesh as one object (one object id, one material).

        ``transforms``: an optional [count, 4, 4] array applied before ``transform``; ``colors``: an
        optional [count, 3] array of linear RGB in [0, 1] that replaces the material colour per
        copy. The mesh is loaded once per scene for each source (the same object, or the same
        file) and ``lod``, however many objects use it."""
        label = source_label(source)
        _check_names(variant, aa)
        self._check_room("use add_mesh_instances for many copies of one mesh")
        if lod not in MESH_LODS:
            raise SceneError(f"mesh '{label}': lod must be one of {', '.join(map(repr, MESH_LODS))}, got {lod!r}")
        count = _check_count(f"mesh '{label}'", count)
        m = _mesh_model(f"mesh '{label}'", material, transform)
        if transforms is not None:
            try:
                transforms = np.asarray(transforms, dtype=np.float64)
            except (TypeError, ValueError):
                raise SceneError(f"mesh '{label}': transforms must be a [{count}, 4, 4] array of numbers") from None
            if transforms.shape != (count, 4, 4) or not np.all(np.isfinite(transforms)):
                raise SceneError(f"mesh '{label}': transforms must be a finite [{count}, 4, 4] array, "
                                 f"got shape {transforms.shape}")
            transforms = check_values(transforms, f"mesh '{label}': transforms")
        _check_placed(m, transforms, f"mesh '{label}'")
        models = m[None] if transforms is None else m @ transforms
        det = np.linalg.det(models[:, :3, :3])
        if np.any(np.abs(det) < 1e-20):
            k = int(np.argmax(np.abs(det) < 1e-20))
            which = "the transform" if transforms is None else f"instance {k}'s transform"
            raise SceneError(f"mesh '{label}': {which} is singular (it flattens the mesh); give an invertible one")
        if colors is not None:
            try:
                colors = np.asarray(colors, dtype=np.float32)
            except (TypeError, ValueError):
                raise SceneError(f"mesh '{label}': colors must be a [{count}, 3] array of values in [0, 1]") from None
            if colors.shape != (count, 3) or not np.all((colors >= 0) & (colors <= 1)):
                raise SceneError(f"mesh '{label}': colors must be a [{count}, 3] array of values in [0, 1]")
        obj = MeshObject(self._load_mesh(source, lod), m, material or Material(), self.object_count + 1, count,
                         transforms, colors, variant, aa)
        self.meshes.append(obj)
        self.touch()
        return obj

    def add_skinned_mesh(self, source, animation=None, time=None, transform=None, material: Material | None = None,
                         variant: str | None = None, aa: str | None = None) -> SkinnedMeshObject:
        """Add a linear-blend-skinned mesh: a glTF/GLB file with a skin (convert X or FBX files
        first: ``assimp export in.X out.glb -fglb2``) or a paramlod.meshlod.SkinnedMesh.
        ``animation``: the clip's name or index (default: the first). ``time``: the pose's time in
        seconds of the clip (clamped to it); None: the scene's ``time`` drives it, as it drives
        animated parametric objects. Every meshlet is drawn at full detail (no DAG) and culled with
        bounds that hold for the whole clip. ``variant`` ("meshlets", "meshlets-gl") and ``aa`` as
        for add_mesh."""
        label = source_label(source)
        _check_names(variant, aa)
        self._check_room("a skinned mesh takes one object id")
        if animation is not None and (isinstance(animation, bool) or not isinstance(animation, (str, int, np.integer))):
            raise SceneError(f"skinned mesh '{label}': animation must be a name or an index, got {animation!r}")
        if time is not None:
            if not (is_number(time) and np.isfinite(time)):
                raise SceneError(f"skinned mesh '{label}': time must be a finite number of seconds or None, got {time!r}")
            time = float(time)
        m = _mesh_model(f"skinned mesh '{label}'", material, transform)
        if abs(np.linalg.det(m[:3, :3])) < 1e-20:
            raise SceneError(f"skinned mesh '{label}': the transform is singular (it flattens the mesh); give an invertible one")
        key = (source_key(source), "skinned", animation if not isinstance(animation, np.integer) else int(animation))
        hit = self._loaded_meshes.get(key)
        if hit is None:
            hit = self._loaded_meshes[key] = (source, load("skinned", source, animation=animation))
        obj = SkinnedMeshObject(hit[1], m, material or Material(), self.object_count + 1, 1, None, None, variant, aa,
                                time=time)
        self.meshes.append(obj)
        self.touch()
        return obj

    def _load_mesh(self, source, lod):
        key = (source_key(source), lod)
        hit = self._loaded_meshes.get(key)
        if hit is None:
            hit = self._loaded_meshes[key] = (source, load("mesh", source, lod=lod))
        return hit[1]

    def _check_room(self, hint: str) -> None:
        if self.object_count >= MAX_OBJECTS:
            raise SceneError(f"a scene holds at most {MAX_OBJECTS} objects (object ids use 12 bits); {hint}")

    def subscene(self, objects=(), surfels=(), meshes=()) -> "Scene":
        """A scene that draws only ``objects`` (SceneObjects of this scene), ``surfels`` (its
        SurfelObjects) and ``meshes`` (its MeshObjects), keeping their object ids, background and
        time, so that frames of several subscenes composite into the whole scene."""
        ids = {id(o) for o in (*self.objects, *self.surfels, *self.meshes)}
        if any(id(o) not in ids for o in (*objects, *surfels, *meshes)):
            raise SceneError("subscene: an object does not belong to the scene")
        sub = Scene(background=self.background, time=self.time)
        sub.objects, sub.surfels, sub.meshes = list(objects), list(surfels), list(meshes)
        sub.touch()
        return sub

    def touch(self) -> None:
        """Mark the scene as changed: renderers upload its buffers again on the next frame.
        (Versions are unique across scenes, so a renderer never mistakes one scene for another.)"""
        self._version = next(_versions)

    def add_surfels(self, path_or_set, transform=None, strategy=None, specular: float = 0.25, mesh=None,
                    blend: float = DEFAULT_BLEND, material: Material | None = None) -> SurfelObject:
        """Add a ``.surfels`` file or SurfelSet; ``strategy`` picks the prefix each frame
        (paramlod.surfels.FixedSize(2) when None, FixedCount, FrameTimeAdaptive).

        ``mesh`` (anything ``add_mesh`` takes, drawn with its DAG LOD): the mesh the set was made
        from, in the same object space; where the strategy asks for more surfels than the set holds
        (demand = packing / (r^2 N) > 1) the mesh takes over, by a dither over a demand range of
        ``blend`` (weight = clamp((demand - 1) / blend, 0, 1), paramlod.scene.handoff). The mesh is
        a MeshObject of the scene (``obj.mesh``) with the set's transform and object id, coloured
        by ``material`` or the set's mean colour."""
        self._check_room("merge surfel sets into one file")
        blend = check_blend(blend, "add_surfels")
        if material is not None and not isinstance(material, Material):
            raise SceneError(f"add_surfels: material must be a paramlod.Material, got {type(material).__name__}")
        if mesh is None and material is not None:
            raise SceneError("add_surfels: material colours the hand-off mesh; give mesh= too (or leave material out)")
        m = np.eye(4) if transform is None else _as_matrix(transform, "add_surfels: transform")
        obj = SurfelObject(load("surfels", path_or_set), m, strategy, self.object_count + 1, specular, None, blend)
        if mesh is not None:
            if abs(np.linalg.det(m[:3, :3])) < 1e-20:
                raise SceneError("add_surfels: the transform is singular (it flattens the object); "
                                 "give an invertible one")
            if material is None:
                rgb = srgb_to_linear(obj.surfels.colors[:, :3].astype(np.float64) / 255.0).mean(axis=0)
                material = Material(tuple(float(x) for x in np.clip(rgb, 0, 1)), specular)
            obj.mesh = MeshObject(self._load_mesh(mesh, "dag"), m, material, obj.object_id, handoff=obj)
            self.meshes.append(obj.mesh)
        self.surfels.append(obj)
        self.touch()
        return obj

    @property
    def object_count(self) -> int:
        """Objects of every kind (parametric, surfels, meshes): each takes one object id (a surfel
        object's hand-off mesh shares the surfel object's, when both are in the scene)."""
        held = {id(so) for so in self.surfels}
        return len(self.objects) + len(self.surfels) + sum(1 for m in self.meshes if id(m.handoff) not in held)

    @property
    def mesh_instance_count(self) -> int:
        """Drawn copies of meshes."""
        return sum(o.count for o in self.meshes)

    @property
    def instance_count(self) -> int:
        """Parametric instances, parts included (surfel objects not counted)."""
        return sum(len(models) for _, models, _, _, _ in self._expanded())

    def functions(self) -> list[ParametricFunction]:
        """Distinct functions, parts included, in first-use order; the index is the kernel's id."""
        out: list[ParametricFunction] = []

        def visit(fn, depth):
            if all(fn is not f for f in out):
                out.append(fn)
            if depth < MAX_PART_DEPTH:
                for part in getattr(fn, "parts", ()):
                    visit(get_function(part.function), depth + 1)

        for o in self.objects:
            visit(o.function, 0)
        return out

    # --- flattening ------------------------------------------------------------------------
    def _expanded(self):
        """Groups (function, model matrices [n,4,4], blocks [n,k], object id, materials [n,4])."""
        groups = []

        def place(fn, models, blocks, oid, mat, depth):
            groups.append((fn, models, blocks, oid, mat))
            if depth >= MAX_PART_DEPTH:
                return
            for part in getattr(fn, "parts", ()):
                child = get_function(part.function)
                u, v = part.at
                frames = np.stack([fn.surface_frame(u, v, b) for b in blocks])
                local = np.asarray(part.transform if part.transform is not None else np.eye(4), np.float64)
                cmodels = models @ frames @ local
                # parameters named in part.inherit (default: t) flow from each parent instance
                cparams, inherited = dict(part.params or {}), {}
                pcols, cdefs = _param_columns(fn), {p.name: p for p in child.params}
                for name in getattr(part, "inherit", ("t",)):
                    if name in cdefs and name in pcols and name not in cparams:
                        col = blocks[:, pcols[name]]
                        inherited[name] = col if cdefs[name].is_array else col[:, 0]
                cblocks = _blocks(child, cparams, inherited, len(blocks), self.time)
                cmat = mat.copy()
                if getattr(part, "color", None) is not None:
                    cmat[:, :3] = part.color
                place(child, cmodels, cblocks, oid, cmat, depth + 1)

        for o in self.objects:
            models = np.broadcast_to(o.transform, (o.count, 4, 4))
            if o.transforms is not None:
                models = o.transform @ o.transforms
            mats = np.tile(np.array([*o.material.color, o.material.specular], np.float32), (o.count, 1))
            if o.colors is not None:
                mats[:, :3] = o.colors
            place(o.function, np.asarray(models, np.float64),
                  _blocks(o.function, o.params, o.per_instance, o.count, self.time),
                  o.object_id, mats, 0)
        return groups

    def instance_buffers(self):
        """(inst_f float32 [n, 32], inst_u uint32 [n, 4], params float32 [...]) for the kernels."""
        key = (self._version, self.time)
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        funcs = self.functions()
        groups = self._expanded()
        inst_f, inst_u, params, mats = [], [], [], []
        offset = 0
        for fn, models, blocks, oid, mat in groups:
            blocks = fn.device_blocks(blocks)   # the hoisted parameter terms appended
            n = len(models)
            f = np.zeros((n, INST_FLOATS), np.float32)
            f[:, 0:16] = models.reshape(n, 16)
            # each factor was checked; parts placed on parts can add up (or scale down) beyond the limits
            check_transform(models, f"'{fn.name}': the instances' transforms (parts' and instances' multiplied)")
            lin = models[:, :3, :3]
            nrm = np.transpose(np.linalg.inv(lin), (0, 2, 1))
            f[:, 16:28] = np.concatenate([nrm, np.zeros((n, 3, 1))], axis=2).reshape(n, 12)
            f[:, 28:32] = [*fn.u_range, *fn.v_range]
            u = np.zeros((n, INST_UINTS), np.uint32)
            u[:, 0] = next(k for k, g in enumerate(funcs) if g is fn)
            k = blocks.shape[1]
            u[:, 1] = offset + np.arange(n, dtype=np.int64) * k
            u[:, 2] = oid
            offset += n * k
            inst_f.append(f)
            inst_u.append(u)
            params.append(blocks.reshape(-1))
            mats.append(mat)
        if not groups:
            inst_f.append(np.zeros((0, INST_FLOATS), np.float32))
            inst_u.append(np.zeros((0, INST_UINTS), np.uint32))
            mats.append(np.zeros((0, 4), np.float32))
        if offset >= 2 ** 32:
            raise SceneError("the scene's parameter blocks exceed 2^32 floats")
        result = (np.concatenate(inst_f), np.concatenate(inst_u),
                  np.concatenate(params + [np.zeros(1, np.float32)]).astype(np.float32))
        self._materials = np.ascontiguousarray(np.concatenate(mats))
        self._cache = (key, result)
        return result

    def materials(self) -> np.ndarray:
        """float32 [n, 4]: linear RGB and specular per instance."""
        self.instance_buffers()
        return self._materials
