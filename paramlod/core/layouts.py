"""Every record shared by the host and the device, declared once, and the preludes emitted from
the declarations for the OpenCL and GLSL sources.

A record is a list of fields (name, type, count). Two kinds:

- *flat* records (camera, instance floats and uints, material, light, LOD counters): arrays of one
  scalar type read by element offsets. The host builds them as plain float32/uint32 arrays
  (``record.length`` elements each, ``record.slice(field)`` for a field); the kernels read
  ``PREFIX_FIELD`` offsets and the ``size`` macro (``INST_F``, ``CAM_FLOATS``, ...).
- *struct* records (the LOD stage's patches): C structs in OpenCL, std430 structs in GLSL, and
  a packed numpy structured dtype (``record.dtype``) on the host. A float field of 2 or 4 is a
  vector (float4 / vec4); any other count of more than one is that many scalars ``name0``,
  ``name1``, ... (so that no float3 or array stride differs between the three). The layout is
  checked here: every vector sits at a multiple of its size and the record's size is a multiple
  of its largest alignment, so the packed numpy offsets are the C and std430 offsets.

``cl_prelude()`` and ``glsl_prelude()`` return the ``#define``s (offsets, sizes, record constants),
the structs, the shading model's constants (``paramlod.core.shading``) and, for OpenCL, the sRGB
encoding table (``paramlod.core.color``). ``paramlod.device.programs.build`` puts the OpenCL one in
front of every program, the tessellation renderer and the GLSL probe the GLSL one in front of every
stage (after ``#version``). In GLSL every name carries a ``PL_`` prefix and every integer a ``u``
suffix (``PL_INST_F 32u``). ``vertex_format`` gives the moderngl vertex format that reads some of
a struct record's fields as vertex attributes (the tessellation renderer's render list).
tests/core/test_layouts.py compiles both preludes and compares the sizes and offsets the devices
see with these.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from paramlod.core import color, shading

FLOAT, UINT, ULONG = "float", "uint", "ulong"   # ulong: flat records of 64-bit counters only
_NUMPY = {FLOAT: "<f4", UINT: "<u4", ULONG: "<u8"}
_CL_VEC = {2: "float2", 4: "float4"}
_SCALAR = {FLOAT: "float", UINT: "uint"}
_GLSL_VEC = {2: "vec2", 4: "vec4"}
_MODERNGL = {FLOAT: "f", UINT: "u"}


@dataclass(frozen=True)
class Field:
    name: str
    type: str = FLOAT
    count: int = 1
    doc: str = ""


@dataclass(frozen=True)
class Constant:
    """A named value that belongs to a record (a flag bit, a slot with a second meaning)."""
    name: str
    value: int
    unsigned: bool = True   # CL: 16u (GLSL constants are always uint)
    doc: str = ""


class Record:
    """One CPU<->GPU record. ``prefix``: the offset macros' prefix (flat records); ``size``: the
    macro of its length in elements (flat records); ``struct``: the struct name (struct records)."""

    def __init__(self, name: str, doc: str, fields, *, prefix: str = "", size: str = "", struct: str = "",
                 constants=()):
        self.name, self.doc, self.fields = name, doc, tuple(fields)
        self.prefix, self.size_macro, self.struct = prefix, size, struct
        self.constants = tuple(constants)
        self.dtype = np.dtype([(f.name, _NUMPY[f.type]) if f.count == 1 else (f.name, _NUMPY[f.type], f.count)
                               for f in self.fields])
        if struct:
            align = 4
            for f in self.fields:
                if f.type == FLOAT and f.count in _CL_VEC:
                    size_b = 4 * f.count
                    if self.dtype.fields[f.name][1] % size_b:
                        raise ValueError(f"record {name}: vector field {f.name!r} at byte "
                                         f"{self.dtype.fields[f.name][1]}, not a multiple of {size_b}")
                    align = max(align, size_b)
            if self.dtype.itemsize % align:
                raise ValueError(f"record {name}: {self.dtype.itemsize} bytes, not a multiple of its "
                                 f"alignment {align} (C and std430 would pad it)")
        else:
            if not (prefix and size):
                raise ValueError(f"flat record {name} needs a prefix and a size macro")
            if len({f.type for f in self.fields}) != 1:
                raise ValueError(f"flat record {name}: every field must have the same type")

    @property
    def length(self) -> int:
        """Elements (floats, uints or ulongs) of a flat record."""
        return sum(f.count for f in self.fields)

    @property
    def size(self) -> int:
        """Bytes of one record."""
        return self.dtype.itemsize

    def offset(self, field: str) -> int:
        """Element offset (flat record) or byte offset (struct record) of ``field``."""
        off = self.dtype.fields[field][1]
        return off if self.struct else off // np.dtype(_NUMPY[self.fields[0].type]).itemsize

    def slice(self, field: str) -> slice:
        """The elements of ``field`` in a flat record."""
        f = next(f for f in self.fields if f.name == field)
        at = self.offset(field)
        return slice(at, at + f.count)

    def constant(self, name: str) -> int:
        """The value of one of the record's constants."""
        return next(c.value for c in self.constants if c.name == name)

    def macro(self, field: str) -> str:
        return f"{self.prefix}_{field.upper()}"

    # --- emitters -------------------------------------------------------------------------------
    def _defines(self, glsl: bool) -> list[str]:
        pre, suf = ("PL_", "u") if glsl else ("", "")
        lines = []
        if not self.struct:
            lines.append(f"#define {pre}{self.size_macro} {self.length}{suf}")
            for f in self.fields:
                lines.append(f"#define {pre}{self.macro(f.name)} {self.offset(f.name)}{suf}"
                             + (f"   // {f.doc}" if f.doc else ""))
        for c in self.constants:
            cs = "u" if (glsl or c.unsigned) else ""
            lines.append(f"#define {pre}{c.name} {c.value}{cs}" + (f"   // {c.doc}" if c.doc else ""))
        return lines

    def _struct(self, glsl: bool) -> list[str]:
        lines = [f"struct {self.struct} {{" if glsl else "typedef struct {"]
        for f in self.fields:
            doc = f"   // {f.doc}" if f.doc else ""
            if f.type == FLOAT and f.count in _CL_VEC:
                lines.append(f"    {(_GLSL_VEC if glsl else _CL_VEC)[f.count]} {f.name};{doc}")
            elif f.count == 1:
                lines.append(f"    {_SCALAR[f.type]} {f.name};{doc}")
            else:
                names = ", ".join(f"{f.name}{i}" for i in range(f.count))
                lines.append(f"    {_SCALAR[f.type]} {names};{doc}")
        lines.append("};" if glsl else f"}} {self.struct};")
        return lines

    def emit(self, glsl: bool) -> str:
        head = f"// {self.name} ({self.size} bytes): {self.doc}"
        body = (self._struct(glsl) if self.struct else []) + self._defines(glsl)
        return "\n".join([head, *body])


