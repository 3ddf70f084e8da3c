"""Conservative meshlet bounds of a linear-blend-skinned mesh over its whole animation clip, for
culling the animated meshlets (the method of chapter 4 of the dissertation digest in
/work/shared/reference/dissertation-and-multires.md): ``skin_bounds(mesh, settings) -> SkinBounds``.

Driven offline by the skinned source (paramlod.meshlod.skinned.SkinnedMesh) and its users; the run
time half is paramlod.meshlod.skin_cull (kernel kernels/meshlod/skin_cull.cl, numpy twin
paramlod.meshlod.skin_cull_reference), which reads only what SkinBounds stores. No twin (host only):
tests/meshlod/test_skin_bounds.py checks the bounds against posed meshes at sampled times.

What is stored (per meshlet c of ``mesh.clusters``) and the run-time rule it guarantees:
  principal[c]    the joint with the largest sum of weights over the meshlet's vertices;
  sphere[c]       (centre, radius) around the meshlet's bind-pose vertices, mesh space;
  radius_scale    s_r, one float for the mesh: at every time t of the clip, every skinned vertex p(t)
                  of every meshlet of class 0 or 1 satisfies |p(t) - M_p(t) c| <= ||M_p(t)|| r s_r,
                  M_p(t) = rig.skin_matrices(t)[principal], ||.|| its largest singular value;
  cone[c]         (n_m, cos alpha_max): in the principal joint's space (PBS, q = M_p(t)^-1 p) every
                  triangle normal (q2 - q1) x (q3 - q2) is within alpha_max < 90 deg of n_m at every
                  t; w = -2 where no cone is claimed (classes 1 and 2);
  classes[c]      0: r s_r bound holds with the meshlet's own need <= settings.max_radius_scale and
                  alpha_max <= settings.max_cone_angle_deg (frustum + backface culling); 1: only the
                  radius bound holds (frustum only); 2: neither (never culled);
  intervals       the (sub)interval boundaries the bounds were made over; ``stats`` the numbers.

How (all in float64, every step conservative, i.e. a superset of the true set):
* Time: the clip is cut at the union of its keyframe times; a bound covers [t_a, t_b) of one
  interval (channels that STEP hold their value there; the other channels' bound also holds at t_b),
  plus a last point interval at the clip's end when a channel steps; times outside the clip clamp.
* Per node and interval the local motion is: translation and scale in boxes [lo, hi] (LINEAR: the
  two end values; STEP: the held value; CUBICSPLINE: the Hermite cubic's exact range, from the roots
  of its derivative); rotation = R_ref * Rot(axis, phi), phi in [0, theta] (LINEAR: slerp on the
  shorter arc as paramlod.meshlod.skinned.slerp does, which is a rotation about one fixed axis with
  a linearly growing angle; a nearly-equal pair is lerped and normalised there, which stays on the
  same great arc) times a deviation of angle <= 2 beta about any axis. beta = 0 except for
  CUBICSPLINE: the glTF path normalises a cubic c(s) in quaternion space, which is no fixed-axis
  rotation; c restricted to the interval lies in the convex hull of its 4 Bernstein control points
  P_k, and {q : angle(q, q_ref) <= beta} is a convex cone for beta < 90 deg, so with q_ref = c(mid)
  normalised and beta = max_k angle(P_k, q_ref) every q(s) is within beta of q_ref, i.e. the rotation
  is within 2 beta of R_ref and moves a point x by at most 2 |x| sin(beta) (any axis); when a
  control point is not in q_ref's half-space the rotation is unbounded (any rotation: |x| kept).
  Subdividing the interval (below) shrinks beta, so cubic clips tighten like linear ones.
* Per (meshlet, vertex, joint i) a box of q_i(t) = M_p^-1 M_i v = IB_p^-1 (L..)^-1 (L..) IB_i v:
  start from the point IB_i v, walk the chain bone by bone up from joint i's node to the common
  ancestor with the principal's node (each step x <- T R S x on the box), then down to the principal's
  node (x <- S^-1 R^-1 T^-1 x), then IB_p^-1; the root transform and the ancestors above the common one
  cancel exactly and are never used, and no global matrix is decomposed. Box operations: translate =
  add the translation box; scale = interval product; fixed matrix = transform the 8 corners and
  re-box; rotation about an axis over an angle range = per corner and component the extremes of
  Rodrigues' formula v' = v cos + (n x v) sin + n (n.v)(1 - cos): its derivative vanishes at
  phi_k = atan2((n x v)_k, (v - n(n.v))_k) (+ pi), and the candidate angles phi_k + m pi
  (k = x, y, z; m = -1, 0, 1: the 9 angles) clamped to [min(0, theta), max(0, theta)] plus the two
  ends are evaluated (a candidate inside the range contributes A +- rho exactly). A zero or
  sign-changing scale in an inverse step makes the box unbounded (class 2).
* Vertex box = sum_i w_i * box_i (weights >= 0, summing to 1: float32 weights off by (1 - W) ~ 2^-23
  shift the point by (1 - W) M_p^-1(0), left to the float32 slack below); meshlet box = union of its vertices' boxes; the
  meshlet's need = (farthest box point from the sphere centre + float32 slack) / r, and s_r = the
  largest need among classes 0 and 1. The float32 slack, 2^-16 (|c| + need r + the principal's
  translation scale), covers the GPU's float32 skin matrices, skinning and culling arithmetic
  (errors of a few 2^-24 relative to those magnitudes).
* Normal cone: n_m = the bind-pose area-weighted mean normal. Per triangle the normal is multi-affine
  in its 9 corner coordinates, so over the product of its three vertex boxes it lies in the convex
  hull of its values at the 8^3 = 512 corner combinations; the cone {n : angle(n, n_m) <= alpha} is
  convex for alpha < 90 deg, so alpha_max = the largest angle of those 512 normals (plus 2^-12 rad
  slack) bounds every normal, and no normal can vanish. Early out: a triangle two of whose boxes
  overlap can collapse, so its meshlet gets no cone (class 1). The 512-corner pass is the build's
  most expensive step (about 6 s per pass on the full worm's 327k triangles on 2 cores), so the
  final intervals are taken in ``cone_passes`` consecutive groups and each group's vertex boxes are
  unioned (a box that holds over each interval of a group holds over the group): 0 runs one pass per
  interval (the chapter's, tightest). A meshlet leaves the passes once its alpha exceeds alpha_T.
* Adaptive tightening: after the keyframe intervals, the interval with the worst meshlet need is
  halved (its halves replace it) until every interval meets ``target_radius_scale`` ("target"), the
  time budget would be passed by the next split (its two evaluations, timed by the last one:
  "budget"), the kept float32 boxes would pass MAX_KEPT_BYTES ("memory"), or the worst one is at
  ``max_depth`` halvings ("depth"). The bounds of a half are those of the same method on the smaller
  interval, so each stage holds. ``stats["stopped"]`` says which; the base pass over the keyframe
  intervals always runs (about 1.2 s per interval on the full worm).
"""
from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from paramlod.errors import MeshError
from paramlod.meshlod.build.dag import SettingsRecord
from paramlod.meshlod.skinned import SkinnedMesh, quat_matrix

