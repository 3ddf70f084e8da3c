"""``paramlod bench --peers``: paramlod against the tools its users would use instead, in one run.

Rendering (paramlod's rows, PARAMLOD_ROWS: points, also with pixel-centre and quad coverage, and
tess, also with the grid tessellator and with chord levels, against pyvista/VTK and FURY 2/pygfx, each peer
drawing the same surface as a fixed triangle mesh at several resolutions): the 20x20 order-8 and
order-12 SH glyph fields and the torus, framed and close up. Every row has its warm median time per
frame (render and read the image back to the host) and its silhouette error, 1 - IoU of its coverage
mask against a reference silhouette computed once per scene: the analytic surface tessellated until
its triangles are below a pixel on screen, rasterized at pixel centres in numpy, with the same
camera and size. The "matched error" view gives, per peer, the mesh resolution whose error is
closest to paramlod's and the time ratio there, and the peer's time interpolated at paramlod's
error between the two resolutions around it (``peer_ms_at``) with that ratio.

Sampling (paramlod blue surfels against Open3D and pymeshlab Poisson-disk) of the Stanford bunny at
10k and 100k points: seconds, and evenness (nearest-neighbour distance min / mean / CV, normalised
by the spacing of a hexagonal packing of that many points on the mesh's area), of the whole set and
of its first 1,000 points (only paramlod orders its points so that every prefix is even).

Each peer runs in its own subprocess (``python -m paramlod.app.bench.peers --worker``) with a
timeout: VTK and wgpu make GL/Vulkan contexts that must not meet paramlod's, and a peer that
crashes or hangs becomes a row that says so. A peer that is not installed is a row with the pip
command that installs it (``pip install 'paramlod[peers]'`` installs them all).
"""
from __future__ import annotations

import importlib.metadata
import importlib.resources
import importlib.util
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from paramlod.app.args import parse_size, positive_float, positive_int
from paramlod.app.bench.scenes import apply_variant_settings
from paramlod.core.camera import Camera
from paramlod.core.files import write_atomically
from paramlod.dmri.sh import fibonacci_sphere, sh_matrix
from paramlod.dmri.synthetic import coeffs_from_model
from paramlod.errors import ParamlodError
from paramlod.functions.sh_glyph import make_sh_glyph
from paramlod.pipeline.driver import render
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.scene import Material, Scene
from paramlod.surfels.build import load_mesh, sample_mesh
from paramlod.surfels.build.schedule import kd_tree

# tool -> (module to import, distributions to report the version of, pip command, what it does here)
PEERS = {
    "pyvista": ("pyvista", ("pyvista", "vtk"), "pip install pyvista==0.49.2 vtk==9.7.2", "render"),
    "fury": ("fury", ("fury", "pygfx", "wgpu"), "pip install fury==2.0.0", "render"),
    "open3d": ("open3d", ("open3d",), "pip install open3d==0.20.0", "sample"),
    "pymeshlab": ("pymeshlab", ("pymeshlab",), "pip install pymeshlab==2025.7.post1", "sample"),
}
# what a peer needs from the system when its wheel alone is not enough (said in its failure row)
SYSTEM_HINTS = {
    "pyvista": "VTK needs an OpenGL it can open headless (EGL or OSMesa; else run under xvfb-run: apt-get install xvfb)",
    "fury": "FURY 2 draws through wgpu and needs a Vulkan driver; on a CPU-only machine: apt-get install "
            "mesa-vulkan-drivers (lavapipe)",
    "open3d": "Open3D 0.20's wheel links libusb: apt-get install libusb-1.0-0",
    "pymeshlab": "",
}
SCENES = ("glyphs8", "glyphs12", "torus", "torus-close")
GLYPH_RES = (8, 16, 32, 64, 128)        # sphere segments around phi (half as many in theta) per glyph
TORUS_RES = (16, 32, 64, 128, 256)      # segments around the axis and around the tube
SAMPLE_COUNTS = (10_000, 100_000)
PREFIX = 1_000
FOV = 30.0
MAX_EDGE_PX = 0.6          # reference meshes are refined until their edges are below this on screen
MAX_REF_VERTICES = 8_000_000
WORKER_TIMEOUT_S = 900
THRESHOLD = 84.0           # the thesis's LOD threshold for these scenes (paramlod.app.bench.scenes)


def add_arguments(p):
    p.add_argument("--peers", action="store_true",
                   help="paramlod against pyvista, FURY 2, Open3D and pymeshlab (pip install 'paramlod[peers]'; "
                        "docs/peers.md); with it only this comparison runs")
    p.add_argument("--peers-size", type=parse_size, default=(640, 640), metavar="WxH",
                   help="--peers: frame size, square (default 640x640)")
    p.add_argument("--peers-frames", type=positive_int, default=5, help="--peers: timed frames per row (default 5)")
    p.add_argument("--peers-rounds", type=positive_int, default=1,
                   help="--peers: rounds of every render row, paramlod's then the peers' in turn, so that a slow "
                        "spell of a shared machine reaches both; a row's time is the median of its rounds and "
                        "each ratio is given per round (default 1)")
    p.add_argument("--peers-scenes", nargs="+", choices=SCENES, default=list(SCENES),
                   help="--peers: scenes (default all: glyphs8 glyphs12 torus torus-close)")
    p.add_argument("--peers-tools", nargs="+", choices=["paramlod", *PEERS], default=["paramlod", *PEERS],
                   help="--peers: tools (default all)")
    p.add_argument("--peers-grid", type=positive_int, default=20, help="--peers: glyphs per side (default 20)")
    p.add_argument("--peers-thresholds", type=positive_float, nargs="+", default=[THRESHOLD],
                   help=f"--peers: paramlod LOD thresholds in pixels (default {THRESHOLD:g}, the thesis's; "
                        "smaller: finer silhouettes, slower frames)")
    p.add_argument("--peers-samples", type=positive_int, nargs="*", default=list(SAMPLE_COUNTS),
                   help="--peers: bunny sample counts (default 10000 100000; none: no sampling)")