# --- the records --------------------------------------------------------------------------------
CAMERA = Record(
    "camera", "a frame's camera; paramlod.core.layouts.camera_record(camera)", [
        Field("view", FLOAT, 16, "world -> view, row-major"),
        Field("proj", FLOAT, 16, "view -> clip, row-major"),
        Field("w", FLOAT, 1, "width in pixels"),
        Field("h", FLOAT, 1, "height in pixels"),
        Field("near"), Field("far"),
    ], prefix="CAM", size="CAM_FLOATS")

INSTANCE_F = Record(
    "instance floats", "per instance, Scene.instance_buffers()[0]", [
        Field("model", FLOAT, 16, "4x4 model matrix, row-major"),
        Field("normal", FLOAT, 12, "3 rows of 4: the normal matrix (inverse transpose of the 3x3 part)"),
        Field("domain", FLOAT, 4, "u0, u1, v0, v1"),
    ], prefix="INST", size="INST_F")

INSTANCE_U = Record(
    "instance uints", "per instance, Scene.instance_buffers()[1]", [
        Field("func", UINT, 1, "index of the function in the scene's function list"),
        Field("params", UINT, 1, "offset of its parameter block in the params buffer"),
        Field("object", UINT, 1, "object id (1-based)"),
        Field("flags", UINT, 1, "bit 0 (INST_ONE_SIDED): one-sided, its back faces may be culled; bits 1, 2 "
              "(INST_WRAP_U, INST_WRAP_V): the function repeats across the domain in u, v"),
    ], prefix="INST", size="INST_U",
    constants=[Constant("INST_ONE_SIDED", 1, True, "InstanceU.flags: a one-sided material on a smooth function"),
               Constant("INST_WRAP_U", 2, True, "InstanceU.flags: f(u0, v) = f(u1, v) (a periodic u)"),
               Constant("INST_WRAP_V", 4, True, "InstanceU.flags: f(u, v0) = f(u, v1) (a periodic v)")])