NO_CONE = -2.0           # cone w of a meshlet without a cone (dot <= 1 < 2: never culled by it)
F32_SLACK = 2.0 ** -16   # relative slack for the GPU's float32 skinning and culling (see above)
ANGLE_SLACK = 2.0 ** -12 # radians added to alpha_max
_QUIET_BELOW = 20_000    # triangles: smaller builds show no progress bar by default
_CHUNK = 1 << 15         # (meshlet, vertex, joint) rows per vectorised block
_TRI_CHUNK = 1 << 7      # triangles per block of the 512-corner normal test
MAX_KEPT_BYTES = 1 << 30 # the intervals' float32 vertex boxes kept for the cones: splitting stops beyond


@dataclass(frozen=True)
class SkinBoundsSettings(SettingsRecord):
    WHAT = "skin bounds"
    time_budget_s: float = 5.0           # seconds the adaptive subdivision may take (0: keyframe intervals only)
    target_radius_scale: float = 1.25    # quality target: stop halving once every interval's worst need is below
    # s_r threshold: a meshlet that needs more is class 2 (never culled). The full worm needs at most
    # 1.45 (p99 1.31); the converted real files (assimp's BCN_Epileptic.X, Testwuson.X) p90 2.7 and
    # 1.6: past 2 the moved sphere is 8x the bind volume and culls little, and one constant must
    # serve every class-0/1 meshlet of the mesh (it is their maximum), so outliers go to class 2.
    max_radius_scale: float = 2.0
    # alpha_T: a meshlet whose alpha_max exceeds it is class 1 (no backface test). A cone of half-angle
    # alpha can be culled from at most (1 - sin alpha) / 2 of the view directions (1.7% at 75 deg,
    # 6.7% at 60): beyond 75 the test only costs. Full worm: alpha_max median 35 deg, p90 60 (8 passes).
    max_cone_angle_deg: float = 75.0
    max_depth: int = 6                   # halvings of one keyframe interval at most
    cones: bool = True                   # compute the normal cones (False: classes 1 and 2 only)
    cone_passes: int = 8                 # 512-corner passes: the final intervals in this many groups, each
                                         # group's boxes unioned (0: one pass per interval, the tightest)

    def validate(self) -> "SkinBoundsSettings":
        if not (math.isfinite(self.time_budget_s) and self.time_budget_s >= 0):
            self.bad("time_budget_s", "must be a number of seconds >= 0")
        if not (math.isfinite(self.target_radius_scale) and self.target_radius_scale >= 1):
            self.bad("target_radius_scale", "must be >= 1 (the bind-pose sphere)")
        if not (math.isfinite(self.max_radius_scale) and self.max_radius_scale >= 1):
            self.bad("max_radius_scale", "must be >= 1")
        if not 0 < self.max_cone_angle_deg < 90:
            self.bad("max_cone_angle_deg", "must be in (0, 90) degrees")
        if isinstance(self.max_depth, bool) or not isinstance(self.max_depth, int) or not 0 <= self.max_depth <= 20:
            self.bad("max_depth", "must be an integer in 0..20")
        if isinstance(self.cone_passes, bool) or not isinstance(self.cone_passes, int) or not 0 <= self.cone_passes <= 4096:
            self.bad("cone_passes", "must be an integer in 0..4096 (0: one per interval)")
        return self


