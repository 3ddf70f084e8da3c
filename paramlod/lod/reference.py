"""numpy twin of the LOD stage (kernels/lod.cl), for tests and debugging.

Same sample positions, same segment rules, same split patterns, in float32 where the kernel
computes in float32 (parameter positions, projection). Function values come from numpy in float64
and are rounded to float32, so screen lengths can differ from the kernel's in the last bits; a
split decision can only differ where an extent lies within that rounding of the threshold.

Several views (the camera records of a ``paramlod.core.views.Views``, one after another or as rows):
each patch is measured in every view; it is culled only if no view sees it (a view sees it when its
samples' outcode AND is 0), and otherwise decided on the most demanding measures over the views
that see it (maxima of the lines' lengths, longest segments and w_u, w_v; OR of the mixed lines;
the union of the screen boxes), as the kernel.
"""
from __future__ import annotations

import numpy as np

from paramlod.core.layouts import CAMERA
from paramlod.lod.patches import EVAL_DTYPE, RENDER_DTYPE, FLAG_FORCED, TIER_SHIFT, initial_patches
from paramlod.lod.stage import (BOUNDARY_CAP, BOUNDARY_SHARE, CONE_EPS, CONE_LIPSCHITZ, CURVE_MAX_PX, CURVE_MIN_PX,
                                 MIXED_MIN_PX, SIL_GRAZE, check_budget, tier_values)
from paramlod.lod.uploads import ONE_SIDED, instance_flags, wrap_flags

F = np.float32


def camera_rows(cam) -> np.ndarray:
    """float32 (N, CAM_FLOATS) of N camera records given one after another or as rows."""
    return np.asarray(cam, np.float32).reshape(-1, CAMERA.length)


def world_positions(scene_inst, functions, inst, u, v):
    """World positions (after the instance transform) and the bad mask, per sample."""
    inst_f, inst_u, params = scene_inst
    shape = u.shape
    pos = np.full(shape + (3,), np.nan, np.float32)
    for i in np.unique(inst):
        sel = inst == i
        fn = functions[inst_u[i, 0]]
        block = params[inst_u[i, 1]: inst_u[i, 1] + fn.param_count]
        pos[sel] = fn.evaluate(u[sel].astype(np.float64), v[sel].astype(np.float64), block).astype(np.float32)
    bad = ~np.all(np.isfinite(pos), axis=-1)
    M = inst_f[inst, 0:16].reshape(shape + (4, 4))
    p4 = np.concatenate([pos, np.ones(shape + (1,), np.float32)], axis=-1)
    with np.errstate(over="ignore", invalid="ignore"):   # overflowing samples are bad in every view
        w = np.einsum("...ij,...j->...i", M[..., :3, :], p4)
    return w, bad


def screen_samples(w, bad, cam):
    """Screen position, state (0 front, 1 behind near plane, 2 bad) and outcode, per sample, of
    world positions ``w`` seen by one camera record."""
    shape = bad.shape
    view = cam[0:16].reshape(4, 4)
    proj = cam[16:32].reshape(4, 4)
    with np.errstate(over="ignore", invalid="ignore"):   # overflowing samples are marked bad below
        e = np.einsum("ij,...j->...i", view[:3, :], np.concatenate([w, np.ones(shape + (1,), np.float32)], axis=-1))
        c = np.einsum("ij,...j->...i", proj, np.concatenate([e, np.ones(shape + (1,), np.float32)], axis=-1))
    bad = bad | ~np.all(np.isfinite(c), axis=-1)   # overflowed on the way to clip space (kernel: lod_project)
    x, y, z, cw = c[..., 0], c[..., 1], c[..., 2], c[..., 3]
    with np.errstate(invalid="ignore", divide="ignore"):   # screen positions only where in front
        code = ((x < -cw) * 1 | (x > cw) * 2 | (y < -cw) * 4 | (y > cw) * 8 | (z < -cw) * 16 | (z > cw) * 32).astype(np.uint32)
        front = cw >= cam[34]
        sx = (x / cw * F(0.5) + F(0.5)) * cam[32]
        sy = (F(0.5) - y / cw * F(0.5)) * cam[33]
    state = np.where(bad, 2, np.where(front, 0, 1))
    code = np.where(bad, np.uint32(63), code)
    s = np.stack([np.where(state == 0, sx, 0), np.where(state == 0, sy, 0)], axis=-1).astype(np.float32)
    return s, state, code


def _seg(s, state):
    """Segment lengths along the last sample axis: NaN adds 0, behind the near plane is infinite."""
    a, b = state[..., :-1], state[..., 1:]
    d = np.linalg.norm(s[..., 1:, :] - s[..., :-1, :], axis=-1).astype(np.float32)
    d = np.where((a == 1) | (b == 1), np.float32(np.inf), d)
    return np.where((a == 2) | (b == 2), np.float32(0), d)