# --- scenes: one description, built by every tool from it ------------------------------------------
def scene_spec(name: str, size, grid: int = 20) -> dict:
    """The scene ``name`` as plain data (what a worker process receives): kind, parameters, camera."""
    w, h = size
    if w != h:
        raise ParamlodError(f"--peers-size must be square (the peers' field of view is set on the shorter "
                            f"side), got {w}x{h}")
    if name.startswith("glyphs"):
        half = grid / 2
        d = (half + 0.3) / math.tan(math.radians(FOV / 2))   # the whole field just inside the frame
        cam = dict(eye=[0.0, 0.0, d], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0], near=d - 2, far=d + 2)
        return dict(name=name, kind="glyphs", order=int(name[6:]), grid=grid, camera=dict(cam, fov=FOV, size=[w, h]),
                    resolutions=list(GLYPH_RES))
    if name in ("torus", "torus-close"):
        direction = np.array([0.3, 0.8, 1.0]) / np.linalg.norm([0.3, 0.8, 1.0])
        # the torus (radius 1.35, height 0.7) just fills the frame at d; close up is 0.35 d, as in `bench`
        d = 1.45 / math.sin(math.radians(FOV / 2)) * (0.35 if name == "torus-close" else 1.0)
        cam = dict(eye=(direction * d).tolist(), target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0],
                   near=max(0.01, d - 1.5), far=d + 1.5)
        return dict(name=name, kind="torus", major=1.0, minor=0.35, camera=dict(cam, fov=FOV, size=[w, h]),
                    resolutions=list(TORUS_RES))
    raise ParamlodError(f"unknown peers scene {name!r} (available: {', '.join(SCENES)})")


def camera_of(spec: dict) -> Camera:
    c = spec["camera"]
    return Camera.look_at(c["eye"], c["target"], c["up"], c["fov"], tuple(c["size"]), near=c["near"], far=c["far"])


def glyph_field(order: int, grid: int) -> tuple[np.ndarray, np.ndarray]:
    """Canonical SH coefficients [n, k] of a grid x grid crossing-fibre field, each glyph scaled to
    max radius 1, and the glyph centres [n, 3] on a unit grid. Deterministic: every tool gets these."""
    n = grid * grid
    j, i = np.divmod(np.arange(n), grid)
    x, y = (i + 0.5) / grid, (j + 0.5) / grid
    # two in-plane bundles whose crossing angle grows across the field, and a through-plane third
    a1 = np.pi * (0.25 + 0.5 * y)
    a2 = a1 + np.pi * (0.2 + 0.6 * x)
    dirs = np.stack([np.stack([np.cos(a1), np.sin(a1), 0 * x], 1), np.stack([np.cos(a2), np.sin(a2), 0 * x], 1),
                     np.broadcast_to([0.25, 0.0, 1.0], (n, 3)) / math.hypot(0.25, 1.0)], axis=1)
    frac = np.stack([np.ones(n), 0.4 + 0.6 * x, 0.8 * np.clip(1.5 - np.hypot(x - 0.7, y - 0.3) / 0.2, 0, 1)], 1)
    coeffs = coeffs_from_model(dirs, frac / frac.sum(1, keepdims=True), order)
    xyz, theta, phi = fibonacci_sphere(4000)
    rmax = np.abs(coeffs @ sh_matrix(order, theta, phi).T).max(axis=1)
    centres = np.stack([i - (grid - 1) / 2, j - (grid - 1) / 2, np.zeros(n)], 1)
    return coeffs / rmax[:, None], centres


GLYPH_SCALE = 0.45   # glyphs of max radius 1 drawn at radius 0.45 on a unit grid


def _grid_faces(nu: int, nv: int) -> np.ndarray:
    """Two triangles per cell of an (nu+1) x (nv+1) vertex grid (seams duplicated)."""
    a = (np.arange(nu)[:, None] * (nv + 1) + np.arange(nv)[None, :]).reshape(-1)
    b, c, d = a + nv + 1, a + 1, a + nv + 2
    return np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)]).astype(np.int64)