@dataclass
class SkinBounds:
    """The bounds of one SkinnedMesh's meshlets over its clip (see the module docstring)."""
    principal: np.ndarray     # uint32 [C] principal joint of each meshlet
    sphere: np.ndarray        # float32 [C, 4] bind-pose sphere (mesh space centre, radius)
    cone: np.ndarray          # float32 [C, 4] PBS reference normal (unit) and cos(alpha_max), or w = -2
    radius_scale: float       # s_r (float32 value) for classes 0 and 1
    classes: np.ndarray       # uint8 [C]: 0 frustum + backface, 1 frustum only, 2 never culled
    intervals: np.ndarray     # float64 [I + 1] (sub)interval boundaries (a repeated last time: the end point)
    triangles: np.ndarray     # uint32 [C] triangles per meshlet (for the cull's counters)
    need: np.ndarray          # float64 [C] each meshlet's own radius scale (inf: unbounded)
    alpha: np.ndarray         # float64 [C] alpha_max in radians (inf: no cone)
    stats: dict = field(default_factory=dict)   # seconds, intervals, splits, stopped, meshlets per class

    def class_counts(self) -> dict:
        return {k: int((self.classes == i).sum()) for i, k in enumerate(("both", "frustum", "none"))}


# --- the clip's motion per interval -----------------------------------------------------------------
def _qmul(a, b):
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], -1)


def _cubic(ch, k, sa, sb):
    """Power coefficients [4, d] in u in [0, 1] of channel ``ch``'s Hermite segment k restricted to
    its local parameter range [sa, sb]."""
    v, ts = ch.values, ch.times
    td = ts[k + 1] - ts[k]
    p0, m0, p1, m1 = v[k, 1], td * v[k, 2], v[k + 1, 1], td * v[k + 1, 0]
    a = [p0, m0, -3 * p0 - 2 * m0 + 3 * p1 - m1, 2 * p0 + m0 - 2 * p1 + m1]
    h = sb - sa   # s = sa + h u
    b0 = a[0] + a[1] * sa + a[2] * sa ** 2 + a[3] * sa ** 3
    b1 = (a[1] + 2 * a[2] * sa + 3 * a[3] * sa ** 2) * h
    b2 = (a[2] + 3 * a[3] * sa) * h ** 2
    b3 = a[3] * h ** 3
    return np.stack([b0, b1, b2, b3])


def _cubic_range(b):
    """(lo, hi) of the cubic b0 + b1 u + b2 u^2 + b3 u^3 (coefficients [4, d]) over u in [0, 1]."""
    vals = [b[0], b.sum(axis=0)]
    for j in range(b.shape[1]):
        roots = np.roots([3 * b[3, j], 2 * b[2, j], b[1, j]]) if np.any(b[1:, j] != 0) else []
        for r in np.atleast_1d(roots):
            if abs(r.imag) < 1e-12 and 0 < r.real < 1:
                u = r.real
                val = b[0].copy()
                val[j] = b[0, j] + b[1, j] * u + b[2, j] * u * u + b[3, j] * u ** 3
                vals.append(np.where(np.arange(b.shape[1]) == j, val, b[0]))
    vals = np.stack(vals)
    return vals.min(axis=0), vals.max(axis=0)


@dataclass
class _Motion:
    """Each node's local motion over one interval (see the module docstring)."""
    t_lo: np.ndarray; t_hi: np.ndarray     # [N, 3]
    s_lo: np.ndarray; s_hi: np.ndarray     # [N, 3]
    r_ref: np.ndarray                      # [N, 3, 3]
    axis: np.ndarray                       # [N, 3] local frame (after r_ref)
    theta: np.ndarray                      # [N] angle range [0, theta], theta in [0, pi] (the shorter arc)
    beta: np.ndarray                       # [N] deviation half-angle (pi/2: any rotation)
    moving: bool                           # False: the pose is constant over the interval


def _motion(rig, ta: float, tb: float) -> _Motion:
    t0, q0, s0 = (a.copy() for a in rig.rest)
    n = len(t0)
    t_lo, t_hi, s_lo, s_hi = t0.copy(), t0.copy(), s0.copy(), s0.copy()
    q_ref, q_end = q0.copy(), q0.copy()
    beta = np.zeros(n)
    for ch in rig.channels:   # in the order Rig.local_trs applies them (a later channel wins)
        ts, node = ch.times, ch.node
        bt = 0.0
        if len(ts) == 1 or tb <= ts[0] or ta >= ts[-1]:
            lo = hi = qa = qb = ch.sample(ta if ta >= ts[-1] else ts[0])
        else:
            k = int(np.searchsorted(ts, ta, side="right")) - 1
            if tb > ts[k + 1] + 1e-12 * max(1.0, abs(ts[k + 1])):
                raise MeshError(f"{rig.name}: interval [{ta}, {tb}] crosses keyframe {ts[k + 1]} (internal error)")
            if ch.interpolation == "STEP":
                lo = hi = qa = qb = ch.values[k]
            elif ch.interpolation == "LINEAR":
                va, vb = ch.sample(ta), ch.sample(min(tb, ts[k + 1]))
                lo, hi, qa, qb = np.minimum(va, vb), np.maximum(va, vb), va, vb
            else:
                td = ts[k + 1] - ts[k]
                b = _cubic(ch, k, (ta - ts[k]) / td, (min(tb, ts[k + 1]) - ts[k]) / td)
                if ch.path != "rotation":
                    lo, hi = _cubic_range(b)
                else:   # Bernstein control points of c(u) on the interval; q_ref = c(1/2) normalised
                    P = np.stack([b[0], b[0] + b[1] / 3, b[0] + 2 * b[1] / 3 + b[2] / 3, b.sum(axis=0)])
                    mid = b[0] + b[1] / 2 + b[2] / 4 + b[3] / 8
                    nm = np.linalg.norm(mid)
                    qa = qb = mid / nm if nm > 0 else np.array([0.0, 0, 0, 1])
                    cos = (P @ qa) / np.maximum(np.linalg.norm(P, axis=1), 1e-300)
                    bt = math.pi / 2 if nm == 0 or np.any(cos <= 1e-9) else float(np.arccos(np.clip(cos.min(), -1, 1)))
        if ch.path == "translation":
            t_lo[node], t_hi[node] = lo, hi
        elif ch.path == "scale":
            s_lo[node], s_hi[node] = lo, hi
        else:
            q_ref[node], q_end[node] = qa / np.linalg.norm(qa), qb / np.linalg.norm(qb)
            beta[node] = bt
    # the shorter arc from q_ref to q_end: a rotation about one axis by theta in [0, pi]
    q_end = np.where((np.sum(q_ref * q_end, axis=1) < 0)[:, None], -q_end, q_end)
    d = _qmul(q_ref * np.array([-1, -1, -1, 1.0]), q_end)
    sn = np.linalg.norm(d[:, :3], axis=1)
    theta = 2 * np.arctan2(sn, np.abs(d[:, 3]))
    axis = np.where(sn[:, None] > 0, d[:, :3] * np.sign(np.where(d[:, 3] < 0, -1.0, 1.0))[:, None]
                    / np.maximum(sn, 1e-300)[:, None], np.array([0, 0, 1.0]))
    theta = np.where(sn > 0, theta, 0.0)
    moving = bool(np.any(t_lo != t_hi) or np.any(s_lo != s_hi) or np.any(theta > 0) or np.any(beta > 0))
    return _Motion(t_lo, t_hi, s_lo, s_hi, quat_matrix(q_ref), axis, theta, beta, moving)


