"""Skinned mesh measurements of ``paramlod bench`` (extra "skinned"): our rigged giant worm at full
size (paramlod.meshlod.build.worm_rig: 307,200 triangles in a closed shell, 64 bones, a wave), generated into a
temporary folder, loaded through the glTF loader, its conservative bounds built offline
(paramlod.meshlod.build.skin_bounds, through the cache of paramlod.meshlod.source.skinned_bounds:
"built in" is the build's own time, "this run" 0 when they came from the cache), then drawn over the clip by both mesh renderers with the
skinned cull on and off in the same run: frame ms, skinning ms, cull ms, meshlets drawn and
culled per bounds class, and the pixels (object id or depth) in which the frames with and without
culling differ, next to the pixels in which the first frame differs from itself drawn again with
the same settings: OpenGL draws the cut's clusters in the order the device appended them, which
varies from run to run, and where two fragments tie in the depth test the first drawn wins, so
meshlets-gl frames can differ by a few pixels run to run (the OpenCL raster's atom_min keys cannot).
For meshlets-gl, "pose copy" is the host time of reading the posed vertices back from OpenCL and
writing them into the GL vertex buffers.

Cameras: a close orbit (the worm fills the screen and leaves it at the edges, so the frustum
culls), and a view into the mouth from in front of it (the case the chapter's bounds are for: back
faces inside the body are seen through the mouth).
"""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from paramlod.core.camera import Camera
from paramlod.errors import ParamlodError
from paramlod.meshlod.build.worm_rig import FULL, SMALL, write_worm
from paramlod.meshlod.skinned import load_skinned
from paramlod.meshlod.source import skinned_bounds
from paramlod.pipeline.driver import render, scene_state
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.scene import Material, Scene

VARIANTS = ("meshlets", "meshlets-gl")
CLASSES = ("both", "frustum", "none")   # bounds classes 0, 1, 2 (skin_bounds)


def cameras(mesh, size, count: int) -> dict:
    c, r = mesh.bounding_sphere()
    out = {"orbit": [], "mouth": []}
    for k in range(count):
        a = 2 * np.pi * k / max(count, 1)
        eye = c + r * np.array([0.8 * np.sin(a), 0.3, 0.8 * np.cos(a)])
        out["orbit"].append(Camera.look_at(eye, c, (0, 1, 0), 45.0, size, near=0.01 * r, far=10 * r))
    # the mouth: the vertices the rig's first joint (the head's) carries most
    w0 = (mesh.weights * (mesh.joints == 0)).sum(axis=1)
    mouth = mesh.vertices[w0 >= 0.5 * w0.max()].astype(np.float64).mean(axis=0)
    axis = mouth - c
    axis /= np.linalg.norm(axis)
    for k in range(count):
        eye = mouth + axis * r * (0.6 + 0.1 * np.sin(k))
        out["mouth"].append(Camera.look_at(eye, mouth, (0, 1, 0) if abs(axis[1]) < 0.9 else (1, 0, 0), 50.0, size,
                                           near=0.01 * r, far=10 * r))
    return out


def _renderer(scene):
    st = scene_state(scene)
    return st.renderer(st.passes[0].groups[0])


def _differing(a, b) -> int:
    """Pixels whose object id or depth differ between frames a and b ((ids, depth) each)."""
    return int(np.count_nonzero((a[0] != b[0]) | ~((a[1] == b[1]) | (np.isnan(a[1]) & np.isnan(b[1])))))


def _frames(scene, mesh, cams, times, variant, cull: bool, warmup: int) -> tuple[dict, list]:
    rs = RenderSettings()
    rs.mesh.cull_frustum = rs.mesh.cull_backface = cull
    rows, ids, per_class = [], [], []
    classes = mesh.bounds.classes
    seq = [*list(zip(cams, times))[:warmup], *zip(cams, times)]
    for k, (cam, t) in enumerate(seq):
        f = render(scene, cam, variant, rs, time=float(t))
        st = f.stats
        if k < warmup:
            continue
        rows.append(st)
        ids.append((f.object_id.copy(), f.depth.copy()))
        if k == warmup:   # the same frame again: how much this renderer varies run to run
            again = render(scene, cam, variant, rs, time=float(t))
            repeat_px = _differing(ids[-1], (again.object_id, again.depth))
        # the pairs of this frame (read back after it, outside its time): drawn meshlets per class
        sel = _renderer(scene).selection
        pairs = sel.read_pairs(sel.counts()["selected"])
        drawn = np.bincount(classes[pairs[:, 1]], minlength=3) if len(pairs) else np.zeros(3, np.int64)
        per_class.append(drawn)
    med = statistics.median
    ms = [r["ms"] for r in rows]
    total = np.bincount(classes, minlength=3)
    drawn = np.median(np.stack(per_class), axis=0)
    out = {"variant": variant, "cull": cull, "frames": len(rows), "repeat_px": repeat_px,
           "frame_ms": med(m.get("frame", m.get("total", 0.0)) for m in ms),
           "skin_ms": med(m.get("skin", 0.0) for m in ms), "cut_ms": med(m.get("cut", 0.0) for m in ms),
           "pose_copy_ms": med(m.get("pose_copy", 0.0) for m in ms),
           "render_ms": med(m.get("render", 0.0) for m in ms),
           "meshlets_drawn": med(r.get("clusters_drawn", 0) for r in rows),
           "culled_frustum": med(r.get("clusters_culled_frustum", 0) for r in rows),
           "culled_backface": med(r.get("clusters_culled_backface", 0) for r in rows),
           "triangles_drawn": med(r.get("triangles_drawn", 0) for r in rows),
           "drawn_per_class": {k: float(drawn[i]) for i, k in enumerate(CLASSES)},
           "culled_per_class": {k: float(total[i] - drawn[i]) for i, k in enumerate(CLASSES)}}
    return out, ids