def glyph_mesh(order: int, grid: int, n_phi: int, field=None) -> tuple[np.ndarray, np.ndarray]:
    """All glyphs of the field as one triangle mesh, each a sphere of n_phi x n_phi/2 segments whose
    radius is the SH series (what pyvista and FURY users draw)."""
    coeffs, centres = field if field is not None else glyph_field(order, grid)
    n_theta = max(2, n_phi // 2)
    theta, phi = np.meshgrid(np.linspace(0, np.pi, n_theta + 1), np.linspace(0, 2 * np.pi, n_phi + 1), indexing="ij")
    theta, phi = theta.reshape(-1), phi.reshape(-1)
    unit = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], 1)
    r = coeffs @ sh_matrix(order, theta, phi).T                      # [glyphs, vertices]: one matmul
    verts = (r[:, :, None] * unit[None] * GLYPH_SCALE + centres[:, None, :]).reshape(-1, 3)
    f = _grid_faces(n_theta, n_phi)
    faces = (f[None] + (np.arange(len(coeffs)) * len(unit))[:, None, None]).reshape(-1, 3)
    return verts, faces


def torus_mesh(major: float, minor: float, n: int, m: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    m = m or n
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, n + 1), np.linspace(0, 2 * np.pi, m + 1), indexing="ij")
    ring = major + minor * np.cos(v)
    verts = np.stack([ring * np.cos(u), ring * np.sin(u), minor * np.sin(v)], -1).reshape(-1, 3)
    return verts, _grid_faces(n, m)


def peer_mesh(spec: dict, res: int, field=None) -> tuple[np.ndarray, np.ndarray]:
    if spec["kind"] == "glyphs":
        return glyph_mesh(spec["order"], spec["grid"], res, field)
    return torus_mesh(spec["major"], spec["minor"], res)


def paramlod_scene(spec: dict, field=None):
    s = Scene()
    if spec["kind"] == "glyphs":
        coeffs, centres = field if field is not None else glyph_field(spec["order"], spec["grid"])
        tr = np.repeat(np.eye(4)[None], len(coeffs), axis=0)
        tr[:, :3, :3] *= GLYPH_SCALE
        tr[:, :3, 3] = centres
        s.add_instances(make_sh_glyph(spec["order"]), len(coeffs), per_instance={"coeffs": coeffs.astype(np.float32)},
                        transforms=tr, material=Material((0.8, 0.75, 0.7)))
    else:
        s.add("torus", params={"major": spec["major"], "minor": spec["minor"]})
    return s