# --- box operations (lo, hi: [n, 3]) -----------------------------------------------------------------
_CORNERS = np.array([[(i >> 0) & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], bool)


def _corners(lo, hi):
    """The 8 corners of boxes [n, 3] as 3 coordinate arrays [n, 8]."""
    return [np.where(_CORNERS[None, :, k], hi[:, k, None], lo[:, k, None]) for k in range(3)]


def _matrix_box(m, lo, hi):
    """Box of the affine map m [n, 3, 4] of the box: centre m c, half-extent |m3| h (the box of
    its 8 transformed corners, exactly)."""
    c, h = (lo + hi) / 2, (hi - lo) / 2
    mc = np.einsum("nij,nj->ni", m[:, :, :3], c) + m[:, :, 3]
    mh = np.einsum("nij,nj->ni", np.abs(m[:, :, :3]), h)
    return mc - mh, mc + mh


def _scale_box(lo, hi, a, b):
    with np.errstate(invalid="ignore", over="ignore"):
        p = np.stack([lo * a, lo * b, hi * a, hi * b])
    p = np.where(np.isnan(p), np.inf, p)   # 0 * inf: unbounded
    lo2, hi2 = p.min(axis=0), p.max(axis=0)
    bad = np.isinf(p).any(axis=0)
    return np.where(bad, -np.inf, lo2), np.where(bad, np.inf, hi2)


def _rotate_box(lo, hi, fixed, axis, ph_lo, ph_hi, beta):
    """Box of {Rot(axis, phi) D fixed x : x in box, phi in [ph_lo, ph_hi], D any rotation of angle
    <= 2 beta}: ``fixed`` [n, 3, 3] applied to the corners first, ``axis`` [n, 3] in the frame after it."""
    x = _corners(lo, hi)
    y = [(fixed[:, i, 0, None] * x[0] + fixed[:, i, 1, None] * x[1]) + fixed[:, i, 2, None] * x[2] for i in range(3)]
    a = [axis[:, k, None] for k in range(3)]
    ay = (a[0] * y[0] + a[1] * y[1]) + a[2] * y[2]
    A = [a[k] * ay for k in range(3)]
    B = [y[k] - A[k] for k in range(3)]
    C = [a[1] * y[2] - a[2] * y[1], a[2] * y[0] - a[0] * y[2], a[0] * y[1] - a[1] * y[0]]
    pl, ph = ph_lo[:, None], ph_hi[:, None]
    cl, sl, ch, sh = np.cos(pl), np.sin(pl), np.cos(ph), np.sin(ph)
    spin = (ph_hi - ph_lo) > 0
    if np.any(ph_hi - ph_lo > math.pi + 1e-9):
        raise MeshError("internal: a rotation range wider than pi (the shorter arc is at most pi)")
    lo2, hi2 = np.empty_like(lo), np.empty_like(hi)
    for k in range(3):
        v1 = A[k] + B[k] * cl + C[k] * sl
        v2 = A[k] + B[k] * ch + C[k] * sh
        mx, mn = np.maximum(v1, v2), np.minimum(v1, v2)
        if spin.any():
            # f = B cos + C sin peaks where (cos, sin) points along (B, C) (the zero of its
            # derivative, atan2(C, B)) and dips at the opposite angle: a candidate counts when that
            # direction lies in the sector [phi_lo, phi_hi] (at most pi wide: the shorter arc)
            rho = np.sqrt(B[k] * B[k] + C[k] * C[k])
            tol = 1e-12 * rho
            e1 = cl * C[k] - sl * B[k]      # cross(dir(phi_lo), (B, C))
            e2 = B[k] * sh - C[k] * ch      # cross((B, C), dir(phi_hi))
            sp = spin[:, None]
            mx = np.where(sp & (e1 >= -tol) & (e2 >= -tol), A[k] + rho, mx)
            mn = np.where(sp & (e1 <= tol) & (e2 <= tol), A[k] - rho, mn)
        lo2[:, k], hi2[:, k] = mn.min(axis=1), mx.max(axis=1)
    if np.any(beta > 0):
        r = np.sqrt((y[0] * y[0] + y[1] * y[1]) + y[2] * y[2]).max(axis=1)   # rotation keeps |y|
        any_rot = beta >= math.pi / 2 - 1e-12
        ext = np.where(any_rot, 0.0, 2 * np.sin(np.minimum(beta, math.pi / 2)) * r)[:, None]
        lo2, hi2 = lo2 - ext, hi2 + ext
        lo2 = np.where(any_rot[:, None], -r[:, None], lo2)
        hi2 = np.where(any_rot[:, None], r[:, None], hi2)
    return lo2, hi2


def _step_up(lo, hi, mo: _Motion, nodes):
    """x <- T R S x over the interval, per row's node."""
    lo, hi = _scale_box(lo, hi, mo.s_lo[nodes], mo.s_hi[nodes])
    th = mo.theta[nodes]
    ref = mo.r_ref[nodes]
    ax = np.einsum("nij,nj->ni", ref, mo.axis[nodes])
    lo, hi = _rotate_box(lo, hi, ref, ax, np.zeros_like(th), th, mo.beta[nodes])
    return lo + mo.t_lo[nodes], hi + mo.t_hi[nodes]


def _step_down(lo, hi, mo: _Motion, nodes):
    """x <- S^-1 R^-1 T^-1 x over the interval, per row's node."""
    lo, hi = lo - mo.t_hi[nodes], hi - mo.t_lo[nodes]
    th = mo.theta[nodes]
    lo, hi = _rotate_box(lo, hi, np.transpose(mo.r_ref[nodes], (0, 2, 1)), mo.axis[nodes], -th,
                         np.zeros_like(th), mo.beta[nodes])
    a, b = mo.s_lo[nodes], mo.s_hi[nodes]
    ok = (a > 0) | (b < 0)
    with np.errstate(divide="ignore"):
        ia, ib = np.where(ok, 1 / np.where(ok, b, 1), -np.inf), np.where(ok, 1 / np.where(ok, a, 1), np.inf)
    return _scale_box(lo, hi, ia, ib)


# --- the mesh's fixed structure ------------------------------------------------------------------
class _Layout:
    """The (meshlet, vertex) rows, their joints and paths, computed once per mesh."""

    def __init__(self, mesh: SkinnedMesh):
        rig = mesh.rig
        cl = mesh.clusters
        first, count = cl["first"].astype(np.int64), cl["count"].astype(np.int64)
        nt = len(mesh.triangles)
        if len(cl) == 0 or (first + count).max() > nt or count.min() < 1:
            raise MeshError(f"{mesh.name}: the meshlets must cover contiguous triangle ranges of the mesh")
        tri_m = np.repeat(np.arange(len(cl)), count)
        tri_idx = np.concatenate([np.arange(f, f + c) for f, c in zip(first, count)])
        self.tri_m, self.tri = tri_m, mesh.triangles[tri_idx].astype(np.int64)
        V = len(mesh.vertices)
        key = np.unique(tri_m[:, None] * V + self.tri)                   # sorted (meshlet, vertex)
        self.mv_m, self.mv_v = key // V, key % V
        self.corner_row = np.searchsorted(key, tri_m[:, None] * V + self.tri)   # [T', 3] rows of the corners
        self.starts = np.searchsorted(self.mv_m, np.arange(len(cl)))
        C = len(cl)
        J = len(rig.joint_nodes)
        w = mesh.weights.astype(np.float64)
        jn = mesh.joints.astype(np.int64)
        # principal: the joint with the largest weight sum over the meshlet's vertices (lowest index on ties)
        r, s = np.nonzero(w[self.mv_v] > 0)
        pk = self.mv_m[r] * J + jn[self.mv_v[r], s]
        uk, inv = np.unique(pk, return_inverse=True)
        sums = np.bincount(inv, weights=w[self.mv_v[r], s])
        um, uj = uk // J, uk % J
        order = np.lexsort((uj, -sums, um))
        firsts = order[np.r_[0, np.nonzero(np.diff(um[order]))[0] + 1]]
        self.principal = np.zeros(C, np.int64)
        self.principal[um[firsts]] = uj[firsts]
        # rows: (meshlet-vertex row, joint, weight) with weight > 0
        self.row, self.joint, self.weight = r, jn[self.mv_v[r], s], w[self.mv_v[r], s]
        p_of_row = self.principal[self.mv_m[r]]
        self.pj = p_of_row
        # paths per distinct (joint, principal)
        par = rig.parents
        def chain(n):
            out = []
            while n >= 0:
                out.append(n)
                n = int(par[n])
            return out
        pairs, pinv = np.unique(np.stack([self.joint, p_of_row], 1), axis=0, return_inverse=True)
        ups, downs = [], []
        for ji, pi in pairs:
            ci, cp = chain(int(rig.joint_nodes[ji])), chain(int(rig.joint_nodes[pi]))
            common = set(ci) & set(cp)
            a = next((n for n in ci if n in common), -1)
            ups.append([n for n in ci[:ci.index(a)]] if a >= 0 else ci)
            downs.append(list(reversed(cp[:cp.index(a)] if a >= 0 else cp)))
        U = max(1, max(len(u) for u in ups))
        D = max(1, max(len(d) for d in downs))
        up = np.full((len(pairs), U), -1)
        dn = np.full((len(pairs), D), -1)
        for k, (u, d) in enumerate(zip(ups, downs)):
            up[k, :len(u)], dn[k, :len(d)] = u, d
        pinv = pinv.reshape(-1)
        self.up, self.down = up[pinv], dn[pinv]
        ib = rig.inverse_bind
        try:
            self.bind_inv = np.linalg.inv(ib)
        except np.linalg.LinAlgError:
            raise MeshError(f"{mesh.name}: an inverse bind matrix is singular") from None
        v = mesh.vertices.astype(np.float64)
        self.start = np.einsum("nij,nj->ni", ib[self.joint, :3, :3], v[self.mv_v[r]]) + ib[self.joint, :3, 3]
        # bind-pose spheres and reference normals
        pv = v[self.mv_v]
        lo = np.minimum.reduceat(pv, self.starts)
        hi = np.maximum.reduceat(pv, self.starts)
        self.centre = (lo + hi) / 2
        d = np.sqrt(((pv - self.centre[self.mv_m]) ** 2).sum(axis=1))
        self.radius = np.maximum.reduceat(d, self.starts) * (1 + 1e-6) + 1e-30
        p = v[self.tri]
        tn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 1])
        ns = np.zeros((C, 3))
        np.add.at(ns, tri_m, tn)
        ln = np.linalg.norm(ns, axis=1)
        self.normal = np.where(ln[:, None] > 0, ns / np.maximum(ln, 1e-300)[:, None], np.array([0, 0, 1.0]))
        self.has_normal = ln > 0
        # the principal joints' translation scale (float32 slack; sampled at the keyframes)
        ts = rig.times
        ts = ts[np.linspace(0, len(ts) - 1, min(len(ts), 16)).round().astype(int)]
        tscale = np.zeros(J)
        for t in ts:
            m = rig.skin_matrices(float(t))
            sv = np.linalg.svd(m[:, :3, :3], compute_uv=False)
            tscale = np.maximum(tscale, (np.linalg.norm(m[:, :3, 3], axis=1) + 1) / np.maximum(sv[:, 2], 1e-30))
        self.tscale = tscale[self.principal]


