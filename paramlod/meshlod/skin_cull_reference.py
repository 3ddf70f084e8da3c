"""numpy twin of the skinned meshlet cull (kernels/meshlod/skin_cull.cl, driven by
paramlod.meshlod.skin_cull): the same float32 operations in the same order, so it selects the same
(instance, cluster) pairs and counts the same counters exactly (tests/meshlod/test_skin_cull.py).

Also the host's half shared with the driver: ``records`` packs the bounds of the skinned slots.

The rule, per meshlet m of a skinned mesh (paramlod.meshlod.build.skin_bounds.SkinBounds: bind
sphere (c, r), principal joint p, cone (n, cos alpha), class, the mesh's s_r) and instance i (model
M_i, largest scale s_i, the frame's float32 skin matrix J = J_p):
* class 2: drawn (no test);
* frustum (classes 0 and 1): world centre w = M_i (J c), radius R = ((r s_r) ||J||) s_i with
  ||J|| = sqrt(max row sum of |J3^T J3|) (Gershgorin on the Gram matrix: >= the largest singular
  value, so R >= the true bound |M_i J (q - c)| <= s_i sigma(J) |q - c|; equal for orthogonal
  columns, i.e. any T R S joint); culled when wholly outside one of the six planes of the cut
  camera record (paramlod.meshlod.cut_reference.cut_camera; the test of kernels/meshlod/cut_common.cl);
* backface (class 0 only, and only in batches whose instances all have a one-sided material,
  ``one_sided``: a two-sided mesh shows its back faces): in the principal joint's space (PBS, q = J^-1 M_i^-1 x) the meshlet lies
  in the sphere (c, r s_r) and its triangle normals within alpha of n at every time of the clip. The
  eye (homogeneous E, E_w = 1 perspective, 0 orthographic) is brought there exactly: mesh space by
  the instance's normal matrix as the static cut does, PBS by adj(J3) / det(J3). Facing is invariant
  under an invertible map of positive determinant (n_world = cof(A) n_q, and n . (x - e) keeps its
  sign), so the test needs no SIMILAR flag and no widened angle for non-uniform joints or instances;
  a joint with det <= 0 (mirroring or singular) gets no backface test. With d = c E_w - e_q:
  culled iff |d| > 0 and cos(alpha) (n . d) - sin(alpha) |n x d| >= (r s_r) E_w + SLACK |d|, i.e.
  the angle between n and d is at most 90 deg - alpha - asin(r s_r / |d|) (every normal in the cone
  sees every point of the sphere from behind), with a slack of 2^-12 |d| for the float32 eye transform.
Instances whose hand-off weight is 0 select nothing and make no tests.
Several views (``select_views``): a meshlet is dropped only when every view culls it (frustum, or
backface for class 0; counted as frustum-culled when every view's frustum test culls it, else as
backface-culled) and drawn into the views that do not (its view mask), as the static cut's rule
(paramlod.meshlod.cut_reference); with one view this is the rule above.
"""
from __future__ import annotations

import numpy as np

from paramlod.core.layouts import INSTANCE_F, INSTANCE_U
from paramlod.core.views import as_views
from paramlod.errors import MeshError
from paramlod.meshlod.cut_reference import (CC_EYE, COUNTERS, ONE_SIDED, append_selected, cut_camera,
                                           planes_outside, sort_views)

SLACK = 2.0 ** -12
_F = np.float32


def records(bounds_list):
    """(spheres float32 [M, 4], cones float32 [M, 4], meta uint32 [M, 4] (principal, class,
    triangles, 0), s_r float32 [S], first meshlet uint32 [S]) of the SkinBounds of each slot."""
    sph, con, meta, srs, first = [], [], [], [], []
    k = 0
    for b in bounds_list:
        n = len(b.principal)
        if not (len(b.sphere) == len(b.cone) == len(b.classes) == len(b.triangles) == n):
            raise MeshError("skin cull: the skin bounds' arrays have different lengths")
        if not (np.isfinite(b.radius_scale) and b.radius_scale >= 1):
            raise MeshError(f"skin cull: the radius scale must be finite and >= 1, got {b.radius_scale}")
        sph.append(np.asarray(b.sphere, _F))
        con.append(np.asarray(b.cone, _F))
        m = np.zeros((n, 4), np.uint32)
        m[:, 0], m[:, 1], m[:, 2] = b.principal, b.classes, b.triangles
        meta.append(m)
        srs.append(b.radius_scale)
        first.append(k)
        k += n
    z = np.zeros((0, 4), _F)
    return (np.concatenate(sph) if sph else z, np.concatenate(con) if con else z,
            np.concatenate(meta) if meta else np.zeros((0, 4), np.uint32), np.asarray(srs, _F),
            np.asarray(first, np.uint32))