# --- silhouettes ----------------------------------------------------------------------------------------
def project(camera: Camera, verts) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates [V, 2] (x right, y down, pixel centres at +0.5) and clip w [V] of world points."""
    w, h = camera.size
    m = camera.projection @ camera.view
    clip = np.asarray(verts, np.float64) @ m[:, :3].T + m[:, 3]
    cw = clip[:, 3]
    safe = np.where(np.abs(cw) > 1e-12, cw, 1e-12)
    xy = np.stack([(clip[:, 0] / safe + 1) * 0.5 * w, (1 - clip[:, 1] / safe) * 0.5 * h], 1)
    return xy, cw


def coverage_mask(xy, faces, size, w=None, near: float = 0.0) -> np.ndarray:
    """Boolean [H, W] mask of the pixel centres inside any triangle (edges included; either winding).
    Triangles with a vertex at or behind the near plane (``w`` < ``near``) are dropped."""
    width, height = size
    xy = np.asarray(xy, np.float64)
    faces = np.asarray(faces, np.int64)
    if w is not None:
        faces = faces[(np.asarray(w)[faces] > near).all(axis=1)]
    mask = np.zeros(height * width, bool)
    chunk = 1 << 20
    for a in range(0, len(faces), chunk):
        p = xy[faces[a:a + chunk]]                                    # [T, 3, 2]
        lo, hi = p.min(axis=1), p.max(axis=1)
        i0 = np.maximum(np.ceil(lo[:, 0] - 0.5), 0)
        i1 = np.minimum(np.floor(hi[:, 0] - 0.5), width - 1)
        j0 = np.maximum(np.ceil(lo[:, 1] - 0.5), 0)
        j1 = np.minimum(np.floor(hi[:, 1] - 0.5), height - 1)
        keep = (i1 >= i0) & (j1 >= j0)                               # its box holds a pixel centre
        span = np.maximum(i1 - i0, j1 - j0) + 1
        done = 0
        s = 1
        while keep.any() and done < span[keep].max():
            sel = np.flatnonzero(keep & (span > done) & (span <= s))
            step = max(1, (1 << 22) // (s * s))                       # bounded memory per batch
            dy, dx = np.divmod(np.arange(s * s), s)
            for b in range(0, len(sel), step):
                t = sel[b:b + step]
                cx = i0[t, None] + dx[None]
                cy = j0[t, None] + dy[None]
                px, py = cx + 0.5, cy + 0.5
                q = p[t]
                e = [(q[:, k1, 0, None] - q[:, k0, 0, None]) * (py - q[:, k0, 1, None])
                     - (q[:, k1, 1, None] - q[:, k0, 1, None]) * (px - q[:, k0, 0, None])
                     for k0, k1 in ((0, 1), (1, 2), (2, 0))]
                inside = (((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0)))
                inside &= (cx <= i1[t, None]) & (cy <= j1[t, None])
                area = (q[:, 1, 0] - q[:, 0, 0]) * (q[:, 2, 1] - q[:, 0, 1]) - (q[:, 1, 1] - q[:, 0, 1]) * (q[:, 2, 0] - q[:, 0, 0])
                inside &= (area != 0)[:, None]
                mask[(cy[inside] * width + cx[inside]).astype(np.int64)] = True
            done, s = s, s * 2
    return mask.reshape(height, width)


def silhouette_error(mask, reference) -> float:
    """1 - IoU of two coverage masks of one size (0: identical; both empty counts as identical)."""
    mask, reference = np.asarray(mask, bool), np.asarray(reference, bool)
    if mask.shape != reference.shape:
        raise ParamlodError(f"silhouette error: mask {mask.shape} and reference {reference.shape} differ in size")
    union = np.logical_or(mask, reference).sum()
    return 0.0 if union == 0 else float(1 - np.logical_and(mask, reference).sum() / union)


def _max_edge_px(camera, verts, faces) -> float:
    xy, cw = project(camera, verts)
    w, h = camera.size
    f = faces[(cw[faces] > camera.near).all(axis=1)]
    p = xy[f]
    on = ((p[..., 0] > -w) & (p[..., 0] < 2 * w) & (p[..., 1] > -h) & (p[..., 1] < 2 * h)).any(axis=1)
    p = p[on]
    if not len(p):
        return 0.0
    return float(max(np.linalg.norm(p[:, k] - p[:, (k + 1) % 3], axis=1).max() for k in range(3)))


def reference_silhouette(spec: dict, field=None) -> tuple[np.ndarray, dict]:
    """The dense analytic silhouette of a scene: its surface tessellated until on-screen edges are
    below MAX_EDGE_PX (within MAX_REF_VERTICES), rasterized at pixel centres. Returns the mask and
    how it was made (resolution, largest edge in pixels, seconds)."""
    t0 = time.perf_counter()
    cam = camera_of(spec)
    probe = 16 if spec["kind"] == "glyphs" else 64
    edge = _max_edge_px(cam, *peer_mesh(spec, probe, field))
    n = max(probe, int(math.ceil(probe * edge / MAX_EDGE_PX)))
    per_res = (len(field[0]) if field is not None else spec.get("grid", 1) ** 2) / 2 if spec["kind"] == "glyphs" else 1
    n = min(n, int(math.sqrt(MAX_REF_VERTICES / per_res)))
    verts, faces = peer_mesh(spec, n, field)
    xy, cw = project(cam, verts)
    mask = coverage_mask(xy, faces, cam.size, cw, cam.near)
    info = {"resolution": n, "vertices": len(verts), "max_edge_px": edge * probe / n,
            "seconds": time.perf_counter() - t0}
    return mask, info


# --- paramlod ------------------------------------------------------------------------------------------
# paramlod's rows -> their renderer: its variants and bench variants with their own settings
# (paramlod.app.bench.scenes.VARIANT_SETTINGS: the points with pixel-centre and quad coverage, the quads with
# the LOD's finer detail split, tess with the grid tessellator, tess with chord levels)
PARAMLOD_ROWS = {"points": "points", "points-centre": "points", "points-quad": "points", "points-quad-fine": "points",
                 "tess": "tess", "tess-grid": "tess", "tess-chord": "tess"}


def paramlod_render_row(spec: dict, variant: str, frames: int, warmup: int = 1, field=None,
                        threshold: float = THRESHOLD) -> dict:
    """paramlod's row (``variant``: a key of PARAMLOD_ROWS): warm median of render + image
    read-back, and the last frame's coverage."""
    scene = paramlod_scene(spec, field)
    cam = camera_of(spec)
    rs = RenderSettings()
    rs.lod.threshold = (threshold, threshold)
    rs.tess.l_max, rs.tess.l_min = 64.0, 8.0   # the thesis's, as in paramlod.app.bench.scenes
    label, variant = variant, PARAMLOD_ROWS[variant]
    apply_variant_settings(rs, label)
    times, frame = [], None
    for k in range(warmup + frames):
        t0 = time.perf_counter()
        frame = render(scene, cam, variant, rs)
        frame.rgb8()
        if k >= warmup:
            times.append((time.perf_counter() - t0) * 1e3)
    label = label if threshold == THRESHOLD else f"{label} t={threshold:g}"
    return {"tool": "paramlod", "version": _version("paramlod"), "variant": label, "threshold": threshold,
            "ms": statistics.median(times), "mask": frame.coverage}


# --- peers, each in a small adapter run by the worker process -------------------------------------------
def _timed_frames(draw, frames: int, warmup: int) -> tuple[float, np.ndarray]:
    times, img = [], None
    for k in range(warmup + frames):
        t0 = time.perf_counter()
        img = draw()
        if k >= warmup:
            times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), img