def edge_extrapolate(a, b):
    """Twin of edge_extrapolate() in lod.cl: a line's speed at its end from its two segments nearest
    the end (a, then b); 0 where unmeasurable."""
    with np.errstate(invalid="ignore", over="ignore"):
        t = F(1.5) * np.asarray(a, np.float32)
        r = (t - F(0.5) * np.asarray(b, np.float32)).astype(np.float32)
    return np.where(np.isfinite(r), np.fmax(r, F(0)), F(0)).astype(np.float32)


def raise_measure(s, need):
    """Twin of raise_measure() in lod.cl: s raised to BOUNDARY_SHARE x a boundary's need, at most
    to BOUNDARY_CAP x s."""
    with np.errstate(invalid="ignore", over="ignore"):
        n = (BOUNDARY_SHARE * np.asarray(need, np.float32)).astype(np.float32)
        return np.fmax(s, np.fmin(BOUNDARY_CAP * s, n)).astype(np.float32)


def boundary_measures(seg_u, seg_v, s_g, st_g, msu_line, msv_line):
    """w_u, w_v (n,) of lod.cl: 7 x the longest segment raised to what the patch's four boundary
    lines need. seg_u, seg_v: (n, 4, 7) segments of the u- and v-lines; s_g, st_g: the 5x5 grid
    (n, j over v, i over u); msu_line, msv_line: (n, 4) each line's longest segment."""
    F7 = F(7)
    ends_u = F7 * np.fmax(edge_extrapolate(seg_u[:, :, 0], seg_u[:, :, 1]),
                          edge_extrapolate(seg_u[:, :, 6], seg_u[:, :, 5]))   # (n, 4)
    ends_v = F7 * np.fmax(edge_extrapolate(seg_v[:, :, 0], seg_v[:, :, 1]),
                          edge_extrapolate(seg_v[:, :, 6], seg_v[:, :, 5]))
    chord = lambda s, st: F(4) * _seg(s, st).max(axis=-1)   # noqa: E731  (an edge's 4 chords)
    e8, e9 = chord(s_g[:, 0], st_g[:, 0]), chord(s_g[:, 4], st_g[:, 4])                 # v = v0, v1
    e10, e11 = chord(s_g[:, :, 0], st_g[:, :, 0]), chord(s_g[:, :, 4], st_g[:, :, 4])   # u = u0, u1
    nu_b = np.fmax(np.fmax(np.fmax(ends_u[:, 0], ends_u[:, 1]), np.fmax(ends_u[:, 2], ends_u[:, 3])), np.fmax(e8, e9))
    nv_b = np.fmax(np.fmax(np.fmax(ends_v[:, 0], ends_v[:, 1]), np.fmax(ends_v[:, 2], ends_v[:, 3])), np.fmax(e10, e11))
    with np.errstate(over="ignore"):
        su, sv = F7 * msu_line.max(axis=1), F7 * msv_line.max(axis=1)
    return raise_measure(su, nu_b), raise_measure(sv, nv_b)


def line_turns(w, bad, curve_cos) -> np.ndarray:
    """Twin of line_turns() in lod.cl: per line of 8 world positions (..., 8, 3), whether two
    consecutive segments with good ends turn by more than the angle whose cosine is ``curve_cos``."""
    with np.errstate(invalid="ignore", over="ignore"):   # bad samples (NaN, inf) are left out below
        d = (w[..., 1:, :] - w[..., :-1, :]).astype(np.float32)                      # (..., 7, 3)
        a, b = d[..., :-1, :], d[..., 1:, :]
        dot = (a * b).sum(axis=-1, dtype=np.float32)
        la = np.sqrt((a * a).sum(axis=-1, dtype=np.float32))
        lb = np.sqrt((b * b).sum(axis=-1, dtype=np.float32))
        turn = dot < F(curve_cos) * (la * lb).astype(np.float32)
    good = ~(bad[..., :-2] | bad[..., 1:-1] | bad[..., 2:])
    return (turn & good).any(axis=-1)