MATERIAL = Record(
    "material", "per instance, Scene.materials() (float4 / vec4 per instance)", [
        Field("color", FLOAT, 3, "linear RGB"),
        Field("specular", FLOAT, 1, "specular weight"),
    ], prefix="MAT", size="MAT_FLOATS")

LIGHT = Record(
    "light", "the shading record, paramlod.core.shading.LIGHT (GLSL: uniform vec4 u_light)", [
        Field("towards", FLOAT, 3, "unit vector towards the light, view space"),
        Field("ambient", FLOAT, 1, "ambient share"),
    ], prefix="LIGHT", size="LIGHT_FLOATS")

LOD_COUNTER = Record(
    "LOD counters", "one record per LOD step (paramlod.lod.stage); record 0 holds the initial "
    "patch count (children) and the render list's length (LOD_RENDER_TOTAL)", [
        Field("children", UINT, 1, "patches the step emitted (the next step's input)"),
        Field("split", UINT), Field("culled", UINT), Field("rendered", UINT),
        Field("forced", UINT, 1, "rendered although they would split (last step)"),
        Field("backface", UINT, 1, "culled as back-facing (also counted in culled)"),
        Field("promoted", UINT, 1, "re-queued to a finer hybrid tier by the spot check (also in children)"),
        Field("tier1", UINT, 1, "rendered at hybrid tier 1 (also in rendered)"),
        Field("tier2", UINT, 1, "rendered at hybrid tier 2 (also in rendered)"),
        Field("spare", UINT, 1),
    ], prefix="LOD", size="LOD_COUNTERS",
    constants=[Constant("LOD_RENDER_TOTAL", 1, False, "counters[LOD_RENDER_TOTAL]: the render list's length")])

EVAL_PATCH = Record(
    "eval patch", "a patch waiting for evaluation in an LOD step", [
        Field("range", FLOAT, 4, "u0, u1, v0, v1"),
        Field("inst", UINT),
        Field("tier", UINT, 1, "hybrid anti-aliasing tier (0 coarsest; 0 without hybrid)"),
        Field("pad", UINT, 2),
    ], struct="EvalPatch")

RENDER_PATCH = Record(
    "render patch", "a patch scheduled for rendering (the LOD stage's render list)", [
        Field("range", FLOAT, 4, "u0, u1, v0, v1"),
        Field("bbox", FLOAT, 4, "screen x0, y0, x1, y1 in pixels (of the samples in front of the camera)"),
        # e_u, e_v: the thesis's measured extents (longest of the 4 polylines per direction);
        # s_u, s_v: 7 x the longest single segment, an upper estimate for even sampling
        Field("ext", FLOAT, 4, "e_u, e_v, s_u, s_v in pixels"),
        Field("inst", UINT),
        Field("flags", UINT, 1, "bits 0-3: LOD step; bit 4: forced at the last step; bits 5-6: hybrid tier"),
        Field("w", FLOAT, 2, "w_u, w_v: s_u, s_v raised to what the patch's four boundary lines need (the direct points renderer)"),
    ], struct="RenderPatch",
    constants=[Constant("FLAG_FORCED", 16, True, "RenderPatch.flags: forced out at the last step"),
               Constant("TIER_SHIFT", 5, False, "RenderPatch.flags >> TIER_SHIFT & 3: the hybrid tier")])