def pyvista_render(spec: dict, res: int, frames: int, warmup: int, field=None) -> tuple[float, np.ndarray]:
    """pyvista/VTK offscreen: the mesh unlit white on black, no MSAA; time = render + screenshot."""
    import pyvista as pv

    verts, faces = peer_mesh(spec, res, field)
    c = spec["camera"]
    mesh = pv.PolyData(verts.astype(np.float32), np.hstack([np.full((len(faces), 1), 3), faces]).reshape(-1))
    pl = pv.Plotter(off_screen=True, window_size=tuple(c["size"]))
    pl.ren_win.SetMultiSamples(0)   # one sample per pixel, as the reference
    pl.add_mesh(mesh, color="white", lighting=False)
    pl.set_background("black")
    pl.disable_anti_aliasing()
    pl.show(auto_close=False)
    pl.camera.position, pl.camera.focal_point, pl.camera.up = c["eye"], c["target"], c["up"]
    pl.camera.view_angle = c["fov"]
    pl.camera.clipping_range = (c["near"], c["far"])

    def draw():
        pl.render()
        return pl.screenshot(return_img=True)

    ms, img = _timed_frames(draw, frames, warmup)
    pl.close()
    return ms, img[..., :3].max(axis=-1) > 127


def fury_render(spec: dict, res: int, frames: int, warmup: int, field=None) -> tuple[float, np.ndarray]:
    """FURY 2 (pygfx/wgpu) offscreen: ``actor.surface`` of the mesh, unlit; time = draw + snapshot."""
    from fury import actor, window

    verts, faces = peer_mesh(spec, res, field)
    c = spec["camera"]
    sm = window.ShowManager(size=tuple(c["size"]), window_type="offscreen", camera_light=False, pixel_ratio=1)
    sm.scene.background = (0, 0, 0)
    # one sample per pixel, as paramlod's noAA rows and the reference (FURY's default is 2x2 SSAA and
    # a post-process AA, which move the thresholded edge)
    sm.renderer.pixel_scale, sm.renderer.pixel_filter, sm.renderer.ppaa = 1, "nearest", "none"
    sm.scene.add(actor.surface(verts.astype(np.float32), faces.astype(np.int32), material="basic", colors=(1, 1, 1)))
    cam = sm.screens[0].camera
    cam.fov = c["fov"]
    cam.depth_range = (c["near"], c["far"])
    cam.world.reference_up = c["up"]
    cam.local.position = c["eye"]
    cam.look_at(c["target"])

    def draw():
        sm.window.draw()
        return np.asarray(sm.renderer.snapshot())

    ms, img = _timed_frames(draw, frames, warmup)
    sm.close() if hasattr(sm, "close") else None
    return ms, img[..., :3].max(axis=-1) > 127


def open3d_sample(mesh_path: str, n: int) -> tuple[float, np.ndarray]:
    import open3d as o3d

    mesh = o3d.io.read_triangle_mesh(mesh_path)
    t0 = time.perf_counter()
    pts = mesh.sample_points_poisson_disk(n)
    return time.perf_counter() - t0, np.asarray(pts.points)


def pymeshlab_sample(mesh_path: str, n: int) -> tuple[float, np.ndarray]:
    """pymeshlab Poisson disk with exactnumflag (its default returns tens of % more points than asked)."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(mesh_path)
    t0 = time.perf_counter()
    ms.generate_sampling_poisson_disk(samplenum=n, exactnumflag=True)
    return time.perf_counter() - t0, np.asarray(ms.current_mesh().vertex_matrix())


RENDERERS = {"pyvista": pyvista_render, "fury": fury_render}
SAMPLERS = {"open3d": open3d_sample, "pymeshlab": pymeshlab_sample}


def _worker(job_path: str, out_path: str) -> int:
    """Runs one peer's part of a job (JSON) and writes its results (npz: a JSON header and arrays)."""
    job = json.loads(Path(job_path).read_text())
    try:
        rows, arrays = _work(job)
    except Exception as exc:   # the parent's row says what failed, in one line, without a traceback
        Path(out_path + ".err").write_text(f"{type(exc).__name__}: {exc}".splitlines()[0][:300])
        return 1
    np.savez(out_path, header=np.array(json.dumps(rows)), **arrays)
    return 0


def _work(job: dict) -> tuple[list, dict]:
    tool = job["tool"]
    arrays, rows = {}, []
    if tool in RENDERERS:
        for spec in job["scenes"]:
            field = glyph_field(spec["order"], spec["grid"]) if spec["kind"] == "glyphs" else None
            for res in job.get("resolutions") or spec["resolutions"]:
                ms, mask = RENDERERS[tool](spec, res, job["frames"], job["warmup"], field)
                key = f"m{len(rows)}"
                arrays[key] = mask
                rows.append({"scene": spec["name"], "resolution": res, "ms": ms, "mask": key})
                print(f"{tool} {spec['name']} {res}: {ms:.1f} ms", flush=True)
    else:
        SAMPLERS[tool](job["mesh"], 500)   # the first call loads libraries: untimed
        for n in job["counts"]:
            sec, pts = SAMPLERS[tool](job["mesh"], n)
            key = f"p{len(rows)}"
            arrays[key] = pts.astype(np.float32)
            rows.append({"n": n, "seconds": sec, "points": key})
            print(f"{tool} {n}: {sec:.2f} s", flush=True)
    return rows, arrays


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "?"


def peer_versions(tool: str) -> str:
    return " / ".join(f"{d} {_version(d)}" for d in PEERS[tool][1])


def missing_row(tool: str) -> dict:
    return {"tool": tool, "status": "not installed", "install": PEERS[tool][2]}