def _view_measures(rows, cols, grid, turns=None):
    """One view's measures of n patches from its projected samples ((s, state, code) of the
    u-lines, the v-lines (n, 4, 8) and the 5x5 grid (n, 5, 5); turns: (n, 8), line_turns of the
    lines): code (n,), eu, ev (n, 4), msu, msv, w_u, w_v (n,), mixed, curvy (n, 8: u-lines then
    v-lines; curvy: turning lines over CURVE_MIN_PX), box (n, 4)."""
    (s_r, st_r, c_r), (s_c, st_c, c_c), (s_g, st_g, c_g) = rows, cols, grid
    n = len(s_r)
    code = (np.bitwise_and.reduce(c_r.reshape(n, 32), axis=1) & np.bitwise_and.reduce(c_c.reshape(n, 32), axis=1)
            & np.bitwise_and.reduce(c_g.reshape(n, 25), axis=1))
    seg_u, seg_v = _seg(s_r, st_r), _seg(s_c, st_c)
    eu = np.zeros((n, 4), np.float32)
    ev = np.zeros((n, 4), np.float32)
    for k in range(7):  # sequential float32 sums, as in the kernel
        eu += seg_u[:, :, k]
        ev += seg_v[:, :, k]
    w_u, w_v = boundary_measures(seg_u, seg_v, s_g, st_g, seg_u.max(axis=2), seg_v.max(axis=2))
    allpts = np.concatenate([s_r.reshape(n, 32, 2), s_c.reshape(n, 32, 2), s_g.reshape(n, 25, 2)], axis=1)
    front = np.concatenate([st_r.reshape(n, 32), st_c.reshape(n, 32), st_g.reshape(n, 25)], axis=1) == 0
    big = np.float32(np.inf)
    box = np.stack([np.where(front, allpts[..., 0], big).min(axis=1), np.where(front, allpts[..., 1], big).min(axis=1),
                    np.where(front, allpts[..., 0], -big).max(axis=1), np.where(front, allpts[..., 1], -big).max(axis=1)],
                   axis=1)
    # lines with both bad and good samples split like long ones (lod.cl: edges of the defined part)
    bad_r, bad_c = (st_r == 2).sum(axis=2), (st_c == 2).sum(axis=2)    # (n, 4) per line
    mixed = np.concatenate([(bad_r > 0) & (bad_r < 8) & (eu > MIXED_MIN_PX),   # ... while the good part
                            (bad_c > 0) & (bad_c < 8) & (ev > MIXED_MIN_PX)], axis=1)   # is over a pixel
    # lines whose samples do not resolve the surface (lod.cl line_turns), long enough on screen
    curvy = np.zeros_like(mixed) if turns is None else turns & (np.concatenate([eu, ev], axis=1) > CURVE_MIN_PX)
    return {"code": code, "eu": eu, "ev": ev, "msu": seg_u.max(axis=(1, 2)), "msv": seg_v.max(axis=(1, 2)),
            "w_u": w_u, "w_v": w_v, "mixed": mixed, "curvy": curvy, "box": box}


def _most(x, seen):
    """Max over the views that see each patch (axis 0) of float32 measures >= 0, as the kernel takes
    it: the largest float bits (NaN included), 0 where no view sees the patch."""
    bits = np.ascontiguousarray(x, np.float32).view(np.uint32)
    seen = seen.reshape(seen.shape + (1,) * (bits.ndim - seen.ndim))
    return np.where(seen, bits, np.uint32(0)).max(axis=0).view(np.float32)


def _measure(patches, scene_inst, functions, cam, curve_cos=F(-2)) -> dict:
    """Every view's measures of ``patches`` (as lod_step's kernel: f once per sample, then every
    view): a dict of arrays (views, n, ...)."""
    n = len(patches)
    r = patches["range"].astype(np.float32)
    u0, u1, v0, v1 = (r[:, i:i + 1] for i in range(4))
    du, dv = u1 - u0, v1 - v0
    inst = patches["inst"]
    fk = ((np.arange(4, dtype=np.float32) + F(0.5)) * F(0.25))[None, :, None]
    fi = (np.arange(8, dtype=np.float32) * F(1.0 / 7.0))[None, None, :]
    # rows along u (n, 4, 8) and columns along v (n, 4, 8)
    ru, rv = u0[:, :, None] + du[:, :, None] * fi, v0[:, :, None] + dv[:, :, None] * fk
    ru, rv = np.broadcast_to(ru, (n, 4, 8)), np.broadcast_to(rv, (n, 4, 8))
    cu, cv = u0[:, :, None] + du[:, :, None] * fk, v0[:, :, None] + dv[:, :, None] * fi
    cu, cv = np.broadcast_to(cu, (n, 4, 8)), np.broadcast_to(cv, (n, 4, 8))
    g = np.arange(5, dtype=np.float32) * F(0.25)
    gu = u0[:, :, None] + du[:, :, None] * g[None, None, :]          # (n, 1, 5) over i
    gv = v0[:, :, None] + dv[:, :, None] * g[None, :, None]          # (n, 5, 1) over j
    gu, gv = np.broadcast_to(gu, (n, 5, 5)), np.broadcast_to(gv, (n, 5, 5))
    ii = np.broadcast_to(inst[:, None, None], (n, 4, 8))
    world = (world_positions(scene_inst, functions, ii, ru, rv), world_positions(scene_inst, functions, ii, cu, cv),
             world_positions(scene_inst, functions, np.broadcast_to(inst[:, None, None], (n, 5, 5)), gu, gv))
    turns = np.concatenate([line_turns(*world[0], curve_cos), line_turns(*world[1], curve_cos)], axis=1)   # (n, 8)
    per_view = [_view_measures(*(screen_samples(w, bad, c) for w, bad in world), turns) for c in camera_rows(cam)]
    return {k: np.stack([pv[k] for pv in per_view]) for k in per_view[0]}


