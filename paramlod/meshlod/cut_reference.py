"""numpy twin of the per-frame LOD cut (kernels/meshlod/cut.cl, driven by paramlod.meshlod.cut):
the same float32 operations in the same order, so it selects the same (instance, cluster) pairs
and counts the same counters exactly. Tests compare the two (tests/meshlod/test_cut.py).

Also the host's half of the cut, shared with the driver: ``cut_camera`` turns a camera and a
threshold into the small float32 record the kernel reads (derived once per frame in float64).

The rule, per instance i and cluster c of its mesh (threshold T pixels), for one view:
  draw(c, i) = not proj(error, lod_sphere) > T  and  (parent_error = +inf  or  proj(parent_error, parent_sphere) > T)
  proj(e, S) = 0 if e == 0, else (e * s_i) * K / w(dn)
  dn = max(depth(M_i * centre_S) - r_S * s_i, near),  w(d) = wa * d + wb
with K = P[1][1] * H / 2, wa = -P[3][2], wb = P[3][3] (perspective: w = d; orthographic: w = 1)
and s_i the instance's largest scale. The nearest depth of the sphere makes it conservative; a
child's parent test and its parents' own test read the same floats, so they never disagree.
Then, for drawn clusters: the frustum test (bounding sphere, world centre M_i * c, radius r * s_i,
against the six normalised world planes of P V; culled when wholly outside one), then the
backface cone (instances flagged SIMILAR and ONE_SIDED only: a two-sided material shows its back
faces), tested in object space against the eye brought there by M_i^-1 (facing is invariant
under any invertible model, mirrors included):
culled iff cutoff < 1 and |d| > 0 and dot(d, axis) >= cutoff * |d|, d = apex * E_w - eye_obj,
with the eye homogeneous (E_w = 1 perspective, 0 orthographic: E is then the backward direction).
Instances whose hand-off weight is 0 (paramlod.scene.handoff: their surfels draw every pixel) are
skipped: no pair, no test counted.

Several views (a multi-view frame, paramlod.core.views.Views; ``select_views``): "proj(e, S) > T"
becomes ``exceeds``: proj_v(e, S) > T in some view v whose frustum S meets (S not wholly outside
one of v's planes, the test above on the LOD sphere), or, when S is outside every view, in every
view. That is the largest projected error over the views that see S, or the smallest over all
when none does: a function of (e, S) alone, so the cut stays a cut, and monotone from leaf to
root (a parent's sphere holds its children's: it meets every view they meet, and the smallest
over all views is at most any one view's), so exactly one cluster of each path is drawn, as fine
as the finest any view that sees its group asks for. A drawn cluster is dropped only when every
view culls it (frustum, or backface cone; counted as frustum-culled when every view's frustum
test culls it, else as backface-culled) and is drawn into the views that do not: its view mask,
bit v. With one view this is the rule above exactly.
"""
from __future__ import annotations

import numpy as np

from paramlod.core.layouts import CUT_COUNTER, INSTANCE_F, INSTANCE_U
from paramlod.core.transforms import is_number
from paramlod.core.views import as_views
from paramlod.errors import MeshError

# the counters (8 ulong on the device; the rest are spare zeros)
COUNTERS = tuple(f.name for f in CUT_COUNTER.fields if f.name != "spare")
VIEW_COUNTERS = ("clusters", "triangles")   # per view of a multi-view cut, after the 8
SIMILAR, ONE_SIDED = 1, 4   # MeshInstances flags (paramlod.meshlod.buffers; checked equal in the tests)

# the cut camera record (float32): offsets the kernel gets as -D defines (paramlod.meshlod.cut)
CC_PLANES = 0      # 6 x (nx, ny, nz, d): world planes, inside where n . x + d >= 0, |n| = 1
CC_DEPTH = 24      # 4: depth(x) = d0 x + d1 y + d2 z + d3 (the view's -z row)
CC_EYE = 28        # 4: homogeneous eye in world space (w = 1: a point, w = 0: the backward direction)
CC_K = 32          # P[1][1] * H / 2
CC_WA, CC_WB = 33, 34   # w(d) = wa * d + wb
CC_NEAR = 35
CC_T = 36          # threshold in pixels
CC_FLOATS = 40