def run_worker(tool: str, job: dict, timeout: float = WORKER_TIMEOUT_S) -> tuple[list, dict] | dict:
    """Runs ``tool``'s adapter in a subprocess; its rows and arrays, or a failure row (never raises)."""
    with tempfile.TemporaryDirectory(prefix="paramlod-peers-") as tmp:
        jp, op = Path(tmp) / "job.json", Path(tmp) / "out.npz"
        jp.write_text(json.dumps(dict(job, tool=tool)))
        env = dict(os.environ)
        env.setdefault("XDG_RUNTIME_DIR", tmp)   # wgpu's Vulkan loader complains without one
        cmd = [sys.executable, "-m", "paramlod.app.bench.peers", "--worker", str(jp), str(op)]
        # VTK without a display falls back to EGL; where that fails too, a virtual X server may do
        tries = [cmd] + ([["xvfb-run", "-a", *cmd]] if tool == "pyvista" and shutil.which("xvfb-run")
                         and not env.get("DISPLAY") else [])
        for c in tries:
            try:
                p = subprocess.run(c, capture_output=True, text=True, timeout=timeout, env=env)
            except subprocess.TimeoutExpired:
                return {"tool": tool, "status": f"timed out after {timeout:.0f} s", "hint": SYSTEM_HINTS[tool]}
            if p.returncode == 0 and op.exists():
                break
        else:
            err_file = Path(str(op) + ".err")
            lines = [line for line in (p.stderr or "").strip().splitlines() if line.strip()]
            msg = err_file.read_text() if err_file.exists() else (lines[-1][:200] if lines else "no message")
            return {"tool": tool, "status": f"failed (exit {p.returncode}): {msg}", "hint": SYSTEM_HINTS[tool]}
        with np.load(op) as z:
            rows = json.loads(str(z["header"]))
            arrays = {k: z[k] for k in z.files if k != "header"}
    return rows, arrays


# --- sampling metrics ----------------------------------------------------------------------------------
def evenness(points, area: float) -> dict:
    """Nearest-neighbour distances of ``points`` on a surface of ``area``, over the spacing of a
    hexagonal packing of as many points (sqrt(2 A / (sqrt(3) n))): min, mean and CV (std / mean)."""
    pts = np.asarray(points, np.float64)
    if len(pts) < 2:
        raise ParamlodError(f"evenness: needs at least 2 points, got {len(pts)}")
    d, _ = kd_tree(pts).query(pts, k=2)
    nn = d[:, 1]
    hexd = math.sqrt(2 * area / (math.sqrt(3) * len(pts)))
    return {"min": float(nn.min() / hexd), "mean": float(nn.mean() / hexd), "cv": float(nn.std() / nn.mean())}


def bunny_path() -> str:
    try:
        return str(importlib.resources.files("pymeshfix").joinpath("examples/StanfordBunny.ply"))
    except ModuleNotFoundError:
        raise ParamlodError("--peers-samples: the bunny that is sampled comes with pymeshfix: pip install pymeshfix "
                            "(or give --peers-samples no counts to leave the sampling out)") from None


def sampling_row(tool: str, version: str, n: int, seconds: float, pts, area: float) -> dict:
    row = {"tool": tool, "version": version, "scene": "bunny", "n": n, "got": len(pts), "seconds": seconds,
           "all": evenness(pts, area)}
    if len(pts) > PREFIX:
        row["prefix"] = evenness(pts[:PREFIX], area)
    return row


def paramlod_sample(mesh_path: str, n: int, views: int = 16, resolution: int | None = None) -> tuple[float, np.ndarray]:
    """Seconds and positions of ``sample_mesh`` with its defaults (the resolution from the count),
    of the mesh loaded first: the peers' times leave their loading out too."""
    soup = load_mesh(mesh_path)
    t0 = time.perf_counter()
    s = sample_mesh(soup, n, views=views, resolution=resolution)
    return time.perf_counter() - t0, s.positions


# --- the run -------------------------------------------------------------------------------------------
def peer_ms_at(cands: list, error: float) -> float | None:
    """A peer's time at silhouette error ``error``: between the two of its rows (``cands``) whose
    errors bracket it, straight in log time against log error (its time/error front); None outside
    their range or at error 0 (nothing to interpolate in logs)."""
    front = sorted((r["error"], r["ms"]) for r in cands if r["error"] > 0)
    if error <= 0:
        return None
    for (e0, t0), (e1, t1) in zip(front, front[1:]):
        if e0 <= error <= e1:
            w = 0.0 if e1 == e0 else math.log(error / e0) / math.log(e1 / e0)
            return math.exp(math.log(t0) + w * math.log(t1 / t0))
    return None