def view_masks(patches, scene_inst, functions, cam) -> np.ndarray:
    """Twin of the kernel's render_views: per patch the views that see it (uint64, bit v: view
    v sees it: not all of its samples outside one of v's clip planes)."""
    if len(patches) == 0:
        return np.zeros(0, np.uint64)
    seen = _measure(patches, scene_inst, functions, cam)["code"] == 0     # (views, n)
    bits = np.uint64(1) << np.arange(len(seen), dtype=np.uint64)
    return (seen.astype(np.uint64) * bits[:, None]).sum(axis=0, dtype=np.uint64)


def backfacing(patches, scene_inst, functions, cams, seen, widen) -> np.ndarray:
    """Per patch: one-sided (INST_U flags bit 0), seen by some view, and back-facing in every view
    that sees it (``seen``: (views, n)), as lod.cl decides it."""
    one_sided = (scene_inst[1][patches["inst"], 3] & ONE_SIDED) != 0
    back = one_sided & seen.any(axis=0)
    if back.any():
        idx = np.flatnonzero(back)
        cone, sphere = normal_cones(patches[idx], scene_inst, functions, widen)
        for view, cam in enumerate(cams):
            back[idx] &= ~seen[view, idx] | cone_back(cam, cone, sphere)
    return back


def lod_step(patches, scene_inst, functions, cam, t_u, t_v, step, force, backface=True, widen=0.25,
             curve_cos=F(-2), hybrid=None):
    """One PATCH SUBDIVISION step; ``cam``: one or more camera records (``camera_rows``);
    ``backface``: cull the back-facing patches of one-sided instances, whose cones hold over the
    patch widened by ``widen`` per side; ``hybrid``: None, or the kernel's (max_tier, tier_t,
    tier_scale, spot_cos, spot_min, silhouettes) (stage.tier_values, LodSettings.spot,
    LodSettings.spot_silhouettes). Returns (children, render patches, stats)."""
    n = len(patches)
    r = patches["range"].astype(np.float32)
    inst = patches["inst"]
    tier = patches["tier"].astype(np.uint32)
    m = _measure(patches, scene_inst, functions, cam, curve_cos)

    seen = m["code"] == 0
    back = backfacing(patches, scene_inst, functions, camera_rows(cam), seen, widen) if backface else np.zeros(n, bool)
    culled = ~seen.any(axis=0) | back
    eu, ev = _most(m["eu"], seen), _most(m["ev"], seen)
    msu, msv = _most(m["msu"], seen), _most(m["msv"], seen)
    w_u, w_v = _most(m["w_u"], seen), _most(m["w_v"], seen)
    mixed = (m["mixed"] & seen[:, :, None]).any(axis=0)
    # turning lines split while the patch's longest line that way is short (lod.cl CURVE_MAX_PX)
    curvy = (m["curvy"] & seen[:, :, None]).any(axis=0)
    short = np.stack([eu.max(axis=1), ev.max(axis=1)], axis=1) < CURVE_MAX_PX   # (n, 2): along u, along v
    mixed |= curvy & np.repeat(short, 4, axis=1)
    mu_, mv_ = mixed[:, :4], mixed[:, 4:]
    big = np.float32(np.inf)
    lo = np.where(seen[:, :, None], m["box"][:, :, :2], big).min(axis=0)
    hi = np.where(seen[:, :, None], m["box"][:, :, 2:], -big).max(axis=0)
    bx0, by0, bx1, by1 = lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]

    max_tier, tier_t, tier_scale, spot_cos, spot_min, silhouettes = hybrid or (0, np.zeros(4, F), np.ones(2, F), F(1), 1,
                                                                               False)
    # each patch's tier's thresholds (lod.cl: tier 0 t_u, t_v; tiers 1, 2 tier_t)
    tu = np.where(tier == 0, F(t_u), np.where(tier == 1, tier_t[0], tier_t[2])).astype(F)
    tv = np.where(tier == 0, F(t_v), np.where(tier == 1, tier_t[1], tier_t[3])).astype(F)
    a = (eu[:, 0] > tu) | (eu[:, 1] > tu) | mu_[:, 0] | mu_[:, 1]
    b = (eu[:, 2] > tu) | (eu[:, 3] > tu) | mu_[:, 2] | mu_[:, 3]
    c = (ev[:, 0] > tv) | (ev[:, 1] > tv) | mv_[:, 0] | mv_[:, 1]
    d = (ev[:, 2] > tv) | (ev[:, 3] > tv) | mv_[:, 2] | mv_[:, 3]
    split = a | b | c | d
    # patches about to be rendered at a tier that has a finer one: a silhouette (from tier 0) or
    # the spot check sends them on
    candidate = (tier < max_tier) & (not force) & ~culled & ~split
    edge = np.zeros(n, bool)
    if silhouettes and (candidate & (tier == 0)).any():
        idx = np.flatnonzero(candidate & (tier == 0))
        edge[idx] = grid_silhouettes(patches[idx], scene_inst, functions, camera_rows(cam), seen[:, idx])
    promote = candidate & ~edge
    if promote.any():
        idx = np.flatnonzero(promote)
        scale = np.where(tier[idx] == 0, F(1), tier_scale[0]).astype(F)
        counts = spot_counts(patches[idx], scene_inst, functions, eu.max(axis=1)[idx], ev.max(axis=1)[idx], scale,
                             spot_cos)
        promote[idx] = counts >= spot_min
    promote |= edge
    to_render = ~culled & (~split | bool(force)) & ~promote
    rp = np.zeros(int(to_render.sum()), RENDER_DTYPE)
    rp["range"] = r[to_render]
    rp["bbox"] = np.stack([bx0, by0, bx1, by1], axis=1)[to_render]
    rp["ext"] = np.stack([eu.max(axis=1), ev.max(axis=1), F(7) * msu, F(7) * msv], axis=1)[to_render]
    rp["inst"] = inst[to_render]
    rp["w"] = np.stack([w_u, w_v], axis=1)[to_render]
    rp["flags"] = step | np.where(split[to_render], FLAG_FORCED, 0) | (tier[to_render] << np.uint32(TIER_SHIFT))

    children = []
    sp = ~culled & split & (not force)
    mu, mv = F(0.5) * (r[:, 0] + r[:, 1]), F(0.5) * (r[:, 2] + r[:, 3])
    U0, U1, V0, V1 = r[:, 0], r[:, 1], r[:, 2], r[:, 3]
    quad = sp & (a | b) & (c | d)
    cases = [
        (quad, [(U0, mu, V0, mv), (mu, U1, V0, mv), (U0, mu, mv, V1), (mu, U1, mv, V1)]),
        (sp & ~quad & a & b, [(U0, mu, V0, V1), (mu, U1, V0, V1)]),
        (sp & ~quad & c & d, [(U0, U1, V0, mv), (U0, U1, mv, V1)]),
        (sp & ~quad & a & ~b, [(U0, mu, V0, mv), (mu, U1, V0, mv), (U0, U1, mv, V1)]),
        (sp & ~quad & b & ~a, [(U0, U1, V0, mv), (U0, mu, mv, V1), (mu, U1, mv, V1)]),
        (sp & ~quad & c & ~d & ~a & ~b, [(U0, mu, V0, mv), (U0, mu, mv, V1), (mu, U1, V0, V1)]),
        (sp & ~quad & d & ~c & ~a & ~b, [(U0, mu, V0, V1), (mu, U1, V0, mv), (mu, U1, mv, V1)]),
    ]
    for mask, rects in cases:
        for rect in rects:
            ch = np.zeros(int(mask.sum()), EVAL_DTYPE)
            ch["range"] = np.stack([x[mask] for x in rect], axis=1)
            ch["inst"] = inst[mask]
            ch["tier"] = tier[mask]
            children.append(ch)
    again = np.zeros(int(promote.sum()), EVAL_DTYPE)   # measured again at the next tier
    again["range"], again["inst"], again["tier"] = r[promote], inst[promote], tier[promote] + 1
    children = np.concatenate(children + [again])
    rendered_tier = tier[to_render]
    stats = {"step": step, "in": n, "split": int(sp.sum()), "culled": int(culled.sum()),
             "out": int(to_render.sum()), "forced": int((to_render & split).sum()), "backface": int(back.sum()),
             "promoted": int(promote.sum()), "tiers": [int((rendered_tier == t).sum()) for t in range(3)]}
    return children, rp, stats


