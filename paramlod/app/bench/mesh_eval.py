"""The mesh-LOD evaluation of ``paramlod bench`` (extra "mesh-eval"): the cluster DAG against a
discrete LOD chain (paramlod.meshlod.build.chain, what most engines ship) and against the full mesh,
on the same meshes, in one run.

Per mesh (the Stanford bunny scan of pymeshfix: 99,785 triangles, 67 parts, open borders; a mesh of
many small parts made here, deterministically; with ``big``, the bunny split to 1.6 M triangles as
paramlod.app.bench.meshes makes it) and per representation (full / chain / dag):
- build seconds, levels, clusters, triangles stored, bytes in host memory, on the device (the
  mesh's device arrays: float4 vertices and normals, uint32 triangles, Cluster records) and on disk
  (the ``.meshlod`` file, written to a temporary folder);
- four scenarios: ``grid`` (10 x 10 copies under seeded random cameras, paramlod.app.bench.meshes'
  grid_scene / grid_cameras), ``path`` (one copy, the camera from far to near, path_cameras),
  ``close`` (one copy seen from inside its bounding sphere, where a chain must draw level 0) and
  ``move`` (one copy, a slow dolly in: consecutive frames differ a little, so level switches show);
- at each threshold (0.25, 0.5, 1, 2, 4 px; the full mesh once, it has no threshold): frame ms,
  cut and raster ms, clusters and triangles drawn (medians over the frames), drawn by the
  "meshlets" renderer without anti-aliasing;
- image quality of every frame against the full mesh drawn with 16xSS (4 x 4 supersampling of the
  same renderer) from the same camera: 1 - SSIM and FLIP (variants in SSIM_VARIANT, FLIP_VARIANT),
  per frame and averaged. The full mesh's own row (no AA against 16xSS) is the aliasing floor;
- popping (``move``): FLIP between consecutive frames, averaged, minus the full mesh's (the motion
  itself), and the largest excess of one pair;
- the DAG against the chain at equal quality: the chain's frame time interpolated at the DAG's FLIP
  (linear in FLIP between the chain's thresholds), divided by the DAG's.

Driven by paramlod.app.bench.run (``paramlod bench --extras mesh-eval``); ``run_mesh_eval`` is
usable alone. No twin (a measurement). flip_evaluator, scikit-image and matplotlib are imported
when used (``pip install 'paramlod[bench]'``).
"""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from paramlod.app.bench.meshes import bench_meshes, grid_cameras, grid_scene, normalizing, path_cameras
from paramlod.app.bench.plots import pyplot, save_figure
from paramlod.core.camera import Camera
from paramlod.errors import MeshError, ParamlodError
from paramlod.meshlod.buffers import MeshArrays
from paramlod.meshlod.build.chain import build_chain
from paramlod.meshlod.build.dag import build_dag
from paramlod.meshlod.format import save_meshlod
from paramlod.pipeline.driver import render
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.meshes import read_mesh
from paramlod.scene.scene import Material, Scene

REPRESENTATIONS = ("full", "chain", "dag")
THRESHOLDS = (0.25, 0.5, 1.0, 2.0, 4.0)
VARIANT = "meshlets"
REFERENCE_AA = "16xSS"
SCENARIOS = ("grid", "path", "close", "move")
SSIM_VARIANT = ("1 - SSIM: scikit-image structural_similarity on the sRGB-encoded RGB image in [0, 1], the mean "
                "over the three channels and every pixel; Gaussian weights (sigma 1.5, 11 x 11 window), "
                "population covariance, K1 = 0.01, K2 = 0.03, data range 1 (Wang et al. 2004's settings)")
FLIP_VARIANT = ("FLIP: flip_evaluator.evaluate(reference, test, 'LDR', inputsRGB=True), the mean of the error "
                "map, at its default 67 pixels per degree")
_ORIGINAL_VERTEX_BYTES = 32    # the device's float4 position + float4 normal
_MATERIAL = Material((0.75, 0.7, 0.62), two_sided=False)   # closed scans: clusters facing away culled