CLUSTER = Record(
    "cluster", "one cluster of a mesh's LOD DAG (paramlod.meshlod; object space). A cluster is drawn "
    "iff its own error projects to <= the threshold and its parent error to > it", [
        Field("sphere", FLOAT, 4, "bounding sphere of its triangles: centre xyz, radius (culling)"),
        Field("cone_apex", FLOAT, 4, "backface cone apex xyz, w unused"),
        Field("cone", FLOAT, 4, "backface cone axis xyz, cutoff (cos); culled iff dot(normalize(apex - eye), axis) >= cutoff"),
        Field("lod_sphere", FLOAT, 4, "sphere of the group it was made in; contains its children's lod spheres"),
        Field("parent_sphere", FLOAT, 4, "lod sphere of the group it was simplified into (its parents' lod_sphere)"),
        Field("error", FLOAT, 1, "object-space error of its group (0 for the original triangles)"),
        Field("parent_error", FLOAT, 1, "error of the parents' group; +inf for a root"),
        Field("first", UINT, 1, "first triangle in the mesh's triangle list"),
        Field("count", UINT, 1, "triangles (at most CLUSTER_MAX_TRIANGLES)"),
        Field("level", UINT, 1, "0 for the original triangles"),
        Field("group", UINT, 1, "the group it was made in (clusters of one group share lod_sphere and error)"),
        Field("spare", UINT, 2),
    ], struct="Cluster",
    constants=[Constant("CLUSTER_MAX_TRIANGLES", 128, True, "triangles per cluster at most")])

GRID_VERTEX = Record(
    "grid vertex", "a vertex of the grid tessellator (kernels/tess/grid.cl), drawn by tess/grid_vertex.glsl", [
        Field("pos", FLOAT, 4, "world position; w: 1 where f is NaN/inf (the fragment stage drops its triangles)"),
        Field("normal", FLOAT, 3, "world normal, not normalized"),
        Field("inst", UINT, 1, "the instance"),
    ], struct="GridVertex")

# The render kernels' statistics counters (one ulong each, added with atom_add; the host zeroes
# them before a frame and reads them after it)
POINTS_COUNTER = Record(
    "point counters", "points_direct and points_schedule (paramlod.renderers.points)", [
        Field("samples", ULONG, 1, "samples evaluated"),
        Field("atomics", ULONG, 1, "64-bit atom_min issued into the key buffer"),
        Field("nan_samples", ULONG, 1, "samples whose position is NaN or infinite"),
        Field("capped_patches", ULONG, 1, "patches whose grid hit PointSettings.max_side"),
        Field("sched", ULONG, 1, "points_schedule: patches listed << CHUNK_BITS | units listed so far"),
        Field("units", ULONG, 1, "the most units a list of the frame holds (the host checks MAX_UNITS)"),
    ], prefix="PTS", size="PTS_COUNTERS")

OCC_COUNTER = Record(
    "occlusion counts", "occlusion_first and occlusion_second (paramlod.renderers.occlusion)", [
        Field("early", UINT, 1, "patches drawn now (listed in `early`)"),
        Field("deferred", UINT, 1, "patches deferred to the second test (their indices in `deferred`)"),
        Field("late", UINT, 1, "of them drawn after the second test (listed in `late`)"),
    ], prefix="OCC", size="OCC_COUNTS")