def rows_point3(m, p):
    """Rows 0..2 of row-major matrices m [..., 16] applied to points p [..., 3] (rows.cl's order)."""
    return [((m[..., 4 * r] * p[0] + m[..., 4 * r + 1] * p[1]) + m[..., 4 * r + 2] * p[2]) + m[..., 4 * r + 3]
            for r in range(3)]


def scale_bound(J):
    """float32 [...]: sqrt of the Gershgorin bound on J3^T J3's largest eigenvalue (kernel order)."""
    g = [[(J[..., a] * J[..., b] + J[..., 4 + a] * J[..., 4 + b]) + J[..., 8 + a] * J[..., 8 + b]
          for b in range(3)] for a in range(3)]
    rows = [(np.abs(g[a][0]) + np.abs(g[a][1])) + np.abs(g[a][2]) for a in range(3)]
    return np.sqrt(np.fmax(np.fmax(rows[0], rows[1]), rows[2]))


def backfacing(S, sr, cone, model, normal, J, cc):
    """kernels/meshlod/skin_cull.cl's sc_backfacing, elementwise over broadcast float32 arrays."""
    ew = cc[CC_EYE + 3]
    u = [cc[CC_EYE + k] - ew * model[..., 4 * k + 3] for k in range(3)]
    e = [(normal[..., a] * u[0] + normal[..., 4 + a] * u[1]) + normal[..., 8 + a] * u[2] for a in range(3)]
    x = [e[k] - ew * J[..., 4 * k + 3] for k in range(3)]
    j = [J[..., i] for i in range(12)]
    a00, a01, a02 = j[5] * j[10] - j[6] * j[9], j[2] * j[9] - j[1] * j[10], j[1] * j[6] - j[2] * j[5]
    a10, a11, a12 = j[6] * j[8] - j[4] * j[10], j[0] * j[10] - j[2] * j[8], j[2] * j[4] - j[0] * j[6]
    a20, a21, a22 = j[4] * j[9] - j[5] * j[8], j[1] * j[8] - j[0] * j[9], j[0] * j[5] - j[1] * j[4]
    det = (j[0] * a00 + j[1] * a10) + j[2] * a20
    ok = (det > 0) & ~np.isinf(det)
    with np.errstate(all="ignore"):
        dd = np.where(ok, det, _F(1))
        q = [((a00 * x[0] + a01 * x[1]) + a02 * x[2]) / dd, ((a10 * x[0] + a11 * x[1]) + a12 * x[2]) / dd,
             ((a20 * x[0] + a21 * x[1]) + a22 * x[2]) / dd]
        d = [S[..., k] * ew - q[k] for k in range(3)]
        length = np.sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2])
        dt = (d[0] * cone[..., 0] + d[1] * cone[..., 1]) + d[2] * cone[..., 2]
        cx = cone[..., 1] * d[2] - cone[..., 2] * d[1]
        cy = cone[..., 2] * d[0] - cone[..., 0] * d[2]
        cz = cone[..., 0] * d[1] - cone[..., 1] * d[0]
        cr = np.sqrt((cx * cx + cy * cy) + cz * cz)
        sa = np.sqrt(np.fmax(_F(1) - cone[..., 3] * cone[..., 3], _F(0)))
        lhs = cone[..., 3] * dt - sa * cr
        rhs = (S[..., 3] * sr) * ew + _F(SLACK) * length
        return ok & (length > 0) & np.isfinite(length) & (lhs >= rhs)


