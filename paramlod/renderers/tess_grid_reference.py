"""numpy twin of the grid tessellator (kernels/tess/grid.cl), for tests and debugging.

``grid_topology``: the vertices' parameters and the triangles of given levels records, the same
integers and the same float32 parameters as the kernels. ``grid_levels``: the levels records of
render patches, from function values that numpy computes in float64 and rounds to float32, so a
level can differ from the kernel's where the measure lies within that rounding of a whole number
(the unrounded levels come back too, so a test can tell).
"""
from __future__ import annotations

import numpy as np

from paramlod.core.layouts import camera_record
from paramlod.lod.reference import screen_samples, world_positions
from paramlod.renderers.tess_grid import level_rule

F = np.float32
SAMPLES = 8   # grid.cl GRID_EDGE_SAMPLES


def _counts(n, a, b):
    verts = (a - 1) * (b - 1) + n.sum(axis=-1)
    tris = 2 * (a - 2) * (b - 2) + n.sum(axis=-1) + 2 * (a - 2) + 2 * (b - 2)
    return verts, tris


def _lerp(a, b, t):
    """grid_lerp: a + (b - a) t in float32, exactly b at t >= 1."""
    a, b, t = F(a), F(b), F(t)
    return np.where(t >= 1, b, a + (b - a) * t).astype(np.float32)


def _line_measures(scene_inst, functions, cam, inst, u_from, u_to, v_from, v_to):
    """(length, bend) of parameter lines (arrays of their ends), as grid_line_measure."""
    f = (np.arange(SAMPLES, dtype=np.float32) / F(SAMPLES - 1))
    u = _lerp(u_from[:, None], u_to[:, None], f[None, :])
    v = _lerp(v_from[:, None], v_to[:, None], f[None, :])
    w, bad = world_positions(scene_inst, functions, np.repeat(inst[:, None], SAMPLES, axis=1), u, v)
    s, state, _ = screen_samples(w, bad, cam)
    ok = state == 0
    seg = np.linalg.norm(s[:, 1:] - s[:, :-1], axis=-1).astype(np.float32)
    behind = (state[:, 1:] == 1) | (state[:, :-1] == 1)
    length = np.where(ok[:, 1:] & ok[:, :-1], seg, F(0)).sum(axis=1, dtype=np.float32)
    d2 = np.linalg.norm(s[:, :-2] - F(2) * s[:, 1:-1] + s[:, 2:], axis=-1).astype(np.float32)
    bend = np.where(ok[:, :-2] & ok[:, 1:-1] & ok[:, 2:], d2, F(0)).max(axis=1)
    inf = behind.any(axis=1)
    return np.where(inf, F(np.inf), length), np.where(inf, F(np.inf), bend)


def _clamp(level, lclamp):
    return np.clip(np.where(np.isnan(level), lclamp[0], level), lclamp[0], lclamp[1]).astype(np.float32)