def _row_boxes(L: _Layout, mo: _Motion):
    """Boxes [rows, 3] of q_i for every (meshlet, vertex, joint) row over the interval."""
    n = len(L.row)
    lo, hi = L.start.copy(), L.start.copy()
    for k in range(L.up.shape[1]):
        sel = np.nonzero(L.up[:, k] >= 0)[0]
        for c in range(0, len(sel), _CHUNK):
            s = sel[c:c + _CHUNK]
            lo[s], hi[s] = _step_up(lo[s], hi[s], mo, L.up[s, k])
    for k in range(L.down.shape[1]):
        sel = np.nonzero(L.down[:, k] >= 0)[0]
        for c in range(0, len(sel), _CHUNK):
            s = sel[c:c + _CHUNK]
            lo[s], hi[s] = _step_down(lo[s], hi[s], mo, L.down[s, k])
    for c in range(0, n, _CHUNK):
        s = slice(c, c + _CHUNK)
        with np.errstate(invalid="ignore"):
            l2, h2 = _matrix_box(L.bind_inv[L.pj[s], :3, :], lo[s], hi[s])
        bad = ~(np.isfinite(lo[s]).all(axis=1) & np.isfinite(hi[s]).all(axis=1))
        lo[s] = np.where(bad[:, None], -np.inf, l2)
        hi[s] = np.where(bad[:, None], np.inf, h2)
    return lo, hi