def run_lod(scene, camera_records, settings, functions=None, tiers=None):
    """The whole LOD stage in numpy for one or more views (``camera_records``: their records one
    after another, or as rows); ``tiers``: hybrid tiers 1 and 2's (divisor, scale), as LodStage.enqueue:
    returns (render patches, per-step stats)."""
    functions = functions or scene.functions()
    inst_f, inst_u, params = scene.instance_buffers()
    # the flags SceneBuffers sends
    inst = (inst_f, instance_flags(scene, inst_u, wrap_flags(scene, inst_u, params)), params)
    patches = initial_patches(inst[0][:, 28:32], settings.initial_grid)
    out, steps, made = [], [], 0
    hybrid = (*tier_values(settings, tiers), *settings.spot(), settings.spot_silhouettes) if tiers is not None else None
    for step in range(1, settings.max_steps + 1):
        if len(patches) == 0:
            steps.append({"step": step, "in": 0, "split": 0, "culled": 0, "out": 0, "forced": 0, "backface": 0,
                          "promoted": 0, "tiers": [0, 0, 0]})
            continue
        patches, rp, st = lod_step(patches, inst, functions, camera_rows(camera_records),
                                   settings.threshold[0], settings.threshold[1], step,
                                   step == settings.max_steps, settings.backface_cull, settings.backface_widen,
                                   settings.curve_cos(), hybrid)
        out.append(rp)
        steps.append(st)
        made += len(patches)
        check_budget(made, settings)   # as the device stage: splitting stops at the budget
    return (np.concatenate(out) if out else np.zeros(0, RENDER_DTYPE)), steps