# --- the meshes ------------------------------------------------------------------------------------
def parts_mesh(count: int = 1000, seed: int = 0, subdiv: int = 1, box: float = 10.0):
    """(vertices float32, faces uint32) of ``count`` disconnected icospheres (20 * 4^subdiv
    triangles each) of radius 0.05..0.2 at seeded random places in [-box/2, box/2]^3: a mesh of
    many parts, where edge-only clustering never reaches one root."""
    import trimesh

    rng = np.random.default_rng(int(seed))
    unit = trimesh.creation.icosphere(subdivisions=int(subdiv), radius=1.0)
    uv, uf = np.asarray(unit.vertices, np.float64), np.asarray(unit.faces, np.int64)
    centres = rng.uniform(-box / 2, box / 2, size=(int(count), 3))
    radii = rng.uniform(0.05, 0.2, size=(int(count), 1, 1))
    v = (uv[None] * radii + centres[:, None, :]).reshape(-1, 3).astype(np.float32)
    f = (uf[None] + (np.arange(int(count)) * len(uv))[:, None, None]).reshape(-1, 3).astype(np.uint32)
    return v, f


def eval_meshes(big: bool, parts: int = 1000) -> list:
    """(name, vertices, faces, normals, what) of the evaluated meshes."""
    bunny, *rest = bench_meshes(big)
    out = [(*bunny, "Stanford bunny scan (pymeshfix): 67 parts, open borders")]
    if parts:
        m = read_mesh(parts_mesh(parts))
        out.append((f"parts-{parts}", m.vertices, m.faces, m.normals,
                    f"{parts} disconnected icospheres of 80 triangles, scattered (seed 0)"))
    out += [(*r, "the bunny split twice into four") for r in rest]
    return out


def build_representations(name, v, f, n, folder: Path, log=print) -> dict:
    """{representation: (MeshLod, info)}: build seconds, levels, clusters, triangles stored,
    host / device / disk bytes and device bytes against the original mesh's."""
    original = len(v) * _ORIGINAL_VERTEX_BYTES + len(f) * 12
    out = {}
    for rep in REPRESENTATIONS:
        t0 = time.perf_counter()
        if rep == "chain":
            lod = build_chain(v, f, n, name=name, progress=False)
        else:
            lod = build_dag(v, f, n, lod=rep, name=name, progress=False)
        secs = time.perf_counter() - t0
        path = save_meshlod(lod, folder / f"{name}-{rep}.meshlod")
        device = MeshArrays.pack([lod]).nbytes
        info = {"build_s": secs, "levels": lod.levels, "clusters": len(lod.clusters), "roots": len(lod.roots),
                "triangles_stored": len(lod.triangles),
                "triangles_per_level": [int(lod.clusters["count"][lod.clusters["level"] == k].sum())
                                        for k in range(lod.levels)],
                "host_bytes": lod.nbytes, "device_bytes": device, "disk_bytes": path.stat().st_size,
                "device_vs_original": device / original}
        out[rep] = (lod, info)
        log(f"mesh-eval build {name} {rep}: {secs:.2f} s, {info['levels']} levels, {info['clusters']:,} clusters, "
            f"{info['triangles_stored']:,} triangles, device {device / 2 ** 20:.1f} MiB ({info['device_vs_original']:.2f}x)")
    return out


# --- cameras and scenes --------------------------------------------------------------------------------
def move_cameras(count: int, size, far: float = 6.0, near: float = 2.0, turn: float = 0.15) -> list:
    """A slow dolly towards the mesh at the origin (radius about 1): ``far`` to ``near`` units,
    turning ``turn`` radians, in ``count`` frames."""
    cams = []
    for k in range(count):
        t = k / max(count - 1, 1)
        d = far * (near / far) ** t
        a = turn * t
        eye = (d * np.sin(a), 0.25 * d, d * np.cos(a))
        cams.append(Camera.look_at(eye, (0, 0, 0), (0, 1, 0), 45.0, size, near=0.01, far=1000.0))
    return cams