def matched(rows: list) -> list:
    """Per scene, paramlod variant and peer: the peer's resolution whose silhouette error is closest
    to paramlod's, and the peer's time over paramlod's there (> 1: paramlod is faster); and the
    peer's time interpolated at paramlod's very error (``peer_ms_at``; None outside its rows' range)
    over paramlod's, which a closest resolution of half or twice the error does not give."""
    out = []
    ok = [r for r in rows if "ms" in r and "error" in r]
    for p in (r for r in ok if r["tool"] == "paramlod"):
        for tool in sorted({r["tool"] for r in ok if r["tool"] != "paramlod"}):
            cands = [r for r in ok if r["tool"] == tool and r["scene"] == p["scene"]]
            if not cands:
                continue
            best = min(cands, key=lambda r: (abs(r["error"] - p["error"]), r["resolution"]))
            out.append({"scene": p["scene"], "paramlod": p["variant"], "paramlod_ms": p["ms"],
                        "paramlod_error": p["error"], "peer": tool, "resolution": best["resolution"],
                        "peer_ms": best["ms"], "peer_error": best["error"], "ratio": best["ms"] / p["ms"]})
            at = peer_ms_at(cands, p["error"])
            out[-1].update(peer_ms_at_error=at, ratio_at_error=None if at is None else at / p["ms"])
    return out


def merge_rounds(per_round: list) -> list:
    """The render rows of several rounds as one row each (the first round's, in its order): ``ms``
    the median of the rounds' times, ``ms_rounds`` each round's."""
    out = []
    for r in per_round[0]:
        same = [x for rows in per_round for x in rows
                if (x["tool"], x["scene"], x["variant"]) == (r["tool"], r["scene"], r["variant"])]
        out.append(dict(r, ms=statistics.median(x["ms"] for x in same), ms_rounds=[x["ms"] for x in same]))
    return out


def run_peers(args, out_dir, log=print) -> dict:
    """The comparison (module docstring); writes out_dir/peers.json and peers.md atomically."""
    out_dir = Path(out_dir)
    size = tuple(args.peers_size)
    tools = list(args.peers_tools)
    frames, warmup = args.peers_frames, 1
    result = {"size": list(size), "frames": frames, "warmup": warmup, "render": [], "sampling": [],
              "missing": [], "failed": [], "references": {}}

    def save():
        write_atomically(out_dir / "peers.json", lambda tmp: Path(tmp).write_text(json.dumps(result, indent=1)))

    present = {}
    for t in tools:
        if t == "paramlod":
            continue
        if importlib.util.find_spec(PEERS[t][0]) is None:
            result["missing"].append(missing_row(t))
        else:
            present[t] = PEERS[t][3]
    counts = list(args.peers_samples)
    samplers = [t for t, kind in present.items() if kind == "sample"]
    # the sampled mesh is found before the renders, which take minutes
    bunny = bunny_path() if counts and ("paramlod" in tools or samplers) else None
    specs = [scene_spec(s, size, args.peers_grid) for s in args.peers_scenes]
    renderers = [t for t, kind in present.items() if kind == "render"]
    refs, fields = {}, {}
    rendering = bool(specs) and ("paramlod" in tools or bool(renderers))
    if rendering:
        for spec in specs:
            fields[spec["name"]] = glyph_field(spec["order"], spec["grid"]) if spec["kind"] == "glyphs" else None
            refs[spec["name"]], result["references"][spec["name"]] = reference_silhouette(spec, fields[spec["name"]])
            info = result["references"][spec["name"]]
            log(f"reference {spec['name']}: {info['vertices']:,} vertices, edges <= {info['max_edge_px']:.2f} px, "
                f"{refs[spec['name']].sum():,} pixels covered ({info['seconds']:.1f} s)")

    def worker_rows(tool, job):
        """The worker's rows and arrays, or None once its failure is recorded and logged."""
        got = run_worker(tool, job)
        if isinstance(got, dict):
            result["failed"].append(got)
            log(f"{tool}: {got['status']}")
            return None
        return got

    rounds = args.peers_rounds if rendering else 0
    result["rounds"] = rounds
    per_round = []   # each round's rows: the ratios of one round come from times taken minutes apart at most
    failed_rows = set()   # paramlod's rows that failed, said once: not run again in a later round
    for k in range(rounds):
        mark = f" (round {k + 1} of {rounds})" if rounds > 1 else ""
        rows = []
        for spec in specs if "paramlod" in tools else ():
            for variant, t in ((v, t) for t in args.peers_thresholds for v in PARAMLOD_ROWS):
                if (spec["name"], variant, t) in failed_rows:
                    continue
                try:
                    r = paramlod_render_row(spec, variant, frames, warmup, fields[spec["name"]], t)
                except ParamlodError as exc:
                    failed_rows.add((spec["name"], variant, t))
                    result["failed"].append({"tool": "paramlod", "scene": spec["name"], "variant": variant,
                                             "status": str(exc)})
                    continue
                r["error"] = silhouette_error(r.pop("mask"), refs[spec["name"]])
                r["scene"] = spec["name"]
                rows.append(r)
                log(f"paramlod {r['variant']} {spec['name']}: {r['ms']:.1f} ms, error {r['error']:.3f}{mark}")
        for tool in list(renderers):
            got = worker_rows(tool, {"scenes": specs, "frames": frames, "warmup": warmup})
            if got is None:   # failed, and said so once: not run again in a later round
                renderers.remove(tool)
                continue
            worker, arrays = got
            for r in worker:
                r.update(tool=tool, version=peer_versions(tool), variant=f"mesh {r['resolution']}",
                         error=silhouette_error(arrays[r.pop("mask")], refs[r["scene"]]))
                rows.append(r)
                log(f"{tool} {r['scene']} {r['variant']}: {r['ms']:.1f} ms, error {r['error']:.3f}{mark}")
        per_round.append(rows)
        result["render"] = merge_rounds(per_round)
        save()
    if rounds > 1:
        result["matched_rounds"] = [matched(rows) for rows in per_round]
    result["matched"] = matched(result["render"])
    if bunny is not None:
        import trimesh   # on first use: every command line imports the bench

        path = bunny
        area = float(trimesh.load(path, force="mesh").area)
        if "paramlod" in tools:
            paramlod_sample(path, 1000)   # compiles the kernels: untimed
            for n in counts:
                sec, pts = paramlod_sample(path, n)
                result["sampling"].append(sampling_row("paramlod", _version("paramlod"), n, sec, pts, area))
                log(f"paramlod surfels {n}: {sec:.2f} s")
                save()
        for tool in samplers:
            got = worker_rows(tool, {"mesh": path, "counts": counts})
            if got is None:
                continue
            rows, arrays = got
            for r in rows:
                result["sampling"].append(sampling_row(tool, peer_versions(tool), r["n"], r["seconds"],
                                                       arrays[r["points"]], area))
                log(f"{tool} {r['n']}: {r['seconds']:.2f} s")
            save()
    save()
    md = format_peers_markdown(result)
    write_atomically(out_dir / "peers.md", lambda tmp: Path(tmp).write_text(md))
    return result


