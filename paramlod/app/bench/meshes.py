"""Mesh LOD measurements of ``paramlod bench`` (extra "meshes"), after Smělý's: a 10 x 10 grid of
one mesh under seeded random cameras in [-20, 20]^3 aimed at the origin (the mesh scaled into
[-1, 1], spacing 2), and one mesh along a camera path from far to near. Each runs with the LOD
(threshold 1 px) and without it (threshold 0: the original triangles, through the same cut and
rasterizer) in the same run; also the build time of each mesh (Smělý's table B.3: armadillo,
345,944 triangles, 3.3 s) and the cut alone on about a million cluster tests."""
from __future__ import annotations

import importlib.resources
import statistics
import time

import numpy as np

from paramlod.core.camera import Camera
from paramlod.errors import ParamlodError
from paramlod.meshlod.build.dag import build_dag
from paramlod.meshlod.cut import ClusterCut, Selection
from paramlod.meshlod.format import mesh_info
from paramlod.pipeline.driver import render, render_on_device, scene_state
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.meshes import read_mesh
from paramlod.scene.scene import Material, Scene

# the scanned meshes are closed: one-sided, so clusters that face away are culled
SCANNED = Material((0.75, 0.7, 0.62), two_sided=False)

MESH_VARIANTS = ("meshlets", "meshlets-gl")


def bench_meshes(big: bool) -> list:
    """(name, vertices, faces, normals) of the measured meshes: the Stanford bunny scan (99,785
    triangles, pymeshfix) and, with ``big``, the bunny split twice into four (1.6 M triangles; the
    scan is not manifold, so loop subdivision does not apply)."""
    import trimesh

    path = str(importlib.resources.files("pymeshfix").joinpath("examples/StanfordBunny.ply"))
    bunny = read_mesh(path)
    out = [("bunny", bunny.vertices, bunny.faces, bunny.normals)]
    if big:
        v, f = bunny.vertices.astype(np.float64), bunny.faces.astype(np.int64)
        for _ in range(2):
            v, f = trimesh.remesh.subdivide(v, f)
        m = read_mesh((v.astype(np.float32), f.astype(np.uint32)))
        out.append(("bunny-x16", m.vertices, m.faces, m.normals))
    return out


def normalizing(vertices) -> np.ndarray:
    """The transform that puts the mesh's box centre at the origin and its largest half-extent at 1."""
    lo, hi = vertices.min(axis=0).astype(np.float64), vertices.max(axis=0).astype(np.float64)
    m = np.eye(4)
    m[:3, :3] *= 2.0 / float((hi - lo).max())
    m[:3, 3] = -(lo + hi) / 2 * m[0, 0]
    return m


def grid_scene(lod, n: int = 10, spacing: float = 2.0) -> Scene:
    tr = np.repeat(normalizing(lod.vertices)[None], n * n, axis=0)
    j, i = np.divmod(np.arange(n * n), n)
    tr[:, 0, 3] += (i - (n - 1) / 2) * spacing
    tr[:, 2, 3] += (j - (n - 1) / 2) * spacing
    s = Scene()
    s.add_mesh_instances(lod, n * n, transforms=tr, material=SCANNED)
    return s


def grid_cameras(count: int, size, seed: int = 0, extent: float = 20.0) -> list:
    rng = np.random.default_rng(seed)
    cams = []
    while len(cams) < count:
        eye = rng.uniform(-extent, extent, 3)
        if np.linalg.norm(eye) < 1.0:
            continue
        up = (0, 1, 0) if abs(eye[1]) < 0.99 * np.linalg.norm(eye) else (1, 0, 0)
        cams.append(Camera.look_at(eye, (0, 0, 0), up, 45.0, size, near=0.01, far=1000.0))
    return cams