def close_cameras(count: int, size, distance: float = 1.3, elevation: float = 0.15, sweep: float = 0.3) -> list:
    """Close to the mesh at the origin (scaled into [-1, 1]): ``distance`` units from its centre on
    the +z side, ``elevation`` radians up, swept from -``sweep`` to +``sweep`` radians round it.
    The eye stays outside the mesh's box and inside its bounding sphere (radius 1.34 for the bunny,
    1.56 for the parts), where a chain must draw its level 0."""
    cams = []
    for k in range(count):
        a = sweep * (2 * k / max(count - 1, 1) - 1)
        eye = distance * np.array([np.cos(elevation) * np.sin(a), np.sin(elevation), np.cos(elevation) * np.cos(a)])
        cams.append(Camera.look_at(eye, (0, 0, 0), (0, 1, 0), 45.0, size, near=0.01, far=1000.0))
    return cams


def single_scene(lod) -> Scene:
    s = Scene()
    s.add_mesh(lod, transform=normalizing(lod.vertices), material=_MATERIAL)
    return s


def scenario_setups(size, frames: int, move_frames: int, grid: int) -> dict:
    """{scenario: (scene maker, cameras, slow)}: ``slow`` marks the scenario whose consecutive
    frames measure popping."""
    return {"grid": (lambda lod: grid_scene(lod, grid), grid_cameras(frames, size), False),
            "path": (single_scene, path_cameras(frames, size), False),
            "close": (single_scene, close_cameras(frames, size), False),
            "move": (single_scene, move_cameras(move_frames, size), True)}


# --- the quality metrics ----------------------------------------------------------------------------
def as_image(img, what: str = "image") -> np.ndarray:
    """float32 H x W x 3 in [0, 1] (sRGB-encoded) from an sRGB uint8 image or a float image already
    in [0, 1]; MeshError naming ``what`` otherwise (flip_evaluator takes uint8 silently as 0..255
    and ends the process on a bad shape, so nothing reaches it unchecked)."""
    a = np.asarray(img)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise MeshError(f"{what}: expected an H x W x 3 RGB image, got shape {a.shape}")
    if a.dtype == np.uint8:
        return (a.astype(np.float32) / np.float32(255)).copy()
    if a.dtype.kind != "f":
        raise MeshError(f"{what}: expected uint8 sRGB or float RGB in [0, 1], got {a.dtype}")
    if not np.isfinite(a).all():
        raise MeshError(f"{what}: float RGB must be finite, {int(np.sum(~np.isfinite(a)))} values are not")
    if a.min() < 0 or a.max() > 1:
        raise MeshError(f"{what}: float RGB must be in [0, 1] (sRGB-encoded), got {float(a.min()):.3g}..{float(a.max()):.3g}")
    return np.ascontiguousarray(a, np.float32)


def _pair(reference, test):
    ref, tst = as_image(reference, "reference image"), as_image(test, "test image")
    if ref.shape != tst.shape:
        raise MeshError(f"the reference image is {ref.shape[1]}x{ref.shape[0]} and the test image "
                        f"{tst.shape[1]}x{tst.shape[0]}: compare images of one size")
    return ref, tst


def flip(reference, test) -> float:
    """Mean FLIP of ``test`` against ``reference`` (LDR, sRGB inputs; FLIP_VARIANT)."""
    ref, tst = _pair(reference, test)
    try:
        import flip_evaluator
    except ImportError:
        raise MeshError("the mesh-LOD evaluation needs flip-evaluator: pip install 'paramlod[bench]'") from None
    try:
        _, mean, _ = flip_evaluator.evaluate(ref, tst, "LDR", inputsRGB=True, applyMagma=False, computeMeanError=True)
    except SystemExit as exc:   # its argument checks exit the process
        raise MeshError(f"flip_evaluator refused the images ({exc})") from None
    return float(mean)