def format_peers_markdown(result: dict) -> str:
    w, h = result["size"]
    lines = [f"{w}x{h}; time: warm median of {result['frames']} frames (render and read the image back), ms"
             + (f", the median of {result['rounds']} rounds" if result.get("rounds", 1) > 1 else "")
             + "; silhouette error: 1 - IoU against the dense analytic silhouette."]
    if result["render"]:
        lines += ["", "| scene | tool | version | variant | ms per frame | silhouette error |", "|---|---|---|---|---:|---:|"]
        for r in result["render"]:
            lines.append(f"| {r['scene']} | {r['tool']} | {r.get('version', '')} | {r['variant']} | {r['ms']:.1f} "
                         f"| {r['error']:.3f} |")
    rounds = {}   # (scene, paramlod row, peer) -> each round's ratio at paramlod's error (else, bracketed, closest)
    for ms in result.get("matched_rounds", []):
        for m in ms:
            at = m["ratio_at_error"]
            rounds.setdefault((m["scene"], m["paramlod"], m["peer"]), []).append(
                f"{at:.2f}" if at is not None else f"({m['ratio']:.2f})")
    if result.get("matched"):
        lines += ["", "At matched silhouette error (the peer's mesh resolution whose error is closest to paramlod's; "
                      "then the peer's time interpolated at paramlod's error between its two resolutions around it, "
                      "log time against log error, - outside their range):", "",
                  "| scene | paramlod | ms | error | peer | resolution | peer ms | peer error | peer ms / paramlod ms "
                  "| peer ms at paramlod's error | ratio there |" + (" per round |" if rounds else ""),
                  "|---|---|---:|---:|---|---:|---:|---:|---:|---:|---:|" + ("---|" if rounds else "")]
        for m in result["matched"]:
            at = m.get("peer_ms_at_error")
            there = "- | -" if at is None else f"{at:.1f} | {m['ratio_at_error']:.2f}"
            if rounds:
                there += " | " + " / ".join(rounds.get((m["scene"], m["paramlod"], m["peer"]), []))
            lines.append(f"| {m['scene']} | {m['paramlod']} | {m['paramlod_ms']:.1f} | {m['paramlod_error']:.3f} | "
                         f"{m['peer']} | {m['resolution']} | {m['peer_ms']:.1f} | {m['peer_error']:.3f} | "
                         f"{m['ratio']:.2f} | {there} |")
    if result["sampling"]:
        lines += ["", f"Sampling the bunny; evenness: nearest-neighbour distance over the hexagonal spacing "
                      f"(min, CV), of all points and of the first {PREFIX:,}:", "",
                  "| tool | version | asked | got | seconds | min | CV | prefix min | prefix CV |",
                  "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
        for r in result["sampling"]:
            pre = r.get("prefix")
            lines.append(f"| {r['tool']} | {r['version']} | {r['n']:,} | {r['got']:,} | {r['seconds']:.2f} | "
                         f"{r['all']['min']:.2f} | {r['all']['cv']:.3f} | "
                         + (f"{pre['min']:.2f} | {pre['cv']:.3f} |" if pre else "| |"))
    for r in result["missing"]:
        lines.append(f"\n{r['tool']}: not installed ({r['install']})")
    for r in result["failed"]:
        hint = f"; {r['hint']}" if r.get("hint") else ""
        where = f" {r['scene']} {r['variant']}" if "scene" in r else ""
        lines.append(f"\n{r['tool']}{where}: {r['status']}{hint}")
    return "\n".join(lines) + "\n"


if __name__ == "__main__" and len(sys.argv) == 4 and sys.argv[1] == "--worker":
    sys.exit(_worker(sys.argv[2], sys.argv[3]))