LFB_COUNTER = Record(
    "points-ssaa counters", "lfb_count and points_lfb (paramlod.renderers.points_lfb)", [
        Field("tile_patch_pairs", ULONG, 1, "(tile, patch) pairs"),
        Field("unplaced_patches", ULONG, 1, "patches whose box touches no tile (no sample in front, or off screen)"),
        Field("samples", ULONG, 1, "samples evaluated, every tile that lists the patch counted"),
        Field("samples_unique", ULONG, 1, "samples of the grids, each patch counted once"),
        Field("nan_samples", ULONG, 1, "NaN/inf samples, each patch counted once"),
        Field("bbox_miss_samples", ULONG, 1, "drawable samples that fell in a tile the patch's box did not reach"),
        Field("local_atomics", ULONG, 1, "local atom_min issued (after the early-depth read)"),
        Field("local_hits", ULONG, 1, "samples that landed in the tile being rendered"),
        Field("atomics", ULONG, 1, "global atom_min issued by the resolve (colour buffer)"),
        Field("pixels_resolved", ULONG, 1, "pixels resolved (at least one covered subsample)"),
        Field("covered_subsamples", ULONG, 1, "covered subsamples over all resolved pixels"),
        Field("capped_patches", ULONG, 1, "patches that hit max_side"),
    ], prefix="LFB", size="LFB_COUNTERS")

RASTER_COUNTER = Record(
    "mesh raster counters", "raster_clusters and raster_large (paramlod.meshlod.raster)", [
        Field("triangles", ULONG, 1, "triangles of the selected clusters (times their views)"),
        Field("near_clipped", ULONG, 1, "of them crossing the near plane"),
        Field("culled", ULONG, 1, "of them drawing nothing: behind near, beyond far, not finite, degenerate, "
              "off screen or between pixel centres"),
        Field("large", ULONG, 1, "fan triangles sent to the large list (its length, may pass its capacity)"),
        Field("large_overflow", ULONG, 1, "of them beyond the list's capacity (the host grows it and redraws)"),
        Field("pixels", ULONG, 1, "pixels covered (inside a triangle, depth in [near, far])"),
        Field("atomics", ULONG, 1, "colour atomics issued"),
        Field("spare", ULONG),
    ], prefix="RS", size="RS_COUNTERS")

CUT_COUNTER = Record(
    "mesh cut counters", "the DAG cut and the skinned meshlets' cull (paramlod.meshlod.cut, skin_cull; "
    "twin paramlod.meshlod.cut_reference); a multi-view cut's per-view counters follow (CUT_COUNTERS + 2v)", [
        Field("selected", ULONG, 1, "(instance, cluster) pairs selected (the selection's length, may pass its capacity)"),
        Field("triangles", ULONG, 1, "their triangles"),
        Field("culled_frustum", ULONG), Field("culled_backface", ULONG),
        Field("tests", ULONG, 1, "clusters tested"),
        Field("spare", ULONG, 3),
    ], prefix="CUT", size="CUT_COUNTERS")

SAMPLER_COUNTER = Record(
    "surfel sampler counters", "farthest and survive (paramlod.surfels.build.sampler)", [
        Field("unreached", UINT, 1, "covered pixels no site reached (must stay 0)"),
        Field("eligible", UINT, 1, "candidates that passed the radius threshold"),
    ], prefix="SMP", size="SMP_COUNTERS")

SURFEL_VIEW = Record(
    "surfel view", "per view of a surfel splat (paramlod.surfels.render.view_records)", [
        Field("xf", FLOAT, 24, "the object's model-view rows (12), then its normal-matrix rows (12: inverse transpose)"),
        Field("inv_proj", FLOAT, 16, "the inverse projection, rows"),
        Field("radius", FLOAT, 1, "the disc radius in view units"),
        Field("mesh_weight", FLOAT, 1, "the hand-off weight of the object's mesh (1: the view draws no surfel)"),
    ], prefix="SFV", size="SF_VIEW_FLOATS")

SURFEL_COUNTER = Record(
    "surfel counters", "per view of a surfel splat (paramlod.surfels.render)", [
        Field("surfels_drawn", ULONG), Field("atomics", ULONG, 1, "colour atomics issued"),
        Field("pixels_covered", ULONG),
        Field("surfels_not_finite", ULONG, 1, "a position, normal or radius not finite (or a radius <= 0)"),
    ], prefix="SF", size="SF_COUNTERS")