def ssim_error(reference, test) -> float:
    """1 - SSIM of ``test`` against ``reference`` (SSIM_VARIANT); 0 for identical images."""
    ref, tst = _pair(reference, test)
    if min(ref.shape[:2]) < 11:
        raise MeshError(f"1 - SSIM needs images of at least 11 x 11 pixels (its Gaussian window), got "
                        f"{ref.shape[1]}x{ref.shape[0]}")
    try:
        from skimage.metrics import structural_similarity
    except ImportError:
        raise MeshError("the mesh-LOD evaluation needs scikit-image: pip install 'paramlod[bench]'") from None
    s = structural_similarity(ref.astype(np.float64), tst.astype(np.float64), data_range=1.0, channel_axis=2,
                              gaussian_weights=True, sigma=1.5, use_sample_covariance=False, K1=0.01, K2=0.03)
    return float(1.0 - s)


# --- frames -----------------------------------------------------------------------------------------------
def _settings(threshold: float, aa: str | None = None) -> RenderSettings:
    rs = RenderSettings()
    rs.mesh.threshold_px = float(threshold)
    if aa:
        rs.apply_aa(aa, points_only=True)
    return rs


def draw(scene, cams, threshold: float, warmup: int, aa: str | None = None) -> tuple[list, list]:
    """(stats, sRGB uint8 images) of ``cams`` drawn after ``warmup`` untimed frames."""
    rs = _settings(threshold, aa)
    stats, images = [], []
    for k, cam in enumerate([*cams[:warmup], *cams]):
        frame = render(scene, cam, VARIANT, rs)
        if k >= warmup:
            stats.append(dict(frame.stats))
            images.append(np.array(frame.rgb8(), copy=True))
        del frame   # its key buffers go back to the pool
    return stats, images


def _summary(stats: list) -> dict:
    med = statistics.median
    ms = [s["ms"] for s in stats]
    frame = [m.get("frame", m.get("total", 0.0)) for m in ms]
    return {"frames": len(stats), "frame_ms": med(frame), "frame_ms_p95": float(np.percentile(frame, 95)),
            "cut_ms": med(m.get("cut", 0.0) for m in ms), "raster_ms": med(m.get("render", 0.0) for m in ms),
            "clusters_drawn": med(s.get("clusters_drawn", 0) for s in stats),
            "triangles_drawn": med(s.get("triangles_drawn", 0) for s in stats),
            "triangles_drawn_mean": float(np.mean([s.get("triangles_drawn", 0) for s in stats])),
            "frame_ms_frames": frame, "triangles_frames": [s.get("triangles_drawn", 0) for s in stats],
            "device_bytes_total": stats[-1].get("mesh_device_bytes", 0)}


def _consecutive(images: list) -> list:
    return [flip(a, b) for a, b in zip(images, images[1:])]


def equal_quality(rows: list) -> list:
    """Per (mesh, scenario) and DAG threshold: the chain's frame ms and triangles drawn at the DAG's
    mean FLIP (interpolated linearly in FLIP between the chain's thresholds; None outside their
    range) and the ratios chain / DAG. Triangles are exact where frame times are noisy."""
    out = []
    keys = {(r["mesh"], r["scenario"]) for r in rows}
    for mesh, scenario in sorted(keys):
        chain = sorted((r["flip"], r["frame_ms"], r["triangles_drawn"]) for r in rows
                       if (r["mesh"], r["scenario"], r["representation"]) == (mesh, scenario, "chain"))
        for d in (r for r in rows if (r["mesh"], r["scenario"], r["representation"]) == (mesh, scenario, "dag")):
            ms = tris = None
            if chain and chain[0][0] <= d["flip"] <= chain[-1][0]:
                xs = [c[0] for c in chain]
                ms = float(np.interp(d["flip"], xs, [c[1] for c in chain]))
                tris = float(np.interp(d["flip"], xs, [c[2] for c in chain]))
            out.append({"mesh": mesh, "scenario": scenario, "dag_threshold_px": d["threshold_px"], "flip": d["flip"],
                        "dag_ms": d["frame_ms"], "chain_ms_at_flip": ms,
                        "chain_over_dag": ms / d["frame_ms"] if ms is not None and d["frame_ms"] > 0 else None,
                        "dag_triangles": d["triangles_drawn"], "chain_triangles_at_flip": tris,
                        "chain_over_dag_triangles": (tris / d["triangles_drawn"]
                                                     if tris is not None and d["triangles_drawn"] > 0 else None)})
    return out