def path_cameras(count: int, size, far: float = 30.0, near: float = 1.6) -> list:
    """Towards the mesh (at the origin, radius about 1) from ``far`` to ``near``, turning half round."""
    cams = []
    for k in range(count):
        t = k / max(count - 1, 1)
        d = far * (near / far) ** t
        a = np.pi * t
        eye = (d * np.sin(a), 0.3 * d, d * np.cos(a))
        cams.append(Camera.look_at(eye, (0, 0, 0), (0, 1, 0), 45.0, size, near=0.01, far=1000.0))
    return cams


def _frames(scene, cams, variant, threshold, warmup: int) -> dict:
    rs = RenderSettings()
    rs.mesh.threshold_px = threshold
    rows = []
    for k, cam in enumerate([*cams[:warmup], *cams]):
        st = render_on_device(scene, cam, variant, rs) if variant == "meshlets" else render(scene, cam, variant, rs).stats
        if k >= warmup:
            rows.append(st)
    med = statistics.median
    ms = [r["ms"] for r in rows]
    frame = [m.get("frame", m.get("total")) for m in ms]
    tris = med(r.get("triangles_drawn", 0) for r in rows)
    out = {"variant": variant, "threshold_px": threshold, "frames": len(rows),
           "frame_ms": med(frame), "frame_ms_p95": float(np.percentile(frame, 95)),
           "cut_ms": med(m.get("cut", 0.0) for m in ms), "raster_ms": med(m.get("render", 0.0) for m in ms),
           "clusters_drawn": med(r.get("clusters_drawn", 0) for r in rows), "triangles_drawn": tris,
           "cluster_tests": med(r.get("cluster_tests", 0) for r in rows),
           "mesh_device_bytes": rows[-1].get("mesh_device_bytes", 0)}
    if out["raster_ms"] > 0:
        out["triangles_per_s"] = tris / (out["raster_ms"] * 1e-3)
    return out


def cut_alone(lod, instances: int, size, repeats: int = 10) -> dict:
    """Device time of the cut alone over ``instances`` copies (tests = instances x clusters)."""
    n = int(np.ceil(np.sqrt(instances)))
    scene = grid_scene(lod, n)
    cam = grid_cameras(1, size, seed=1)[0]
    render_on_device(scene, cam, "meshlets")   # uploads
    state = scene_state(scene).renderer(scene_state(scene).passes[0].groups[0])
    cut, sel = ClusterCut(), Selection()
    cut.select(state.dev, cam, 1.0, sel)       # grows the selection once
    times = []
    for _ in range(repeats):
        cut.enqueue(state.dev, cam, 1.0, sel)
        times.append(cut.device_ms())
    tests = sel.read_counters()["tests"]
    return {"instances": n * n, "clusters_per_instance": len(lod.clusters), "tests": tests,
            "cut_ms": statistics.median(times), "tests_per_s": tests / (statistics.median(times) * 1e-3)}