# --- back-face culling (kernels/lod/lod.cl normal_cone, cone_back; docs/lod.md) ---------------
HALF_PI = F(np.pi / 2)


def sampled_range(patches, inst_f, widen):
    """Twin of sampled_range() in common.cl: (u0, u1, v0, v1) float32 (n,) each, every patch's range
    widened by ``widen`` of its size per side and clamped to its instance's domain."""
    r = patches["range"].astype(np.float32)
    dom = inst_f[patches["inst"].astype(np.int64), 28:32]
    w = F(widen)
    wu, wv = (r[:, 1] - r[:, 0]) * w, (r[:, 3] - r[:, 2]) * w
    return (np.fmax(r[:, 0] - wu, dom[:, 0]), np.fmin(r[:, 1] + wu, dom[:, 1]),
            np.fmax(r[:, 2] - wv, dom[:, 2]), np.fmin(r[:, 3] + wv, dom[:, 3]))


def cone_nodes(patches, inst_f, widen):
    """(u, v) float32 (n, 5, 5) [j over v, i over u] of the cone's nodes: the 5x5 grid over each
    patch's sampled_range."""
    u0, u1, v0, v1 = sampled_range(patches, inst_f, widen)
    g = np.arange(5, dtype=np.float32) * F(0.25)
    u = u0[:, None, None] + (u1 - u0)[:, None, None] * g[None, None, :]
    v = v0[:, None, None] + (v1 - v0)[:, None, None] * g[None, :, None]
    return np.broadcast_to(u, (len(u0), 5, 5)), np.broadcast_to(v, (len(u0), 5, 5))


def object_surface(scene_inst, functions, inst, u, v):
    """f and its partials in object space, float32 (..., 3) each, at parameters ``u``, ``v`` of
    instances ``inst`` (arrays of one shape)."""
    inst_f, inst_u, params = scene_inst
    pos = np.full(u.shape + (3,), np.nan, np.float32)
    fu, fv = pos.copy(), pos.copy()
    for i in np.unique(inst):
        sel = inst == i
        fn = functions[inst_u[i, 0]]
        block = params[inst_u[i, 1]: inst_u[i, 1] + fn.param_count]
        p, a, b = fn.surface(u[sel].astype(np.float64), v[sel].astype(np.float64), block)
        pos[sel], fu[sel], fv[sel] = p.astype(np.float32), a.astype(np.float32), b.astype(np.float32)
    return pos, fu, fv


def _norm(x):
    return np.sqrt((x * x).sum(axis=-1, dtype=np.float32)).astype(np.float32)


def normal_cones(patches, scene_inst, functions, widen):
    """Twin of lod.cl normal_cone: per patch the normal cone (axis xyz, half-angle; 4 where there is
    none) and bounding sphere (centre xyz, radius) in world space, float32 (n, 4) each, holding
    over the patch widened by ``widen`` per side (under the bound's assumption, docs/lod.md)."""
    inst_f = scene_inst[0]
    n = len(patches)
    u, v = cone_nodes(patches, inst_f, widen)
    inst = patches["inst"]
    pos, fu, fv = object_surface(scene_inst, functions, np.broadcast_to(inst[:, None, None], u.shape), u, v)
    M = inst_f[inst, 0:16].reshape(n, 4, 4)
    A = M[:, :3, :3]
    with np.errstate(all="ignore"):
        bad = ~np.all(np.isfinite(pos), axis=-1)
        wp = (np.einsum("nij,nabj->nabi", A, pos) + M[:, None, None, :3, 3]).astype(np.float32)
        P = np.einsum("nij,nabj->nabi", A, fu).astype(np.float32)
        Q = np.einsum("nij,nabj->nabi", A, fv).astype(np.float32)
        sgn = np.where(np.linalg.det(A.astype(np.float64)) < 0, F(-1), F(1)).astype(np.float32)
        ok = ~bad.any(axis=(1, 2)) & np.all(np.isfinite(P), axis=(1, 2, 3)) & np.all(np.isfinite(Q), axis=(1, 2, 3))
        mp, mq = _norm(P).max(axis=(1, 2)), _norm(Q).max(axis=(1, 2))
        dup, duq = _norm(P[:, :, 1:] - P[:, :, :-1]).max(axis=(1, 2)), _norm(Q[:, :, 1:] - Q[:, :, :-1]).max(axis=(1, 2))
        dvp, dvq = _norm(P[:, 1:] - P[:, :-1]).max(axis=(1, 2)), _norm(Q[:, 1:] - Q[:, :-1]).max(axis=(1, 2))
        ep = F(0.5) * CONE_LIPSCHITZ * (dup + dvp)
        eq = F(0.5) * CONE_LIPSCHITZ * (duq + dvq)
        nrm = sgn[:, None, None, None] * np.cross(P, Q).astype(np.float32)
        ln = _norm(nrm)
        a = nrm[:, 2, 2]
        # |n(x) - n_k| <= e for every x node k is nearest to (docs/lod.md), so n(x) != 0 when e < |n_k|
        e = ep[:, None, None] * _norm(Q) + _norm(P) * eq[:, None, None] + (ep * eq)[:, None, None]
        ok &= np.all(e < ln, axis=(1, 2))
        ang = np.arctan2(_norm(np.cross(a[:, None, None], nrm)), (a[:, None, None] * nrm).sum(-1, dtype=np.float32))
        ha = (ang + np.arcsin(np.fmin(e / ln, F(1)))).astype(np.float32).max(axis=(1, 2))
        c = wp[:, 2, 2]
        r = _norm(wp - c[:, None, None]).max(axis=(1, 2))
        hu = F(0.25) * (u[:, 0, 4] - u[:, 0, 0])
        hv = F(0.25) * (v[:, 4, 0] - v[:, 0, 0])
        r = (r + (mp + ep) * (F(0.5) * hu) + (mq + eq) * (F(0.5) * hv)).astype(np.float32)
        ok &= np.isfinite(ha) & np.isfinite(r) & np.all(np.isfinite(c), axis=1)
    cone = np.concatenate([a, np.where(ok, ha + CONE_EPS, F(4))[:, None]], axis=1).astype(np.float32)
    sphere = np.concatenate([c, (r * (F(1) + CONE_EPS))[:, None]], axis=1).astype(np.float32)
    return cone, sphere