def run_mesh_eval(size, frames: int = 8, warmup: int = 1, big: bool = False, grid: int = 10,
                  thresholds=THRESHOLDS, move_frames: int = 24, parts: int = 1000, scenarios=SCENARIOS,
                  log=print) -> dict:
    """The evaluation (module docstring) at frame ``size`` = (w, h): ``frames`` per scenario
    (``move_frames`` for the slow move), ``grid`` copies per side, ``parts`` in the many-parts mesh
    (0: none), ``big``: also the 1.6 M-triangle bunny. Returns the results as a JSON-able dict."""
    thresholds = [float(t) for t in thresholds]
    if not thresholds or any(not np.isfinite(t) or t < 0 for t in thresholds):
        raise MeshError(f"mesh-eval thresholds must be pixel counts >= 0, got {thresholds}")
    unknown = [s for s in scenarios if s not in SCENARIOS]
    if unknown:
        raise MeshError(f"unknown mesh-eval scenario(s) {', '.join(unknown)} (known: {', '.join(SCENARIOS)})")
    if frames < 1 or move_frames < 2 or grid < 1:
        raise MeshError(f"mesh-eval needs frames >= 1, move frames >= 2 and grid >= 1, got {frames}, {move_frames}, {grid}")
    res = {"size": list(size), "variant": VARIANT, "reference": f"full mesh, {VARIANT} with {REFERENCE_AA}",
           "ssim": SSIM_VARIANT, "flip": FLIP_VARIANT, "thresholds": thresholds, "grid": grid, "frames": frames,
           "move_frames": move_frames, "warmup": warmup, "representations": list(REPRESENTATIONS),
           "meshes": [], "rows": []}
    setups = {k: v for k, v in scenario_setups(size, frames, move_frames, grid).items() if k in scenarios}
    with tempfile.TemporaryDirectory(prefix="paramlod-mesh-eval-") as tmp:
        for name, v, f, n, what in eval_meshes(big, parts):
            reps = build_representations(name, v, f, n, Path(tmp), log)
            res["meshes"].append({"mesh": name, "what": what, "triangles": int(len(f)), "vertices": int(len(v)),
                                  "original_device_bytes": int(len(v) * _ORIGINAL_VERTEX_BYTES + len(f) * 12),
                                  "representations": {r: info for r, (_, info) in reps.items()}})
            for scenario, (make, cams, slow) in setups.items():
                scenes = {r: make(lod) for r, (lod, _) in reps.items()}
                _, refs = draw(scenes["full"], cams, 0.0, 0, REFERENCE_AA)
                full_pairs = None
                for rep in REPRESENTATIONS:
                    for t in ([None] if rep == "full" else thresholds):
                        try:
                            row = _measure(scenes[rep], cams, t, warmup, refs)
                        except ParamlodError as exc:
                            res["rows"].append({"mesh": name, "scenario": scenario, "representation": rep,
                                                "threshold_px": t, "error": str(exc)})
                            log(f"mesh-eval {name} {scenario} {rep} {t}: error: {exc}")
                            continue
                        images = row.pop("_images")
                        if slow:
                            pairs = _consecutive(images)
                            if rep == "full":
                                full_pairs = pairs
                            row["consecutive_flip_frames"] = pairs
                            row["consecutive_flip"] = float(np.mean(pairs))
                            if full_pairs is not None:
                                excess = np.asarray(pairs) - np.asarray(full_pairs)
                                row["popping"] = float(np.mean(excess))
                                row["popping_max"] = float(np.max(excess))
                        res["rows"].append({"mesh": name, "scenario": scenario, "representation": rep,
                                            "threshold_px": t, **row})
                        log(f"mesh-eval {name} {scenario} {rep} {'-' if t is None else f'{t:g} px'}: "
                            f"{row['frame_ms']:.2f} ms, {row['triangles_drawn']:,.0f} triangles, "
                            f"1-SSIM {row['ssim_error']:.4f}, FLIP {row['flip']:.4f}"
                            + (f", popping {row['popping']:+.4f}" if "popping" in row else ""))
                del scenes
    res["equal_quality"] = equal_quality([r for r in res["rows"] if "error" not in r])
    return res