def one_sided(instances, i0: int, ni: int) -> bool:
    """Whether every instance of the batch ``i0 .. i0 + ni`` has a one-sided material (MeshInstances
    flag ONE_SIDED): only such batches get the backface test (the driver passes it per batch)."""
    return bool(np.all(instances.inst_u[i0:i0 + ni, INSTANCE_U.offset("flags")] & ONE_SIDED))


def select(bounds_list, slots, instances, skin, camera, cull_frustum=True, cull_backface=True, weights=None):
    """The skinned cull of every skinned slot. ``bounds_list``: SkinBounds per slot (in slot order);
    ``slots``: (mesh index, first cluster, first joint) per slot; ``instances``: a MeshInstances
    (its batches say which instances draw which mesh); ``skin``: float32 [J, 4, 4] the frame's skin
    matrices of every slot, concatenated; ``weights``: hand-off weights (None: all 1).
    Returns (pairs uint32 [n, 2] of (instance, cluster) sorted, counters {name: int})."""
    pairs, _, counts = select_views(bounds_list, slots, instances, skin, camera, cull_frustum, cull_backface, weights)
    counts.pop("views")
    return pairs, counts


def select_views(bounds_list, slots, instances, skin, cameras, cull_frustum=True, cull_backface=True, weights=None):
    """``select`` for the views of ``cameras`` (a Camera or a paramlod.core.views.Views): (pairs,
    view masks uint64 [n], counters with "views": per view {"clusters", "triangles"})."""
    ccs = [cut_camera(c, 0.0) for c in as_views(cameras)]
    skin = np.ascontiguousarray(skin, _F).reshape(-1, 16)
    live_all = np.ones(len(instances.inst_f), bool) if weights is None else np.asarray(weights, _F) > 0
    counts = dict.fromkeys(COUNTERS, 0)
    pairs, masks, tris = [], [], {}
    f_model, f_normal = INSTANCE_F.slice("model"), INSTANCE_F.slice("normal")
    by_mesh = {}
    for mesh, i0, ni in instances.batches:
        by_mesh.setdefault(mesh, []).append((i0, ni))
    for b, (mesh, c0, j0) in zip(bounds_list, slots):
        sph, con, meta, srs, _ = records([b])
        sr = srs[0]
        nc = len(sph)
        tris.update(zip(range(c0, c0 + nc), meta[:, 2].tolist()))
        for i0, ni in by_mesh.get(mesh, []):
            if nc == 0 or ni == 0:
                continue
            model = np.ascontiguousarray(instances.inst_f[i0:i0 + ni, f_model], _F)[:, None, :]
            normal = np.ascontiguousarray(instances.inst_f[i0:i0 + ni, f_normal], _F)[:, None, :]
            s = np.asarray(instances.scales[i0:i0 + ni], _F)[:, None]
            live = live_all[i0:i0 + ni]
            counts["tests"] += int(live.sum()) * nc
            J = skin[j0 + meta[:, 0].astype(np.int64)][None, :, :]        # [1, nc, 16]
            S = sph[None]
            cls = meta[None, :, 1]
            draw = np.broadcast_to(live[:, None], (ni, nc)).copy()
            tested = draw & (cls < 2)
            pj = rows_point3(J, [S[..., 0], S[..., 1], S[..., 2]])
            w = rows_point3(model, pj)
            r = ((S[..., 3] * sr) * scale_bound(J)) * s
            mask = np.full((ni, nc), np.uint64((1 << len(ccs)) - 1))
            all_outside = tested.copy()
            for v, cc in enumerate(ccs):
                outside = tested & planes_outside(w, r, cc) if cull_frustum else np.zeros((ni, nc), bool)
                back = tested & ~outside & (cls == 0) & backfacing(S, sr, con[None], model, normal, J, cc) \
                    if cull_backface and one_sided(instances, i0, ni) else np.zeros((ni, nc), bool)
                mask &= np.where(outside | back, ~np.uint64(1 << v), ~np.uint64(0))
                all_outside &= outside
            append_selected(draw, mask, all_outside, meta[:, 2], i0, c0, counts, pairs, masks)
    counts_of = np.zeros(max(tris, default=-1) + 1, np.int64)
    counts_of[list(tris)] = list(tris.values())
    return sort_views(pairs, masks, counts, len(ccs), counts_of)