def _vertex_boxes(L: _Layout, mo: _Motion):
    lo, hi = _row_boxes(L, mo)
    nr = len(L.mv_m)
    vlo, vhi = np.zeros((nr, 3)), np.zeros((nr, 3))
    with np.errstate(invalid="ignore"):
        for k in range(3):
            vlo[:, k] = np.bincount(L.row, weights=L.weight * lo[:, k], minlength=nr)
            vhi[:, k] = np.bincount(L.row, weights=L.weight * hi[:, k], minlength=nr)
    bad = ~(np.isfinite(vlo).all(axis=1) & np.isfinite(vhi).all(axis=1))
    vlo[bad], vhi[bad] = -np.inf, np.inf
    return vlo, vhi


def _down32(x):
    y = x.astype(np.float32)
    return np.where(y.astype(np.float64) > x, np.nextafter(y, np.float32(-np.inf)), y)


def _up32(x):
    y = x.astype(np.float32)
    return np.where(y.astype(np.float64) < x, np.nextafter(y, np.float32(np.inf)), y)


def _needs(L: _Layout, vlo, vhi):
    """Each meshlet's radius scale over the interval (float32 slack included; inf: unbounded)."""
    c = L.centre[L.mv_m]
    far = np.maximum(np.abs(vlo - c), np.abs(vhi - c))
    d = np.sqrt((far * far).sum(axis=1))
    dm = np.maximum.reduceat(d, L.starts)
    slack = F32_SLACK * (np.linalg.norm(L.centre, axis=1) + dm + L.tscale)
    with np.errstate(invalid="ignore"):
        need = (dm + slack) / L.radius
    return np.where(np.isfinite(need), need, np.inf)


