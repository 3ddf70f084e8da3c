"""How a render patch is sampled by the point renderers (kit shared by the direct and the
local-framebuffer variants; kernels/points/points.cl side_count()).

Per patch side, ``ceil(m * factor) + 1`` samples, where ``m`` is the measure chosen by
``sampling`` ("segment": s_u, s_v = 7 x the longest LOD segment; "extent": the thesis's measured
polyline extents e_u, e_v) and ``factor = density * oversample / (1 - epsilon)`` (docs/points.md).
The direct variant sizes "segment" patches from w_u, w_v as well: s_u, s_v raised to what the
patch's four boundary lines need (the LOD stage measures them, kernels/lod/lod.cl). Where w > s,
the outer seventh of the patch at each end is stepped for w and the rest for s (boundary strips,
``grid_axes``), so that two patches sharing an edge both cover it at about 2/7 of the cost of a
whole grid for w; the supersampled local-framebuffer variant has no holes to close and keeps s_u, s_v.
A uniform grid that spans the domain along an axis over which the function repeats (its
``periodic``) does not draw its last line, a copy of its first (``patch_wraps``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from paramlod.core.debug_colors import cluster_color, level_color, tier_color
from paramlod.core.hashing import hash32
from paramlod.core.transforms import in_range
from paramlod.errors import SceneError
from paramlod.lod.patches import render_tiers
from paramlod.lod.uploads import WRAP_U, WRAP_V

SAMPLING = ("segment", "extent")
# the direct variant's colouring (kernels/points/points.cl debug_material): the material, a colour
# per render patch, a colour per LOD step, a colour per hybrid tier
COLOR_BY = ("material", "patch", "level", "tier")
COVERAGE = ("centre", "pixel", "quad")   # PointSettings.coverage
# thin tubes (points.cl patch_axes): loops around of at most THIN_LOOP_1 target pixels drawn with
# one line around, of at most THIN_LOOP_2 (a tube under a pixel across) with two, then 3 and 5
THIN_LOOP_1, THIN_LOOP_2 = np.float32(2), np.float32(3)
THIN_LOOP_3, THIN_LOOP_5 = np.float32(4), np.float32(5.35)
THIN_ALONG = np.float32(1.2)   # samples per target pixel along loops of 1 to THIN_LOOP_2 (points.cl)
POINTS_LOCAL = 64   # work-group size of points_direct (points.cl reqd_work_group_size)
# the kernels' `measure` argument (kernels/points/points.cl patch_measure): which RenderPatch
# columns a grid is sized from
MEASURE_SEGMENT, MEASURE_EXTENT, MEASURE_BOUNDARY = 0, 1, 2


@dataclass
class PointSettings:
    density: float = 1.5    # samples per pixel of s_u, s_v: spacing <= 0.67 px < 1/sqrt(2), no holes at any angle
    widen: float = 0.005    # parameter range enlarged by this fraction per side (no seams)
    max_side: int = 1024    # samples per side at most; patches that hit it are counted in stats
    # what the sample counts are measured from: "segment" (s_u, s_v; hole-free default) or
    # "extent" (e_u, e_v: the thesis's adaptive sampling, fewer samples, may leave 1-px holes)
    sampling: str = "segment"
    oversample: float = 1.0  # fixed oversampling factor on top of density (thesis Fig. 5.17: 1x, 2x, 3x)
    epsilon: float = 0.0     # step shrink: sample steps are (1 - epsilon) x the nominal step
    # anti-aliasing of the direct variant: render into keys supersample x the frame's size, then
    # resolve each block (colour averaged over covered subsamples, alpha = coverage); 1 = off
    supersample: int = 1
    # aa = "hybrid": patches drawn into 1x, 4xSS or 16xSS key buffers as the LOD stage's spot
    # check finds sub-pixel detail (paramlod.renderers.aa.POINT_TIERS); supersample is then unused
    hybrid: bool = False
    # the direct variant's debug colouring: "patch", "level" (LOD step) or "tier" (hybrid tier)
    color_by: str = "material"
    # the direct variant's two-phase occlusion culling of render patches (docs/points.md, the
    # same keys with fewer samples; single-view frames only): True always, False never, "auto"
    # while it saves enough samples to pay (paramlod/renderers/points.py AutoOcclusion)
    occlusion: bool | str = "auto"
    # the direct variant's coverage: "pixel", a sample covers the pixel it lands in (the thesis's
    # rule: silhouettes grown by up to a pixel), or "centre", the pixels whose centres its grid
    # cell holds (silhouettes as a triangle's, but rare 1-pixel holes where the surface curves
    # sharply; docs/points.md, "Pixel-centre coverage"), or "quad", the pixels whose centres the
    # quads between neighbouring samples hold (a mesh of the sample grid, rasterized: silhouettes
    # as its polygon's; docs/points.md, "Quad coverage")
    coverage: str = "pixel"
    # the direct variant with pixel coverage: a patch around which the surface closes (a periodic
    # axis spanned whole) in a loop of at most 3 pixels (a tube under a pixel across) is drawn as a
    # curve: one line around (two over 2 pixels), and samples under a pixel apart along it where
    # the loop is at least a pixel (points.cl patch_axes; docs/points.md, "Thin tubes"). False:
    # sampled as any surface
    thin_tubes: bool = True

    def validate(self):
        if not in_range(self.density, 0.1, 16):
            raise SceneError(f"points density must be in [0.1, 16] samples per pixel, got {self.density}")
        if not in_range(self.widen, 0, 0.25):
            raise SceneError(f"points widen must be in [0, 0.25], got {self.widen}")
        if not in_range(self.max_side, 2, 8192):
            raise SceneError(f"points max_side must be in [2, 8192], got {self.max_side}")
        if self.sampling not in SAMPLING:
            raise SceneError(f"points sampling must be one of {', '.join(SAMPLING)}, got {self.sampling!r}")
        if not in_range(self.oversample, 1, 8):
            raise SceneError(f"points oversample must be in [1, 8], got {self.oversample}")
        if not in_range(self.epsilon, 0, 0.9):
            raise SceneError(f"points epsilon (step shrink) must be in [0, 0.9], got {self.epsilon}")
        if self.supersample not in (1, 2, 3, 4) or isinstance(self.supersample, bool):
            raise SceneError(f"points supersample must be 1 (off), 2, 3 or 4 subsamples per pixel side, "
                             f"got {self.supersample!r}")
        if not isinstance(self.hybrid, (bool, np.bool_)):
            raise SceneError(f"points hybrid must be true or false, got {self.hybrid!r}")
        if not (isinstance(self.occlusion, bool) or self.occlusion == "auto"):
            raise SceneError(f"points occlusion must be true, false or \"auto\", got {self.occlusion!r}")
        if self.coverage not in COVERAGE:
            raise SceneError(f"points coverage must be one of {', '.join(COVERAGE)}, got {self.coverage!r}")
        if not isinstance(self.thin_tubes, (bool, np.bool_)):
            raise SceneError(f"points thin_tubes must be true or false, got {self.thin_tubes!r}")
        if self.color_by not in COLOR_BY:
            raise SceneError(f"points color_by must be one of {', '.join(COLOR_BY)}, got {self.color_by!r}")

    def factor(self, scale: float = 1.0) -> np.float32:
        """Samples per measured pixel along each side, as the kernel receives it (float32);
        ``scale``: target pixels per measured pixel (a hybrid tier's supersampling)."""
        return np.float32(self.density * self.oversample * scale / (1.0 - self.epsilon))

    def curve_factor(self, scale: float = 1.0) -> np.float32:
        """The kernels' ``curve``: target pixels per measured pixel (``factor`` without ``density``;
        thin tubes are sampled THIN_ALONG times that along), 0 where thin tubes are off
        (``thin_tubes`` False, or a coverage other than "pixel", whose cells would lose the tube's
        width)."""
        if not self.thin_tubes or self.coverage != "pixel":
            return np.float32(0)
        return np.float32(self.oversample * scale / (1.0 - self.epsilon))

    @property
    def use_extent(self) -> bool:
        return self.sampling == "extent"

    def measure(self, boundary: bool) -> np.uint32:
        """The kernels' ``measure``: extents, or segments (raised to the boundary lines' need
        where ``boundary``, the direct variant)."""
        if self.use_extent:
            return np.uint32(MEASURE_EXTENT)
        return np.uint32(MEASURE_BOUNDARY if boundary else MEASURE_SEGMENT)


def side_counts(ext: np.ndarray, settings: PointSettings, factor=None) -> np.ndarray:
    """numpy twin of side_count() in points.cl: samples per side for each measure in ``ext``
    (``factor``: float32 scalar or per-measure array; default ``settings.factor()``)."""
    factor = settings.factor() if factor is None else np.asarray(factor, np.float32)
    n = np.ceil(np.asarray(ext).astype(np.float32) * factor) + np.float32(1)
    with np.errstate(invalid="ignore"):
        capped = ~(n < np.float32(settings.max_side))
    return np.where(capped, settings.max_side, np.maximum(np.nan_to_num(n), 2)).astype(np.int64)


def patch_measures(render_list: np.ndarray, measure) -> np.ndarray:
    """Twin of patch_measure() in points.cl: float32 (n, 2) measures of each render patch."""
    if int(measure) == MEASURE_BOUNDARY:
        return np.ascontiguousarray(render_list["w"])   # w_u, w_v
    ext = render_list["ext"]
    return ext[:, 0:2] if int(measure) == MEASURE_EXTENT else ext[:, 2:4]


def grid_axes(s: np.ndarray, w: np.ndarray, boundary: bool, settings: PointSettings, factor=None):
    """Twin of grid_axis() in points.cl: (n, na, nm) int64 arrays for one grid direction, from the
    interior measure ``s`` and the sizing measure ``w``. na = 0: uniform, n samples; else boundary
    strips of na steps at each end (the outer sevenths, stepped for w) and nm middle steps (for s).
    ``factor``: samples per measured pixel (scalar or per patch; default ``settings.factor()``)."""
    f32 = np.float32
    s, w = np.asarray(s, f32), np.asarray(w, f32)
    factor = settings.factor() if factor is None else np.asarray(factor, f32)
    n = side_counts(w, settings, factor)
    na = np.zeros(n.shape, np.int64)
    nm = np.zeros(n.shape, np.int64)
    if not boundary:
        return n, na, nm
    with np.errstate(invalid="ignore", over="ignore"):
        fa = (w * factor).astype(f32)
        fa = (fa * f32(1.0 / 7.0)).astype(f32)
        fm = (s * factor).astype(f32)
        fm = (fm * f32(5.0 / 7.0)).astype(f32)
        ca = np.fmax(np.ceil(fa), f32(1))
        cm = np.fmax(np.ceil(fm), f32(1))
        total = (f32(2) * ca + cm + f32(1)).astype(f32)
        strips = (w > s) & (n < settings.max_side) & (total < f32(settings.max_side)) & ~(total >= n.astype(f32))
    na[strips] = ca[strips].astype(np.int64)
    nm[strips] = cm[strips].astype(np.int64)
    n = n.copy()
    n[strips] = total[strips].astype(np.int64)   # only finite counts are cast
    return n, na, nm


def patch_wraps(render_list: np.ndarray, flags: np.ndarray, domains: np.ndarray) -> np.ndarray:
    """Twin of patch_wraps() in points.cl: bool (n, 2), whether each render patch spans its
    instance's domain along an axis (u, v) over which its function repeats. ``flags``: the
    instances' INST_U flags (INST_WRAP_U / _V); ``domains``: their (u0, u1, v0, v1)."""
    inst = render_list["inst"]
    rng = render_list["range"]
    dom = np.asarray(domains, np.float32)[inst]
    f = np.asarray(flags, np.uint32)[inst]
    return np.stack([((f & bit) != 0) & (rng[:, 2 * k] == dom[:, 2 * k]) & (rng[:, 2 * k + 1] == dom[:, 2 * k + 1])
                     for k, bit in enumerate((WRAP_U, WRAP_V))], axis=1)


def thin_lines(loop: np.ndarray) -> np.ndarray:
    """Twin of points.cl thin_lines: grid lines around a thin tube whose loop measures ``loop``
    target pixels (1, 2, 3 or 5 lines around, and the wrapped copy)."""
    return np.select([loop <= t for t in (THIN_LOOP_1, THIN_LOOP_2, THIN_LOOP_3)], [2, 3, 4], 6)


def grid_counts(render_list: np.ndarray, settings: PointSettings, boundary: bool = True,
                wraps: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(nu, nv) samples drawn per render patch, from the measure ``settings.sampling`` selects: as
    the direct variant samples (``boundary``: segment patches with boundary strips, grid_axes) or
    as the local-framebuffer variant (``boundary=False``). ``wraps``: ``patch_wraps`` of the list
    (None: no patch wraps), whose uniform grids draw one line fewer; the direct variant draws the
    thin tubes among them as curves (``PointSettings.thin_tubes``, points.cl patch_axes)."""
    code = settings.measure(boundary)
    m = patch_measures(render_list, code)
    strips = int(code) == MEASURE_BOUNDARY
    ext = render_list["ext"]
    factor, curve = settings.factor(), settings.curve_factor() if boundary else np.float32(0)
    thin = np.zeros((len(render_list), 2), bool)   # patch_axes: the thin tubes' axis around
    loop = np.zeros(m.shape, np.float32)            # target pixels around
    if wraps is not None and curve > 0:
        with np.errstate(invalid="ignore", over="ignore"):   # inf and NaN measures: no thin tubes
            loop = (m * curve).astype(np.float32)
        small = wraps & (loop <= THIN_LOOP_5)
        thin[:, 1] = small[:, 1]
        thin[:, 0] = small[:, 0] & ~small[:, 1]
    out = []
    for k in range(2):   # sampled along at THIN_ALONG x `curve` where the loop around is 1 to 3 pixels
        around = loop[:, 1 - k]
        curve_along = thin[:, 1 - k] & (around >= np.float32(1)) & (around <= THIN_LOOP_2)
        along = np.where(curve_along, min(factor, THIN_ALONG * curve), factor).astype(np.float32)
        n, na, _ = grid_axes(ext[:, 2 + k], m[:, k], strips, settings, along)
        n = np.where(thin[:, k], np.minimum(n, thin_lines(loop[:, k])), n)
        if wraps is None:
            out.append(n)
            continue
        wrap = wraps[:, k] & ((na == 0) | thin[:, k])
        if boundary and settings.coverage == "quad":   # 3 lines around a tube at least
            n = np.where(wrap, np.maximum(n, min(4, settings.max_side)), n)
        out.append(n - wrap)
    return out[0], out[1]


def patch_debug_materials(render_list: np.ndarray, materials: np.ndarray, color_by: str) -> np.ndarray:
    """numpy twin of debug_material() in points.cl: float32 [n, 4] material of each render patch
    (RGB replaced by the patch's or its LOD step's debug colour; ``materials`` per instance)."""
    m = np.asarray(materials, np.float32)[render_list["inst"]].copy()
    if color_by == "patch":
        r = np.ascontiguousarray(render_list["range"], np.float32).view(np.uint32)
        key = hash32(r[:, 0] ^ hash32(r[:, 2] ^ hash32(render_list["inst"].astype(np.uint32))))
        m[:, :3] = cluster_color(key)
    elif color_by == "level":
        m[:, :3] = level_color(render_list["flags"] & np.uint32(15))
    elif color_by == "tier":
        m[:, :3] = tier_color(render_tiers(render_list))
    return m


# --- pixel-centre coverage (PointSettings.coverage "centre") ------------------------------------
COVER_REACH = 2         # pixels from the sample's own that a cell may reach
COVER_OWN = 0x80000000  # the cell is degenerate: the sample covers its own pixel


def points_cl_defines() -> dict:
    """The constants kernels/points/points.cl is built with (paramlod.device.programs.build): this
    module's, so that the kernels and their numpy twins here read one source."""
    return {"THIN_LOOP_1": THIN_LOOP_1, "THIN_LOOP_2": THIN_LOOP_2, "THIN_LOOP_3": THIN_LOOP_3,
            "THIN_LOOP_5": THIN_LOOP_5, "THIN_ALONG": THIN_ALONG,
            "COVER_REACH": COVER_REACH, "COVER_OWN": f"{COVER_OWN:#x}u", "POINTS_LOCAL": POINTS_LOCAL}


def _ceil_small(t):
    i = t.astype(np.int32)   # towards zero, as (int) in C
    return np.where(i.astype(np.float32) < t, i + 1, i)


def _floor_small(t):
    i = t.astype(np.int32)
    return np.where(i.astype(np.float32) > t, i - 1, i)


def cover_cells(x, y, ju, jv, lo, hi, size) -> np.ndarray:
    """numpy twin of cover_cells() in kernels/points/points.cl, float32 in the kernel's order: for
    samples placed at screen (x, y) with screen Jacobian columns ``ju``, ``jv`` ((n, 2) pixels per
    unit u, v) and cells [-lo, hi] ((n, 2) parameter offsets along u, v), the uint32 mask of the
    pixel centres each cell holds, bit (dy + 2) * 5 + (dx + 2) for the pixel (dx, dy) from the
    sample's own, up to COVER_REACH pixels away, inside the image ``size`` (W, H); COVER_OWN for a
    degenerate or not finite cell."""
    f = np.float32
    x, y = np.asarray(x, f), np.asarray(y, f)
    ju, jv, lo, hi = (np.asarray(a, f) for a in (ju, jv, lo, hi))
    with np.errstate(all="ignore"):
        det = ju[:, 0] * jv[:, 1] - ju[:, 1] * jv[:, 0]
        ju2, jv2 = ju[:, 0] * ju[:, 0] + ju[:, 1] * ju[:, 1], jv[:, 0] * jv[:, 0] + jv[:, 1] * jv[:, 1]
        ok = det * det > f(1e-12) * ju2 * jv2
        box = []
        for k in (0, 1):   # x, then y: the cell's screen extent from the sample
            a0, a1 = ju[:, k] * -lo[:, 0], ju[:, k] * hi[:, 0]
            b0, b1 = jv[:, k] * -lo[:, 1], jv[:, k] * hi[:, 1]
            box.append((np.where(a0 < a1, a0, a1) + np.where(b0 < b1, b0, b1),
                        np.where(a0 < a1, a1, a0) + np.where(b0 < b1, b1, b0)))
        px, py = x.astype(np.int32), y.astype(np.int32)
        fx, fy = x - px.astype(f) - f(0.5), y - py.astype(f) - f(0.5)
        bx0, bx1, by0, by1 = fx + box[0][0], fx + box[0][1], fy + box[1][0], fy + box[1][1]
        reach = f(COVER_REACH + 1)
        ok &= (bx0 <= bx1) & (by0 <= by1)
        bx0, by0 = (np.where(ok, np.where(b > -reach, b, -reach), f(0)) for b in (bx0, by0))
        bx1, by1 = (np.where(ok, np.where(b < reach, b, reach), f(0)) for b in (bx1, by1))
        x0, y0 = (np.maximum(_ceil_small(b), -COVER_REACH) for b in (bx0, by0))
        x1, y1 = (np.minimum(_floor_small(b), COVER_REACH) for b in (bx1, by1))
        idet = f(1) / det
        bits = np.zeros(len(x), np.uint32)
        w, h = size
        for dy in range(-COVER_REACH, COVER_REACH + 1):
            for dx in range(-COVER_REACH, COVER_REACH + 1):
                qx, qy = f(dx) - fx, f(dy) - fy
                a = (qx * jv[:, 1] - qy * jv[:, 0]) * idet
                b = (ju[:, 0] * qy - ju[:, 1] * qx) * idet
                inside = ((a >= -lo[:, 0]) & (a <= hi[:, 0]) & (b >= -lo[:, 1]) & (b <= hi[:, 1])
                          & (px + dx >= 0) & (px + dx < w) & (py + dy >= 0) & (py + dy < h)
                          & (dx >= x0) & (dx <= x1) & (dy >= y0) & (dy <= y1))
                bit = np.uint32(1 << ((dy + COVER_REACH) * (2 * COVER_REACH + 1) + dx + COVER_REACH))
                bits |= np.where(inside, bit, np.uint32(0))
    return np.where(ok, bits, np.uint32(COVER_OWN)).astype(np.uint32)


# --- quad coverage (PointSettings.coverage "quad") ----------------------------------------------
def _edge(ax, ay, bx, by, qx, qy):
    return (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)


def cover_triangle(a, b, c, size) -> tuple[np.ndarray, np.ndarray]:
    """numpy twin of cover_triangle() in kernels/points/points.cl, float32 in the kernel's order,
    for one triangle whose corners ``a``, ``b``, ``c`` are (x, y, depth) in pixels: the pixel
    indices (y * W + x, ascending) whose centres it holds inside the image ``size`` (W, H), edges
    included, either winding, none without area; and the float32 depth interpolated at each."""
    f = np.float32
    (ax, ay, ad), (bx, by, bd), (cx, cy, cd) = (np.asarray(p, f) for p in (a, b, c))
    w, h = size
    none = np.zeros(0, np.int64), np.zeros(0, f)
    with np.errstate(all="ignore"):
        area = _edge(ax, ay, bx, by, cx, cy)
        if not area != 0:
            return none
        x0 = np.fmax(np.ceil(min(ax, bx, cx) - f(0.5)), f(0))
        x1 = np.fmin(np.floor(max(ax, bx, cx) - f(0.5)), f(w) - f(1))
        y0 = np.fmax(np.ceil(min(ay, by, cy) - f(0.5)), f(0))
        y1 = np.fmin(np.floor(max(ay, by, cy) - f(0.5)), f(h) - f(1))
        if not (x0 <= x1 and y0 <= y1):
            return none
        py, px = np.meshgrid(np.arange(y0, y1 + 1, dtype=f), np.arange(x0, x1 + 1, dtype=f), indexing="ij")
        qx, qy = px + f(0.5), py + f(0.5)
        wa, wb, wc = _edge(bx, by, cx, cy, qx, qy), _edge(cx, cy, ax, ay, qx, qy), _edge(ax, ay, bx, by, qx, qy)
        inside = ((wa >= 0) & (wb >= 0) & (wc >= 0)) | ((wa <= 0) & (wb <= 0) & (wc <= 0))
        inv = f(1) / area
        depth = (wa * inv) * ad + (wb * inv) * bd + (wc * inv) * cd
    pix = (py.astype(np.int64) * w + px.astype(np.int64))[inside]
    return pix.reshape(-1), depth[inside].astype(f).reshape(-1)