def run_meshes(size, frames: int, warmup: int, big: bool, grid: int = 10, log=print) -> dict:
    """Every mesh measurement; ``big``: also the 1.6 M-triangle mesh (a GPU's job); ``grid``: copies
    per side of the grid scenario (Smělý: 10)."""
    out = {"builds": [], "scenarios": [], "grid": grid}
    for name, v, f, n in bench_meshes(big):
        t0 = time.perf_counter()
        lod = build_dag(v, f, n, name=name)
        secs = time.perf_counter() - t0
        info = mesh_info(lod)
        out["builds"].append({"mesh": name, "triangles": int(len(f)), "seconds": secs, "levels": info["levels"],
                              "clusters": info["clusters"], "roots": info["roots"], "bytes": info["bytes"]})
        log(f"build {name}: {len(f):,} triangles in {secs:.2f} s, {info['levels']} levels, {info['roots']} roots")
        for scenario, scene, cams in (("mesh_grid", grid_scene(lod, grid), grid_cameras(frames, size)),
                                      ("mesh_path", _one(lod), path_cameras(frames, size))):
            for variant in MESH_VARIANTS:
                pair = {}
                for threshold in (1.0, 0.0):
                    try:
                        r = _frames(scene, cams, variant, threshold, warmup)
                    except ParamlodError as exc:
                        r = {"variant": variant, "threshold_px": threshold, "error": str(exc)}
                    pair[threshold] = r
                    out["scenarios"].append({"scenario": scenario, "mesh": name, **r})
                    log(f"{scenario} {name} {variant} {threshold:g}px: " +
                        (f"{r['frame_ms']:.2f} ms, {r['triangles_drawn']:,.0f} triangles, {r['clusters_drawn']:,.0f} "
                         f"clusters, cut {r['cut_ms']:.3f} ms" if "error" not in r else r["error"]))
                lod_r, full_r = pair[1.0], pair[0.0]
                if "error" not in lod_r and "error" not in full_r and lod_r["frame_ms"] > 0:
                    out["scenarios"][-2]["speedup_vs_full"] = full_r["frame_ms"] / lod_r["frame_ms"]
                    out["scenarios"][-2]["triangle_ratio_vs_full"] = (full_r["triangles_drawn"]
                                                                     / max(lod_r["triangles_drawn"], 1))
        out.setdefault("cut_alone", []).append({"mesh": name, **cut_alone(lod, max(1, 10 ** 6 // len(lod.clusters)), size)})
        log(f"cut alone {name}: {out['cut_alone'][-1]['tests']:,} tests in {out['cut_alone'][-1]['cut_ms']:.3f} ms")
    return out


def _one(lod) -> Scene:
    s = Scene()
    s.add_mesh(lod, transform=normalizing(lod.vertices), material=SCANNED)
    return s


def format_meshes(res: dict, atomics_per_s: float | None, raster_per_s: float | None = None) -> list[str]:
    lines = ["", "## Meshes", "", "| mesh | triangles | build s | levels | clusters | roots | MiB |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for b in res["builds"]:
        lines.append(f"| {b['mesh']} | {b['triangles']:,} | {b['seconds']:.2f} | {b['levels']} | {b['clusters']:,} | "
                     f"{b['roots']} | {b['bytes'] / 2 ** 20:.1f} |")
    lines += ["", "Smělý (RTX 3070 laptop host): armadillo, 345,944 triangles, built in 3.3 s.", "",
              "| scenario | mesh | variant | px | frame ms | cut ms | raster ms | clusters | triangles | "
              "tri/s | full/LOD frame | full/LOD triangles |", "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in res["scenarios"]:
        if "error" in r:
            lines.append(f"| {r['scenario']} | {r['mesh']} | {r['variant']} | {r['threshold_px']:g} | error: {r['error']} |")
            continue
        tps = r.get("triangles_per_s")
        ratios = [f"{r[k]:.1f}" if k in r else "-" for k in ("speedup_vs_full", "triangle_ratio_vs_full")]
        lines.append(f"| {r['scenario']} | {r['mesh']} | {r['variant']} | {r['threshold_px']:g} | {r['frame_ms']:.2f} | "
                     f"{r['cut_ms']:.3f} | {r['raster_ms']:.2f} | {r['clusters_drawn']:,.0f} | "
                     f"{r['triangles_drawn']:,.0f} | {f'{tps / 1e6:,.0f} M' if tps else '-'} | {ratios[0]} | {ratios[1]} |")
    for c in res.get("cut_alone", []):
        lines.append(f"\nCut alone ({c['mesh']}): {c['tests']:,} cluster tests ({c['instances']} instances x "
                     f"{c['clusters_per_instance']:,} clusters) in {c['cut_ms']:.3f} ms ({c['tests_per_s'] / 1e9:.2f} G/s).")
    if atomics_per_s:
        lines.append(f"Random 64-bit atom_min ceiling in the same run: {atomics_per_s / 1e9:.2f} G/s.")
    if raster_per_s:
        lines.append(f"Hardware rasterization ceiling in the same run (tessellated triangles, level 64): "
                     f"{raster_per_s / 1e9:.2f} G triangles/s.")
    return lines