_F = np.float32


def check_threshold(threshold_px) -> float:
    """The threshold as a float, or a MeshError that says what is wrong with it."""
    if not is_number(threshold_px):
        raise MeshError(f"cut threshold_px must be a number of pixels >= 0, got {threshold_px!r}")
    t = float(threshold_px)
    if np.isnan(t) or t < 0:
        raise MeshError(f"cut threshold_px must be >= 0 pixels (0 draws the original triangles), got {t}")
    return t


def cut_camera(camera, threshold_px) -> np.ndarray:
    """The kernel's camera record (float32 [CC_FLOATS]) for a paramlod Camera (any with ``view``,
    ``projection``, ``height``, ``near``) and a threshold in pixels."""
    t = check_threshold(threshold_px)
    V = np.asarray(camera.view, np.float64)
    P = np.asarray(camera.projection, np.float64)
    if P.shape != (4, 4) or V.shape != (4, 4) or not (np.isfinite(P).all() and np.isfinite(V).all()):
        raise MeshError("cut: the camera's view and projection must be finite 4x4 matrices")
    if P[3, 0] != 0 or P[3, 1] != 0 or not (P[3, 2] < 0 or (P[3, 2] == 0 and P[3, 3] > 0)):
        raise MeshError("cut: the camera's projection must have the last row (0, 0, -a, b) of a perspective "
                        f"(a > 0) or orthographic (a = 0, b > 0) camera, got {P[3].tolist()}")
    rec = np.zeros(CC_FLOATS, np.float64)
    A = P @ V
    planes = np.stack([A[3] + A[0], A[3] - A[0], A[3] + A[1], A[3] - A[1], A[3] + A[2], A[3] - A[2]])
    planes /= np.linalg.norm(planes[:, :3], axis=1, keepdims=True)
    rec[CC_PLANES:CC_PLANES + 24] = planes.reshape(-1)
    rec[CC_DEPTH:CC_DEPTH + 4] = -V[2]
    # the camera centre is the null point of P's last row: (0, 0, b, a) in view space
    eye = np.linalg.solve(V, np.array([0.0, 0.0, P[3, 3], -P[3, 2]]))
    eye = eye / eye[3] if P[3, 2] != 0 else np.append(eye[:3] / np.linalg.norm(eye[:3]), 0.0)
    rec[CC_EYE:CC_EYE + 4] = eye
    rec[CC_K] = P[1, 1] * float(camera.height) / 2
    rec[CC_WA], rec[CC_WB] = -P[3, 2], P[3, 3]
    rec[CC_NEAR] = camera.near
    rec[CC_T] = t
    return rec.astype(np.float32)


def cut_cameras(camera, threshold_px) -> np.ndarray:
    """The records of every view (float32 [N * CC_FLOATS], one after another) of a Camera (N = 1)
    or a Views."""
    return np.concatenate([cut_camera(c, threshold_px) for c in as_views(camera)])


# --- the twin's float32 arithmetic, in the kernel's order ----------------------------------------
def _point(m, p):
    """Rows 0-2 of row-major 4x4 matrices ``m`` [n, 16] applied to points ``p`` [c, 3]: [n, c, 3]."""
    x, y, z = (p[None, :, k] for k in range(3))
    return np.stack([((m[:, None, 4 * r] * x + m[:, None, 4 * r + 1] * y) + m[:, None, 4 * r + 2] * z)
                     + m[:, None, 4 * r + 3] for r in range(3)], axis=-1)