def _alphas(L: _Layout, vlo, vhi, live):
    """alpha_max (radians, inf when no cone holds) over the interval for the meshlets ``live``."""
    C = len(L.radius)
    out = np.full(C, np.inf)
    out[live] = 0.0
    tmask = live[L.tri_m]
    tris = np.nonzero(tmask)[0]
    cos_min = np.full(C, np.inf)
    for c0 in range(0, len(tris), _TRI_CHUNK):
        t = tris[c0:c0 + _TRI_CHUNK]
        rows = L.corner_row[t]                                          # [n, 3]
        blo, bhi = vlo[rows], vhi[rows]                                 # [n, 3, 3]
        finite = np.isfinite(blo).all(axis=(1, 2)) & np.isfinite(bhi).all(axis=(1, 2))
        # early out: two corner boxes that overlap can meet (the triangle can collapse)
        overlap = np.zeros(len(t), bool)
        for i, j in ((0, 1), (1, 2), (0, 2)):
            overlap |= np.all((blo[:, i] <= bhi[:, j]) & (blo[:, j] <= bhi[:, i]), axis=1)
        ok = finite & ~overlap
        cm = np.full(len(t), -np.inf)
        if ok.any():
            bl, bh = blo[ok], bhi[ok]
            c1, c2, c3 = (_corners(bl[:, i], bh[:, i]) for i in range(3))      # 3 x [n, 8] each

            def cross(p, q):   # p[i] x q[j] for the 8 x 8 corner pairs: 3 x [n, 8, 8]
                return [p[1][:, :, None] * q[2][:, None, :] - p[2][:, :, None] * q[1][:, None, :],
                        p[2][:, :, None] * q[0][:, None, :] - p[0][:, :, None] * q[2][:, None, :],
                        p[0][:, :, None] * q[1][:, None, :] - p[1][:, :, None] * q[0][:, None, :]]
            x12, x23, x31 = cross(c1, c2), cross(c2, c3), cross(c3, c1)
            # n[i, j, k] = c1_i x c2_j + c2_j x c3_k + c3_k x c1_i: 3 x [n, 8, 8, 8]
            nrm = [x12[k][:, :, :, None] + x23[k][:, None, :, :] + np.swapaxes(x31[k], 1, 2)[:, :, None, :]
                   for k in range(3)]
            ax = L.normal[L.tri_m[t[ok]]]
            dot = (nrm[0] * ax[:, 0, None, None, None] + nrm[1] * ax[:, 1, None, None, None]) \
                + nrm[2] * ax[:, 2, None, None, None]
            ln = np.sqrt((nrm[0] * nrm[0] + nrm[1] * nrm[1]) + nrm[2] * nrm[2])
            with np.errstate(invalid="ignore", divide="ignore"):
                cs = np.where(ln > 0, dot / ln, -np.inf)
            cm[ok] = cs.reshape(len(bl), -1).min(axis=1)
        np.minimum.at(cos_min, L.tri_m[t], cm)
    hit = live & np.isfinite(cos_min) & (cos_min > 0) & L.has_normal
    out[live & ~hit] = np.inf
    out[hit] = np.arccos(np.clip(cos_min[hit], -1, 1))
    return out


# --- the build ---------------------------------------------------------------------------------------
def _base_intervals(rig) -> list[tuple[float, float]]:
    ts = [float(t) for t in rig.times]
    out = [(a, b) for a, b in zip(ts[:-1], ts[1:])]
    if len(ts) == 1 or any(c.interpolation == "STEP" for c in rig.channels):
        out.append((ts[-1], ts[-1]))
    return out