def cone_back(cam, cone, sphere) -> np.ndarray:
    """Twin of lod.cl cone_back for one camera record: per patch, whether every normal of its cone
    faces away from the camera at every point of its sphere."""
    V = np.asarray(cam, np.float32)[0:16].reshape(4, 4)
    with np.errstate(all="ignore"):
        a = (cone[:, :3] @ V[:3, :3].T).astype(np.float32)
        if cam[31] != 0:   # orthographic (CAM_PROJ + 15)
            ang = np.arctan2(_norm(a[:, :2]), -a[:, 2])
            ok = np.ones(len(cone), bool)
        else:
            c = (sphere[:, :3] @ V[:3, :3].T + V[:3, 3]).astype(np.float32)
            d = _norm(c)
            ok = d > sphere[:, 3]
            ang = np.arctan2(_norm(np.cross(a, c)), (a * c).sum(-1, dtype=np.float32)) + np.arcsin(sphere[:, 3] / d)
        return ok & (cone[:, 3] < HALF_PI) & ((ang + cone[:, 3]).astype(np.float32) < HALF_PI)


# --- the hybrid tiers' spot check (kernels/lod/spot.cl) -------------------------------------------
SPOT_OFFSETS = np.array([0.5, 1.0 / 3.0, 0.2], np.float32)   # spot.cl spot_offset


def spot_normals(scene_inst, functions, inst, u, v):
    """Twin of spot.cl spot_normal: unit world-space normals (..., 3) from the analytic partials,
    0 where f or the partials are not finite or the normal vanishes."""
    pos, fu, fv = object_surface(scene_inst, functions, inst, u, v)
    A = scene_inst[0][inst, 0:16].reshape(inst.shape + (4, 4))[..., :3, :3]
    with np.errstate(all="ignore"):
        n = np.cross(np.einsum("...ij,...j->...i", A, fu), np.einsum("...ij,...j->...i", A, fv)).astype(F)
        ln = _norm(n)
        ok = (ln > 0) & np.isfinite(ln) & np.all(np.isfinite(pos), axis=-1)
        return np.where(ok[..., None], n / np.where(ok, ln, F(1))[..., None], F(0)).astype(F)