def projected_error(e, sphere, model, s, cc):
    """Projected errors in pixels [n, c] of object-space errors ``e`` float32 [c] around spheres
    ``sphere`` [c, 4] for instances of models ``model`` float32 [n, 16] (row-major) and largest
    scales ``s`` [n], with ``cc`` = cut_camera(...): the values the kernel compares with the threshold."""
    w = _point(model, sphere[:, :3])
    d = cc[CC_DEPTH:CC_DEPTH + 4]
    depth = ((d[0] * w[..., 0] + d[1] * w[..., 1]) + d[2] * w[..., 2]) + d[3]
    dn = np.fmax(depth - sphere[None, :, 3] * s[:, None], cc[CC_NEAR])
    wd = cc[CC_WA] * dn + cc[CC_WB]
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        p = ((e[None, :] * s[:, None]) * cc[CC_K]) / wd
    return np.where(e[None, :] == 0, _F(0), p)


def planes_outside(w, r, cc):
    """kernels/meshlod/cut_common.cl's planes_outside: spheres of world centres ``w`` = (x, y, z)
    arrays and radii ``r`` wholly outside one of the six planes of ``cc``."""
    out = np.zeros(np.broadcast(w[0], r).shape, bool)
    for k in range(6):
        n = cc[CC_PLANES + 4 * k:CC_PLANES + 4 * k + 4]
        dist = ((n[0] * w[0] + n[1] * w[1]) + n[2] * w[2]) + n[3]
        out |= dist < -r
    return out


def _frustum_culled(sphere, model, s, cc):
    w = _point(model, sphere[:, :3])
    return planes_outside((w[..., 0], w[..., 1], w[..., 2]), sphere[None, :, 3] * s[:, None], cc)


def _backface_culled(apex, cone, model, normal, cc):
    e = cc[CC_EYE:CC_EYE + 4]
    # M^-1 (E_xyz, E_w) = N^T (E_xyz - E_w t): N is the normal matrix (rows of 4), N^T = M3^-1
    u = [e[k] - e[3] * model[:, 4 * k + 3] for k in range(3)]
    eo = [(normal[:, a] * u[0] + normal[:, 4 + a] * u[1]) + normal[:, 8 + a] * u[2] for a in range(3)]
    d = [apex[None, :, k] * e[3] - eo[k][:, None] for k in range(3)]
    length = np.sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2])
    dot = (d[0] * cone[None, :, 0] + d[1] * cone[None, :, 1]) + d[2] * cone[None, :, 2]
    cutoff = cone[None, :, 3]
    return (cutoff < 1) & (length > 0) & (dot >= cutoff * length)


def exceeds(e, sphere, model, s, ccs, T):
    """bool [n, c]: the multi-view projected error of errors ``e`` around spheres ``sphere`` (as
    ``projected_error``) exceeds T, for the views of records ``ccs`` (a list of cut_camera records)."""
    above = np.stack([projected_error(e, sphere, model, s, cc) > T for cc in ccs])
    if len(ccs) == 1:
        return above[0]
    w = _point(model, sphere[:, :3])
    seen = ~np.stack([planes_outside((w[..., 0], w[..., 1], w[..., 2]), sphere[None, :, 3] * s[:, None], cc)
                      for cc in ccs])
    return np.where(seen.any(axis=0), (seen & above).any(axis=0), above.all(axis=0))


def select(arrays, instances, camera, threshold_px, cull_frustum=True, cull_backface=True, weights=None):
    """The cut of every batch of ``instances`` (paramlod.meshlod.buffers.MeshInstances) over the
    clusters of ``arrays`` (MeshArrays); ``weights``: the instances' hand-off weights (None: all 1).
    Returns (pairs uint32 [n, 2] of (instance, cluster), sorted by instance then cluster;
    counters {name: int} with the names of COUNTERS)."""
    pairs, _, counts = select_views(arrays, instances, camera, threshold_px, cull_frustum, cull_backface, weights)
    counts.pop("views")
    return pairs, counts