def _measure(scene, cams, threshold, warmup, refs) -> dict:
    stats, images = draw(scene, cams, 0.0 if threshold is None else threshold, warmup)
    row = _summary(stats)
    row["ssim_error_frames"] = [ssim_error(r, i) for r, i in zip(refs, images)]
    row["flip_frames"] = [flip(r, i) for r, i in zip(refs, images)]
    row["ssim_error"] = float(np.mean(row["ssim_error_frames"]))
    row["flip"] = float(np.mean(row["flip_frames"]))
    row["_images"] = images
    return row


# --- the report --------------------------------------------------------------------------------------
def _mib(n) -> str:
    return f"{n / 2 ** 20:.2f}"


def format_mesh_eval(res: dict) -> list[str]:
    """The markdown section of the evaluation: memory and build, time and quality, popping, equal
    quality."""
    lines = ["", "## Mesh LOD: full mesh, discrete chain, cluster DAG", "",
             f"{res['size'][0]}x{res['size'][1]}, renderer {res['variant']} without AA; quality against the "
             f"{res['reference']}. Grid {res['grid']}x{res['grid']}, {res['frames']} frames per scenario "
             f"({res['move_frames']} for the slow move) after {res['warmup']} warm-up; medians.",
             f"- {res['ssim']}.", f"- {res['flip']}.",
             "- Popping (the slow move): the mean over consecutive frame pairs of FLIP(frame i, frame i+1) minus the "
             "full mesh's for the same pair (the motion itself; in brackets on the full mesh's row), and the largest "
             "excess of one pair (pop max). Negative: steadier than the full mesh without AA, whose small triangles "
             "flicker.",
             "", "| mesh | representation | build s | levels | clusters | triangles stored | host MiB | device MiB | "
             "file MiB | device / original |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for m in res["meshes"]:
        for rep, i in m["representations"].items():
            lines.append(f"| {m['mesh']} | {rep} | {i['build_s']:.2f} | {i['levels']} | {i['clusters']:,} | "
                         f"{i['triangles_stored']:,} | {_mib(i['host_bytes'])} | {_mib(i['device_bytes'])} | "
                         f"{_mib(i['disk_bytes'])} | {i['device_vs_original']:.2f} |")
    lines += ["", "Original: the mesh's float4 positions and normals and uint32 triangles on the device, no cluster "
              "records.", "",
              "| mesh | scenario | representation | px | frame ms | cut ms | raster ms | clusters | triangles | "
              "1 - SSIM | FLIP | popping | pop max |", "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in res["rows"]:
        px = "-" if r["threshold_px"] is None else f"{r['threshold_px']:g}"
        if "error" in r:
            lines.append(f"| {r['mesh']} | {r['scenario']} | {r['representation']} | {px} | error: {r['error']} |")
            continue
        pop = (f"{r['popping']:+.4f} | {r['popping_max']:+.4f}" if "popping" in r else
               f"({r['consecutive_flip']:.4f}) |" if "consecutive_flip" in r else " |")
        lines.append(f"| {r['mesh']} | {r['scenario']} | {r['representation']} | {px} | {r['frame_ms']:.2f} | "
                     f"{r['cut_ms']:.3f} | {r['raster_ms']:.2f} | {r['clusters_drawn']:,.0f} | "
                     f"{r['triangles_drawn']:,.0f} | {r['ssim_error']:.4f} | {r['flip']:.4f} | {pop} |")
    eq = res.get("equal_quality", [])
    if eq:
        lines += ["", "At equal FLIP: the chain's frame ms and triangles interpolated at the DAG's FLIP (- where the "
                  "DAG's FLIP is outside the chain's range).", "",
                  "| mesh | scenario | DAG px | FLIP | DAG ms | chain ms | chain / DAG ms | DAG triangles | "
                  "chain triangles | chain / DAG triangles |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for e in eq:
            def num(x, fmt):
                return "-" if x is None else format(x, fmt)
            lines.append(f"| {e['mesh']} | {e['scenario']} | {e['dag_threshold_px']:g} | {e['flip']:.4f} | "
                         f"{e['dag_ms']:.2f} | {num(e['chain_ms_at_flip'], '.2f')} | {num(e['chain_over_dag'], '.2f')} | "
                         f"{e['dag_triangles']:,.0f} | {num(e['chain_triangles_at_flip'], ',.0f')} | "
                         f"{num(e['chain_over_dag_triangles'], '.2f')} |")
    return lines


def plot_mesh_eval(res: dict, out: Path) -> list[Path]:
    """Per mesh: frame ms against threshold (per scenario), FLIP against frame ms, and bytes per
    representation; [] without matplotlib."""
    plt = pyplot()
    if plt is None:
        return []
    paths = []
    colours = {"full": "0.3", "chain": "tab:orange", "dag": "tab:blue"}
    for m in res["meshes"]:
        rows = [r for r in res["rows"] if r["mesh"] == m["mesh"] and "error" not in r]
        scen = [s for s in SCENARIOS if any(r["scenario"] == s for r in rows)]
        fig, axes = plt.subplots(1, 3, figsize=(14, 4))
        a, b, c = axes
        for s, style in zip(scen, ("-", "--", "-.", ":")):
            for rep in ("chain", "dag"):
                pts = sorted((r["threshold_px"], r["frame_ms"]) for r in rows if r["scenario"] == s and r["representation"] == rep)
                if pts:
                    a.plot(*zip(*pts), style, marker="o", color=colours[rep], label=f"{rep}, {s}")
            full = [r["frame_ms"] for r in rows if r["scenario"] == s and r["representation"] == "full"]
            if full:
                a.axhline(full[0], linestyle=style, color=colours["full"], label=f"full, {s}")
            for rep in REPRESENTATIONS:
                # in threshold order: the curve a threshold sweep traces
                pts = [(r["frame_ms"], r["flip"]) for r in sorted(
                    (r for r in rows if r["scenario"] == s and r["representation"] == rep),
                    key=lambda r: r["threshold_px"] or 0.0)]
                if pts:
                    b.plot(*zip(*pts), style, marker="o" if rep != "full" else "s", color=colours[rep], label=f"{rep}, {s}")
        a.set_xscale("log", base=2)
        a.set_yscale("log")
        a.set_xlabel("threshold (px)")
        a.set_ylabel("frame ms")
        a.set_title("time against threshold")
        a.legend(fontsize=7)
        b.set_xscale("log")
        b.set_xlabel("frame ms")
        b.set_ylabel("mean FLIP against full 16xSS")
        b.set_title("quality against time")
        b.legend(fontsize=7)
        reps = list(m["representations"])
        x = np.arange(len(reps))
        for k, (key, label) in enumerate((("host_bytes", "host"), ("device_bytes", "device"), ("disk_bytes", "file"))):
            c.bar(x + (k - 1) * 0.27, [m["representations"][r][key] / 2 ** 20 for r in reps], 0.27, label=label)
        c.axhline(m["original_device_bytes"] / 2 ** 20, color="k", linewidth=0.8, label="original on device")
        c.set_xticks(x, reps)
        c.set_ylabel("MiB")
        c.set_title("memory per representation")
        c.legend(fontsize=7)
        fig.suptitle(f"{m['mesh']} ({m['triangles']:,} triangles), {res['size'][0]}x{res['size'][1]}", fontsize=9)
        paths.append(save_figure(fig, Path(out) / f"mesh_eval_{m['mesh']}.png"))
    return paths