def skin_bounds(mesh: SkinnedMesh, settings: SkinBoundsSettings = SkinBoundsSettings(), progress=None) -> SkinBounds:
    """The conservative bounds of ``mesh``'s meshlets over its clip (see the module docstring).
    ``progress``: None (a tqdm bar for large meshes on a terminal), True, False, or a callable
    (done, total)."""
    if not isinstance(mesh, SkinnedMesh):
        raise MeshError(f"skin_bounds needs a SkinnedMesh, got {type(mesh).__name__}")
    if not isinstance(settings, SkinBoundsSettings):
        raise MeshError(f"skin_bounds settings must be SkinBoundsSettings, got {type(settings).__name__}")
    settings.validate()
    t0 = time.perf_counter()
    L = _Layout(mesh)
    rig = mesh.rig
    C = len(L.radius)
    base = _base_intervals(rig)
    bar, call = None, (progress if callable(progress) else None)
    if call is None and (progress is True or (progress is None and len(mesh.triangles) >= _QUIET_BELOW)):
        bar = tqdm(total=len(base), unit="interval", desc=f"skin bounds {mesh.name}",
                   disable=None if progress is None else False, leave=False)
    done = [0]

    def evaluate(ta, tb):
        mo = _motion(rig, ta, tb)
        vlo, vhi = _vertex_boxes(L, mo)
        need = _needs(L, vlo, vhi)
        done[0] += 1
        if call is not None:
            call(done[0], len(base) + splits[0] * 2)
        elif bar is not None:
            bar.update(1)
        # kept for the cones, rounded outwards to float32 (half the memory, still conservative)
        boxes = (_down32(vlo), _up32(vhi)) if settings.cones else None
        return need, mo.moving, boxes

    def score(need):
        f = need[np.isfinite(need)]
        return float(f.max()) if len(f) else 1.0

    splits = [0]
    heap, final = [], []
    for k, (a, b) in enumerate(base):
        need, moving, boxes = evaluate(a, b)
        item = (-score(need), k, a, b, 0, need, moving, boxes)
        (heapq.heappush(heap, item) if moving and b > a else final.append(item))
    t_split = time.perf_counter()
    stopped, serial = "target", len(base)
    # a split evaluates two halves: it starts only when the last evaluation's time twice more fits
    per_eval = t_split - t0
    per_eval = per_eval / max(len(base), 1)
    kept_bytes = sum(2 * it[7][0].nbytes for it in heap + final if it[7] is not None)
    per_bytes = kept_bytes / max(len(base), 1)
    while heap:
        worst = heap[0]
        if -worst[0] <= settings.target_radius_scale:
            stopped = "target"
            break
        if time.perf_counter() - t_split + 2 * per_eval > settings.time_budget_s:
            stopped = "budget"
            break
        if (len(heap) + len(final) + 2) * per_bytes > MAX_KEPT_BYTES:
            stopped = "memory"
            break
        item = heapq.heappop(heap)
        _, _, a, b, depth, need, _, _ = item
        if depth >= settings.max_depth:
            final.append(item)
            stopped = "depth"
            continue
        m = (a + b) / 2
        splits[0] += 1
        if bar is not None:
            bar.total += 2
        for lo_, hi_ in ((a, m), (m, b)):
            t_e = time.perf_counter()
            n2, mv, bx = evaluate(lo_, hi_)
            per_eval = time.perf_counter() - t_e
            serial += 1
            it = (-score(n2), serial, lo_, hi_, depth + 1, n2, mv, bx)
            (heapq.heappush(heap, it) if mv and hi_ > lo_ else final.append(it))
    final.extend(heap)
    if stopped == "target" and any(-it[0] > settings.target_radius_scale for it in final):
        stopped = "depth"   # some interval reached max_depth above the target
    final.sort(key=lambda it: (it[2], it[3]))
    t_sub = time.perf_counter() - t_split
    need = np.max(np.stack([it[5] for it in final]), axis=0)
    framed = need <= settings.max_radius_scale
    alpha = np.full(C, np.inf)
    t_cone = time.perf_counter()
    if settings.cones:
        alpha_t = math.radians(settings.max_cone_angle_deg)
        live = framed & L.has_normal
        alpha = np.where(live, 0.0, np.inf)
        groups = len(final) if settings.cone_passes == 0 else min(settings.cone_passes, len(final))
        cuts = np.linspace(0, len(final), groups + 1).round().astype(int)
        for g0, g1 in zip(cuts[:-1], cuts[1:]):
            if not live.any():
                break
            # the union of the group's interval boxes bounds every corner at every time of the group
            vlo = np.min(np.stack([it[7][0] for it in final[g0:g1]]), axis=0).astype(np.float64)
            vhi = np.max(np.stack([it[7][1] for it in final[g0:g1]]), axis=0).astype(np.float64)
            a_i = _alphas(L, vlo, vhi, live)
            alpha = np.where(live, np.maximum(alpha, a_i), alpha)
            live &= alpha + ANGLE_SLACK <= alpha_t
        alpha = np.where(np.isfinite(alpha), alpha + ANGLE_SLACK, np.inf)
    t_cone = time.perf_counter() - t_cone
    if bar is not None:
        bar.close()
    classes = np.where(~framed, 2, np.where(alpha <= math.radians(settings.max_cone_angle_deg), 0, 1)).astype(np.uint8)
    s_r = float(need[framed].max()) if framed.any() else 1.0
    s_r32 = np.float32(s_r)
    if float(s_r32) < s_r:
        s_r32 = np.nextafter(s_r32, np.float32(np.inf))
    sphere = np.zeros((C, 4), np.float32)
    sphere[:, :3] = L.centre
    r32 = L.radius.astype(np.float32)
    sphere[:, 3] = np.where(r32.astype(np.float64) < L.radius, np.nextafter(r32, np.float32(np.inf)), r32)
    cone = np.zeros((C, 4), np.float32)
    cone[:, :3] = L.normal
    cos = np.cos(np.where(classes == 0, alpha, 0.0)).astype(np.float32)
    cone[:, 3] = np.where(classes == 0, np.nextafter(cos, np.float32(-1)), np.float32(NO_CONE))
    bounds_t = [it[2] for it in final] + [final[-1][3]]
    b = SkinBounds(principal=L.principal.astype(np.uint32), sphere=sphere, cone=cone, radius_scale=float(s_r32),
                   classes=classes, intervals=np.array(bounds_t, np.float64),
                   triangles=mesh.clusters["count"].astype(np.uint32), need=need, alpha=alpha)
    b.stats = {"settings": settings.as_dict(), "seconds": round(time.perf_counter() - t0, 4),
               "subdivision_seconds": round(t_sub, 4), "cone_seconds": round(t_cone, 4),
               "keyframe_intervals": len(base), "intervals": len(final), "subdivisions": splits[0],
               "evaluations": done[0], "stopped": stopped if base else "no intervals",
               "radius_scale": float(s_r32), "classes": b.class_counts(), "meshlets": C,
               "triangles": int(len(mesh.triangles))}
    return b


def interval_boxes(mesh: SkinnedMesh, ta: float, tb: float):
    """The principal-joint-space boxes over [ta, tb) (an interval within one keyframe interval of
    the clip): (meshlet lo, hi float64 [C, 3], principal int [C], and per (meshlet, vertex) row:
    meshlet int, vertex int, lo, hi [R, 3]). For checks and tools; skin_bounds uses the same code."""
    L = _Layout(mesh)
    vlo, vhi = _vertex_boxes(L, _motion(mesh.rig, float(ta), float(tb)))
    return (np.minimum.reduceat(vlo, L.starts), np.maximum.reduceat(vhi, L.starts), L.principal,
            L.mv_m, L.mv_v, vlo, vhi)