def select_views(arrays, instances, cameras, threshold_px, cull_frustum=True, cull_backface=True, weights=None):
    """``select`` for the views of ``cameras`` (a Camera or a paramlod.core.views.Views): (pairs,
    view masks uint64 [n] (bit v: drawn into view v), counters: COUNTERS and "views", per view
    {"clusters", "triangles"} drawn into it)."""
    ccs = [cut_camera(c, threshold_px) for c in as_views(cameras)]
    live_all = np.ones(len(instances.inst_f), bool) if weights is None else np.asarray(weights, _F) > 0
    T = ccs[0][CC_T]
    counts = dict.fromkeys(COUNTERS, 0)
    pairs, masks = [], []
    f_model = INSTANCE_F.slice("model")
    f_normal = INSTANCE_F.slice("normal")
    u_flags = INSTANCE_U.offset("flags")
    for mesh, i0, ni in instances.batches:
        c0, nc = (int(x) for x in arrays.ranges[mesh])
        if nc == 0 or ni == 0:
            continue
        cl = arrays.clusters[c0:c0 + nc]
        model = np.ascontiguousarray(instances.inst_f[i0:i0 + ni, f_model], _F)
        normal = np.ascontiguousarray(instances.inst_f[i0:i0 + ni, f_normal], _F)
        s = np.asarray(instances.scales[i0:i0 + ni], _F)
        live = live_all[i0:i0 + ni]
        counts["tests"] += int(live.sum()) * nc
        own = ~exceeds(cl["error"], cl["lod_sphere"], model, s, ccs, T)
        par = np.isinf(cl["parent_error"])[None, :] | exceeds(cl["parent_error"], cl["parent_sphere"], model, s, ccs, T)
        draw = own & par & live[:, None]
        cones = (instances.inst_u[i0:i0 + ni, u_flags] & (SIMILAR | ONE_SIDED)) == (SIMILAR | ONE_SIDED)
        mask = np.zeros(draw.shape, np.uint64)
        all_outside = np.ones(draw.shape, bool)
        for v, cc in enumerate(ccs):
            outside = _frustum_culled(cl["sphere"], model, s, cc) if cull_frustum else np.zeros(draw.shape, bool)
            back = ~outside & cones[:, None] & _backface_culled(cl["cone_apex"], cl["cone"], model, normal, cc) \
                if cull_backface else np.zeros(draw.shape, bool)
            mask |= np.where(~outside & ~back, np.uint64(1 << v), np.uint64(0))
            all_outside &= outside
        append_selected(draw, mask, all_outside, cl["count"], i0, c0, counts, pairs, masks)
    return sort_views(pairs, masks, counts, len(ccs), arrays.clusters["count"])


def append_selected(draw, mask, all_outside, triangles, i0, c0, counts, pairs, masks) -> None:
    """One batch's selection (instances x clusters from i0, c0): the pairs to draw (``draw`` and
    seen by some view of ``mask``) and their view masks appended, the culled ones counted as
    frustum-culled (``all_outside``: outside every view) or back-face-culled; ``triangles`` per
    cluster of the batch. Shared with the skinned cull's twin."""
    dropped = draw & (mask == 0)
    counts["culled_frustum"] += int((dropped & all_outside).sum())
    counts["culled_backface"] += int((dropped & ~all_outside).sum())
    ii, cc_ = np.nonzero(draw & ~dropped)
    counts["selected"] += len(ii)
    counts["triangles"] += int(np.asarray(triangles)[cc_].astype(np.int64).sum())
    pairs.append(np.stack([ii + i0, cc_ + c0], axis=1).astype(np.uint32))
    masks.append(mask[ii, cc_])


def sort_views(pairs, masks, counts, n_views, cluster_counts):
    """(pairs, masks, counts) of a cut (lists of per-batch pairs and masks), sorted by instance
    then cluster, with counts["views"] made from the masks (also the skinned cull's twin's)."""
    out = np.concatenate(pairs) if pairs else np.zeros((0, 2), np.uint32)
    m = np.concatenate(masks) if masks else np.zeros(0, np.uint64)
    order = np.lexsort((out[:, 1], out[:, 0]))
    out, m = out[order], m[order]
    tris = np.asarray(cluster_counts, np.int64)[out[:, 1]]
    counts["views"] = [{"clusters": int(on.sum()), "triangles": int(tris[on].sum())}
                       for on in (((m >> np.uint64(v)) & np.uint64(1)) != 0 for v in range(n_views))]
    return out, m, counts