def run_skinned(size, frames: int, warmup: int, size_name: str = "full", log=print) -> dict:
    """Every skinned measurement (see the module docstring); ``size_name`` "full" or "small"."""
    dims = {"full": FULL, "small": SMALL}[size_name]
    out = {"mesh": f"giant worm ({size_name})", "size": list(size), "runs": []}
    with tempfile.TemporaryDirectory(prefix="paramlod-skinned-") as tmp:
        path = Path(tmp) / "worm.glb"
        t0 = time.perf_counter()
        write_worm(path, dims)
        out["generate_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        mesh = load_skinned(path)
        out["load_s"] = time.perf_counter() - t0
    rig = mesh.rig
    out.update(triangles=int(len(mesh.triangles)), vertices=int(len(mesh.vertices)), meshlets=int(len(mesh.clusters)),
               joints=int(len(rig.joint_nodes)), keyframes=int(len(rig.times)), clip_s=rig.end - rig.start)
    log(f"skinned worm: {out['triangles']:,} triangles, {out['meshlets']:,} meshlets, {out['joints']} joints, "
        f"generated in {out['generate_s']:.1f} s, loaded in {out['load_s']:.1f} s")
    t0 = time.perf_counter()
    # the renderers' default settings, through the cache they use (a second run loads them)
    mesh.bounds = skinned_bounds(mesh, progress=False)
    b = mesh.bounds
    out["bounds"] = {"seconds": float(b.stats.get("seconds", 0.0)), "this_run_s": time.perf_counter() - t0,
                     "radius_scale": float(b.radius_scale),
                     "classes": b.class_counts(), "intervals": int(len(b.intervals) - 1),
                     "stats": {k: v for k, v in b.stats.items() if isinstance(v, (int, float, str))}}
    log(f"skin bounds: built in {out['bounds']['seconds']:.1f} s (this run {out['bounds']['this_run_s']:.1f} s), s_r {b.radius_scale:.3f}, classes {b.class_counts()}")
    # the frames spread over the clip (off the keyframes); the warm-up frames repeat the first ones
    times = np.minimum(np.linspace(rig.start, rig.end, frames, endpoint=False) + 0.01, rig.end)
    for view, cams in cameras(mesh, size, frames).items():
        for variant in VARIANTS:
            scene = Scene()
            scene.add_skinned_mesh(mesh, variant=variant, material=Material((0.55, 0.45, 0.4), two_sided=False))   # closed
            try:
                on, ids_on = _frames(scene, mesh, cams, times, variant, True, warmup)
                off, ids_off = _frames(scene, mesh, cams, times, variant, False, warmup)
            except ParamlodError as exc:
                out["runs"].append({"view": view, "variant": variant, "error": str(exc)})
                log(f"skinned {view} {variant}: error {exc}")
                continue
            differing = sum(_differing(a, c) for a, c in zip(ids_on, ids_off))
            same = differing == 0
            for r in (on, off):
                out["runs"].append({"view": view, **r, "identical_on_off": same, "on_off_px": differing})
                log(f"skinned {view} {variant} cull {'on' if r['cull'] else 'off'}: {r['frame_ms']:.2f} ms "
                    f"(skin {r['skin_ms']:.3f}, cut {r['cut_ms']:.3f}), {r['meshlets_drawn']:,.0f} meshlets drawn, "
                    f"{r['culled_frustum']:,.0f} frustum / {r['culled_backface']:,.0f} backface culled"
                    f"{'' if same else f' -- {differing} PIXELS DIFFER WITH CULLING ON AND OFF'}")
    return out


def format_skinned(res: dict) -> list[str]:
    b = res["bounds"]
    lines = ["", "## Skinned meshes", "",
             f"{res['mesh']}: {res['triangles']:,} triangles, {res['meshlets']:,} meshlets, {res['joints']} joints, "
             f"{res['keyframes']} keyframes over {res['clip_s']:.2f} s; generated in {res['generate_s']:.1f} s, "
             f"loaded (with meshlets) in {res['load_s']:.1f} s; bounds in {b['seconds']:.1f} s over "
             f"{b['intervals']} intervals, s_r = {b['radius_scale']:.3f}, classes "
             + ", ".join(f"{k} {v:,}" for k, v in b["classes"].items()) + ".", "",
             "| view | variant | cull | frame ms | skin ms | pose copy ms | cut ms | drawn | frustum culled | "
             "backface culled | drawn per class (both/frustum/none) | culled per class | px on != off (all frames) | "
             "px of one frame drawn twice |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|---|---:|---:|"]
    for r in res["runs"]:
        if "error" in r:
            lines.append(f"| {r['view']} | {r['variant']} | | error: {r['error']} |")
            continue
        dc = "/".join(f"{r['drawn_per_class'][k]:,.0f}" for k in CLASSES)
        cc = "/".join(f"{r['culled_per_class'][k]:,.0f}" for k in CLASSES)
        lines.append(f"| {r['view']} | {r['variant']} | {'on' if r['cull'] else 'off'} | {r['frame_ms']:.2f} | "
                     f"{r['skin_ms']:.3f} | {r['pose_copy_ms']:.2f} | {r['cut_ms']:.3f} | {r['meshlets_drawn']:,.0f} | {r['culled_frustum']:,.0f} | "
                     f"{r['culled_backface']:,.0f} | {dc} | {cc} | {r['on_off_px']:,} | {r['repeat_px']:,} |")
    return lines