def grid_levels(records, scene, camera, settings, threshold) -> tuple[np.ndarray, np.ndarray]:
    """(levels int32 (P, 8) as grid.cl's records, the unrounded levels float32 (P, 6): n0..n3, a,
    b before ceil and before the inner levels are raised to the edges' and to 2)."""
    rule, kind = level_rule(settings, threshold)
    lclamp = (F(settings.l_min), F(settings.l_max))
    p = len(records)
    raw = np.zeros((p, 6), np.float32)
    if kind == 0:
        raw[:, :4], raw[:, 4:] = F(rule[1]), F(rule[0])
    else:
        inst_f, inst_u, params = scene.instance_buffers()
        scene_inst, functions = (inst_f, inst_u, params), scene.functions()
        cam = camera_record(camera)
        r = records["range"].astype(np.float32)
        inst = records["inst"].astype(np.int64)
        ends = [(r[:, 0], r[:, 0], r[:, 2], r[:, 3]), (r[:, 0], r[:, 1], r[:, 2], r[:, 2]),
                (r[:, 1], r[:, 1], r[:, 2], r[:, 3]), (r[:, 0], r[:, 1], r[:, 3], r[:, 3])]
        for e, (a, b, c, d) in enumerate(ends):
            length, bend = _line_measures(scene_inst, functions, cam, inst, a, b, c, d)
            if kind == 1:
                t = F(rule[2] if e & 1 else rule[3])
                with np.errstate(invalid="ignore"):
                    raw[:, e] = _clamp(length * F(rule[1]) / min(t, F(rule[1])), lclamp)
            else:
                raw[:, e] = _chord(bend, rule[0], lclamp)
        if kind == 1:
            ext = records["ext"].astype(np.float32)
            if settings.inner_levels_for(False) == "segment":
                ext[:, :2] = np.maximum(ext[:, :2], ext[:, 2:])
            for k, t in ((0, rule[2]), (1, rule[3])):
                with np.errstate(invalid="ignore"):
                    raw[:, 4 + k] = _clamp(ext[:, k] * F(rule[0]) / min(F(t), F(rule[0])), lclamp)
        else:
            bend_u = np.zeros(p, np.float32)
            bend_v = np.zeros(p, np.float32)
            for k in range(1, SAMPLES - 1):
                g = F(k) / F(SAMPLES - 1)
                vk, uk = _lerp(r[:, 2], r[:, 3], g), _lerp(r[:, 0], r[:, 1], g)
                bend_u = np.maximum(bend_u, _line_measures(scene_inst, functions, cam, inst, r[:, 0], r[:, 1], vk, vk)[1])
                bend_v = np.maximum(bend_v, _line_measures(scene_inst, functions, cam, inst, uk, uk, r[:, 2], r[:, 3])[1])
            raw[:, 4], raw[:, 5] = _chord(bend_u, rule[0], lclamp), _chord(bend_v, rule[0], lclamp)
    n = np.ceil(raw[:, :4]).astype(np.int32)
    a, b = np.ceil(raw[:, 4]).astype(np.int32), np.ceil(raw[:, 5]).astype(np.int32)
    if kind == 2:
        a, b = np.maximum(a, np.maximum(n[:, 1], n[:, 3])), np.maximum(b, np.maximum(n[:, 0], n[:, 2]))
    a, b = np.maximum(a, 2), np.maximum(b, 2)
    verts, tris = _counts(n, a, b)
    return np.column_stack([n, a, b, verts, tris]).astype(np.int32), raw


def _chord(bend, chord, lclamp):
    with np.errstate(invalid="ignore", over="ignore"):
        level = F(SAMPLES - 1) * np.sqrt(bend / (F(8) * F(chord)))
    return _clamp(level.astype(np.float32), lclamp)


def grid_topology(levels) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(patch of each vertex, its (t_u, t_v) in the patch float32 (V, 2), triangles (T, 3) of
    vertex indices into the whole list) of levels records ``levels`` (P, 8)."""
    levels = np.asarray(levels, np.int64)
    patch, ts, tris = [], [], []
    base = 0
    for p, (n0, n1, n2, n3, a, b, nv, nt) in enumerate(levels):
        inner = [(F(i) / F(a), F(j) / F(b)) for j in range(1, b) for i in range(1, a)]
        ring = ([(F(k) / F(n1), F(0)) for k in range(n1)] + [(F(1), F(k) / F(n2)) for k in range(n2)]
                + [(F(n3 - k) / F(n3), F(1)) for k in range(n3)] + [(F(0), F(n0 - k) / F(n0)) for k in range(n0)])
        ts += inner + ring
        patch += [p] * (len(inner) + len(ring))

        def vin(i, j):
            return (j - 1) * (a - 1) + (i - 1)

        sides = (n1, n2, n3, n0)

        def vring(s, k):
            if k == sides[s]:
                s, k = (s + 1) % 4, 0
            return (a - 1) * (b - 1) + sum(sides[:s]) + k

        def vside(s, k):
            return (vin(1 + k, 1), vin(a - 1, 1 + k), vin(a - 1 - k, b - 1), vin(1, b - 1 - k))[s]

        own = []
        for j in range(1, b - 1):
            for i in range(1, a - 1):
                own += [(vin(i, j), vin(i + 1, j), vin(i + 1, j + 1)), (vin(i, j), vin(i + 1, j + 1), vin(i, j + 1))]
        for s in range(4):
            n, A = sides[s], (b if s & 1 else a)
            m, x, y = A - 2, 0, 0
            while x < n or y < m:
                if x < n and (y == m or (x + 1) * A <= (y + 2) * n):
                    own.append((vring(s, x), vring(s, x + 1), vside(s, y)))
                    x += 1
                else:
                    own.append((vring(s, x), vside(s, y + 1), vside(s, y)))
                    y += 1
        tris += [(base + i, base + j, base + k) for i, j, k in own]
        base += (a - 1) * (b - 1) + sum(sides)
    return (np.asarray(patch, np.int64), np.asarray(ts, np.float32).reshape(-1, 2),
            np.asarray(tris, np.int64).reshape(-1, 3))