def spot_counts(patches, scene_inst, functions, most_u, most_v, scale, spot_cos) -> np.ndarray:
    """Twin of the spot check (spot.cl): per patch, how many of its 189 sub-samples have a normal
    that turns from its cell's blended corner normals by more than acos(``spot_cos``). ``most_u``,
    ``most_v``: the patch's longest measured lines in frame pixels; ``scale``: its tier's divisor."""
    r = patches["range"].astype(F)
    inst = patches["inst"]
    n = len(r)
    cu = ((r[:, 1] - r[:, 0]) / np.fmax(F(most_u) * scale, F(7))).astype(F)
    cv = ((r[:, 3] - r[:, 2]) / np.fmax(F(most_v) * scale, F(3))).astype(F)
    cu_, cv_ = cu[:, None, None], cv[:, None, None]
    # cells (i, j) spread over the patch, centred at (i + 1/2) / 7 of u and (j + 1/2) / 3 of v
    step_u, step_v = (r[:, 1] - r[:, 0]) * (F(1) / F(7)), (r[:, 3] - r[:, 2]) * (F(1) / F(3))
    u0 = r[:, 0, None, None] + (np.arange(7, dtype=F) + F(0.5))[None, None, :] * step_u[:, None, None] - F(0.5) * cu_
    v0 = r[:, 2, None, None] + (np.arange(3, dtype=F) + F(0.5))[None, :, None] * step_v[:, None, None] - F(0.5) * cv_
    u0, v0 = np.broadcast_to(u0, (n, 3, 7)), np.broadcast_to(v0, (n, 3, 7))    # (n, 3 cells v, 7 cells u)
    bit_u, bit_v = np.array([0, 1, 0, 1], F), np.array([0, 0, 1, 1], F)    # spot.cl spot_corner's bits
    cu4, cv4 = cu[:, None, None, None], cv[:, None, None, None]
    corners = spot_normals(scene_inst, functions, np.broadcast_to(inst[:, None, None, None], (n, 3, 7, 4)),
                           u0[..., None] + bit_u * cu4, v0[..., None] + bit_v * cv4)    # (n, 3, 7, 4, 3)
    a = np.tile(SPOT_OFFSETS, 3)     # offset o: a = OFFSETS[o % 3], b = OFFSETS[o // 3]
    b = np.repeat(SPOT_OFFSETS, 3)
    # sub-samples (n, 3 cells v, 7 cells u, 9 offsets), from the cell's first corner
    su = u0[..., None] + a * cu4
    sv = v0[..., None] + b * cv4
    ns = spot_normals(scene_inst, functions, np.broadcast_to(inst[:, None, None, None], su.shape), su, sv)
    n00, n10, n01, n11 = (corners[:, :, :, None, c] for c in range(4))
    w = lambda x: x[..., None]   # noqa: E731  (weights over the vector axis)
    blend = (w((F(1) - a) * (F(1) - b)) * n00 + w(a * (F(1) - b)) * n10 + w((F(1) - a) * b) * n01
             + w(a * b) * n11).astype(F)
    known = [np.any(x != 0, axis=-1) for x in (n00, n10, n01, n11, ns)]
    ok = np.logical_and.reduce(np.broadcast_arrays(*known))
    turns = ok & ((ns * blend).sum(-1, dtype=F) < F(spot_cos) * _norm(blend))
    return turns.reshape(n, -1).sum(axis=1)


def grid_silhouettes(patches, scene_inst, functions, cams, seen) -> np.ndarray:
    """Twin of spot.cl grid_silhouette: per patch, whether in some view that sees it (``seen``:
    (views, n)) the finite-difference normals of its 5 x 5 grid face both towards and away, or
    one of them comes within SIL_GRAZE (cosine) of edge-on."""
    r = patches["range"].astype(F)
    n = len(r)
    g = np.arange(5, dtype=F) * F(0.25)
    u0, u1, v0, v1 = (r[:, i, None, None] for i in range(4))
    gu = np.broadcast_to(u0 + (u1 - u0) * g[None, None, :], (n, 5, 5))    # [patch, j over v, i over u]
    gv = np.broadcast_to(v0 + (v1 - v0) * g[None, :, None], (n, 5, 5))
    w, bad = world_positions(scene_inst, functions, np.broadcast_to(patches["inst"][:, None, None], (n, 5, 5)), gu, gv)
    up, um = [min(i + 1, 4) for i in range(5)], [max(i - 1, 0) for i in range(5)]
    with np.errstate(all="ignore"):
        nrm = np.cross(w[:, :, up] - w[:, :, um], w[:, up, :] - w[:, um, :]).astype(F)
    ok = ~(bad | bad[:, :, up] | bad[:, :, um] | bad[:, up, :] | bad[:, um, :])
    out = np.zeros(n, bool)
    for view, cam in enumerate(cams):
        V = cam[0:16].reshape(4, 4)
        with np.errstate(all="ignore"):
            e = (np.einsum("ij,npqj->npqi", V[:3, :3], w) + V[:3, 3]).astype(F)
            ne = np.einsum("ij,npqj->npqi", V[:3, :3], nrm).astype(F)
            if cam[31] != 0:   # orthographic: the view axis
                towards = np.broadcast_to(np.array([0, 0, 1], F), e.shape)
            else:
                towards = -e / _norm(e)[..., None]
            facing = ((ne * towards).sum(-1, dtype=F) / _norm(ne)).astype(F)
        front = (ok & (facing > 0)).any(axis=(1, 2))
        back = (ok & (facing < 0)).any(axis=(1, 2))
        grazing = (ok & (np.abs(facing) < SIL_GRAZE)).any(axis=(1, 2))
        out |= seen[view] & ((front & back) | grazing)
    return out