RECORDS = (CAMERA, INSTANCE_F, INSTANCE_U, MATERIAL, LIGHT, LOD_COUNTER, EVAL_PATCH, RENDER_PATCH, CLUSTER, GRID_VERTEX,
           POINTS_COUNTER, OCC_COUNTER, LFB_COUNTER, RASTER_COUNTER, CUT_COUNTER, SAMPLER_COUNTER, SURFEL_VIEW,
           SURFEL_COUNTER)

# Constants the host and the kernels share that belong to no record: work-group sizes the host
# launches with and the kernels declare (reqd_work_group_size, __local arrays).
LAUNCH = (Constant("LOD_LOCAL", 32, False, "work-items measuring one LOD patch together"),)



def constant(name: str) -> int:
    """The value of a record's constant or a launch constant, by its (OpenCL) name."""
    return next(c.value for c in (*LAUNCH, *(c for r in RECORDS for c in r.constants)) if c.name == name)


# --- the host's names ---------------------------------------------------------------------------
CAMERA_FLOATS = CAMERA.length


def camera_record(camera) -> np.ndarray:
    """The camera record of ``camera`` (a paramlod Camera), float32 (CAMERA_FLOATS,)."""
    rec = np.zeros(CAMERA.length, np.float32)
    rec[CAMERA.slice("view")] = camera.view.reshape(-1)
    rec[CAMERA.slice("proj")] = camera.projection.reshape(-1)
    rec[CAMERA.offset("w")] = camera.width
    rec[CAMERA.offset("h")] = camera.height
    rec[CAMERA.offset("near")] = camera.near
    rec[CAMERA.offset("far")] = camera.far
    return rec


def vertex_format(record: Record, fields) -> str:
    """The moderngl vertex format that reads ``fields`` (in record order) of a struct record as
    vertex attributes and skips the rest, e.g. "4f 16x 4f 1u 12x" for range, ext, inst of a
    RenderPatch."""
    fields = list(fields)
    names = [f.name for f in record.fields]
    if [n for n in names if n in fields] != fields:
        raise ValueError(f"fields {fields} are not fields of {record.name} in record order ({names})")
    parts, skip = [], 0
    for f in record.fields:
        if f.name in fields:
            if skip:
                parts.append(f"{skip}x")
                skip = 0
            parts.append(f"{f.count}{_MODERNGL[f.type]}")
        else:
            skip += 4 * f.count
    if skip:
        parts.append(f"{skip}x")
    return " ".join(parts)


def _launch(glsl: bool) -> list[str]:
    pre = "PL_" if glsl else ""
    return [f"#define {pre}{c.name} {c.value}{'u' if glsl or c.unsigned else ''}   // {c.doc}" for c in LAUNCH]


_BANNER = ("// ---- generated by paramlod.core.layouts.{0}(): the CPU<->GPU records (paramlod/core/layouts.py),\n"
           "// the shading model (paramlod/core/shading.py){1}. Do not copy these by hand.")


@lru_cache(maxsize=None)
def cl_prelude() -> str:
    """The OpenCL C prelude: every record's offsets, sizes, constants and structs, the shading
    model's constants and the sRGB encoding table (made once: the same text for every program)."""
    parts = [_BANNER.format("cl_prelude", " and the sRGB table (paramlod/core/color.py)")]
    parts += [r.emit(glsl=False) for r in RECORDS]
    parts.append("\n".join(["// launch constants", *_launch(False)]))
    parts.append(shading.prelude(glsl=False))
    parts.append(color.cl_tables())
    parts.append("// ---- end of the prelude\n")
    return "\n\n".join(parts)


@lru_cache(maxsize=None)
def glsl_prelude() -> str:
    """The GLSL 4.50 prelude (after ``#version``): the same records with ``PL_`` names and ``u``
    integers, their structs in std430-compatible form, and the shading model's constants."""
    parts = [_BANNER.format("glsl_prelude", "")]
    parts += [r.emit(glsl=True) for r in RECORDS]
    parts.append("\n".join(["// launch constants", *_launch(True)]))
    parts.append(shading.prelude(glsl=True))
    parts.append("// ---- end of the prelude\n")
    return "\n\n".join(parts)
