import numpy as np
import pyopencl.array as cla
import pytest
from hypothesis import settings

import paramlod as pl
from paramlod.device.context import cl_device
from paramlod.renderers.points import DirectPointRenderer, grid_counts, patch_wraps
from paramlod.renderers.targets import KeyBuffer
from paramlod.scene import loaders

from helpers.stages import ParametricStage as renderer_for

# Hypothesis draws the same examples on every run, so a CI result does not depend on luck (a random
# example once found a known open bug, docs/points.md); the properties are unchanged.
settings.register_profile("deterministic", derandomize=True)
settings.load_profile("deterministic")


def sphere_disc(camera, center=(0, 0, 0), radius=1.0):
    """Analytic silhouette mask of a sphere seen by ``camera`` (pixel centres)."""
    w, h = camera.size
    ys, xs = np.mgrid[0:h, 0:w]
    ndc = np.stack([(xs + 0.5) / w * 2 - 1, 1 - (ys + 0.5) / h * 2], axis=-1)
    inv = np.linalg.inv(camera.projection @ camera.view)
    near = np.concatenate([ndc, -np.ones((h, w, 1)), np.ones((h, w, 1))], axis=-1) @ inv.T
    far = np.concatenate([ndc, np.ones((h, w, 1)), np.ones((h, w, 1))], axis=-1) @ inv.T
    o = near[..., :3] / near[..., 3:]
    d = far[..., :3] / far[..., 3:] - o
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    oc = o - np.asarray(center, float)
    b = np.sum(oc * d, axis=-1)
    c = np.sum(oc * oc, axis=-1) - radius ** 2
    disc = b * b - c
    hit = disc >= 0
    t = -b - np.sqrt(np.where(hit, disc, 0))
    # linear view depth of the front hit
    pts = o + t[..., None] * d
    depth = -(np.concatenate([pts, np.ones((h, w, 1))], axis=-1) @ camera.view.T)[..., 2]
    return hit, np.where(hit, depth, np.inf)


def iou(a, b):
    return np.logical_and(a, b).sum() / max(1, np.logical_or(a, b).sum())


@pytest.fixture
def sphere_scene():
    s = pl.Scene()
    s.add("sphere")
    return s


NOT_VISITED = 0xFFFFFFFE


def record_direct_points(settings, size, scene=None, cam=None):
    """A sphere and a torus (or ``scene`` seen by ``cam``) drawn by the direct point renderer with
    its recording test hook.
    Returns (stats, colour keys flattened, each sample's pixel (~0 when dropped, NOT_VISITED if
    the renderer never reached it), each sample's colour key, the sample count the numpy twin of
    the sample counts predicts)."""
    if scene is None:
        scene = pl.Scene()
        scene.add("sphere", material=pl.Material(color=(0.9, 0.4, 0.2)))
        scene.add("torus", transform=pl.translate(0.8, 0.2, 0.3) @ pl.rotate(70, (1, 0, 0)))
        cam = pl.Camera.look_at((0.5, 0.8, 3.5), (0.3, 0, 0), size=size)
    r = renderer_for(scene)
    dev = r.upload(scene, cam)
    rbuf, n, _, _ = r.lod.run(dev["inst"], dev["domains"], dev["cam"], pl.LodSettings(), one_sided=dev["one_sided"])
    rl = r.lod.read_render_list(n)
    nu, nv = grid_counts(rl, settings, wraps=patch_wraps(rl, dev["flags"], dev["domains"]))
    counts = nu * nv
    total = int(counts.sum())
    q = cl_device().queue
    rec = DirectPointRenderer(scene.functions(), record=True)
    off = cla.to_device(q, np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.uint32))
    pix = cla.empty(q, total, np.uint32)
    pix.fill(NOT_VISITED)
    key = cla.empty(q, total, np.uint64)
    keys = KeyBuffer(*cam.size)
    keys.clear()
    stats = rec.draw(rbuf, n, dev["inst"], dev["materials"], dev["cam"], dev["light"], keys, settings,
                     record_args=(off.data, pix.data, key.data))
    color, _ = keys.read_keys()
    return stats, color.reshape(-1), pix.get(), key.get(), total


def check_every_sample_once(stats, color, pix, key, total):
    """The work-groups' shares of the samples (kernels/points.cl, points_schedule) cover every
    sample of every patch once: none is left unvisited, the count matches, and the key buffer is
    np.minimum.at over the recorded samples. Returns the colour keys."""
    assert stats["samples"] == total
    assert not (pix == NOT_VISITED).any()
    kept = pix != 0xFFFFFFFF
    assert kept.sum() > 1000
    expect = np.full(color.size, np.iinfo(np.uint64).max, np.uint64)
    np.minimum.at(expect, pix[kept], key[kept])
    np.testing.assert_array_equal(color, expect)
    return color


# --- stored-reference images (tests/pipeline/test_reference_images.py) ---------------------------------

import contextlib  # noqa: E402


def pytest_addoption(parser):
    parser.addoption("--regen-refs", action="store_true", default=False,
                     help="rewrite the stored reference images in tests/refs/ instead of comparing")


@pytest.fixture(autouse=True, scope="session")
def _mesh_cache(tmp_path_factory):
    """Mesh builds cached in a folder of this run, never in the user's ~/.cache."""
    import os

    old = os.environ.get("PARAMLOD_CACHE")
    os.environ["PARAMLOD_CACHE"] = str(tmp_path_factory.mktemp("paramlod-cache"))
    yield
    if old is None:
        os.environ.pop("PARAMLOD_CACHE", None)
    else:
        os.environ["PARAMLOD_CACHE"] = old


@pytest.fixture
def mesh_loader():
    """The calls scenes make to the registered "mesh" loader (paramlod.meshlod's), as (source, options)."""
    previous, calls = loaders.LOADERS["mesh"], []

    def counting(source, **options):
        calls.append((source, options))
        return previous(source, **options)

    loaders.register_loader("mesh", counting)
    yield calls
    loaders.register_loader("mesh", previous)


@pytest.fixture(scope="session")
def regen_refs(request):
    """None when comparing; with --regen-refs, a list the reference tests add each file they
    wrote to, reported at the end of the session."""
    if not request.config.getoption("--regen-refs"):
        yield None
        return
    written = []
    yield written
    lines = [f"--regen-refs wrote {len(written)} reference file(s):"] + [f"  {p}" for p in written]
    plugins = request.config.pluginmanager
    reporter, capture = plugins.get_plugin("terminalreporter"), plugins.get_plugin("capturemanager")
    with capture.global_and_fixture_disabled() if capture else contextlib.nullcontext():
        if reporter is not None:
            reporter.write_line("")
            for line in lines:
                reporter.write_line(line)
        else:
            print("\n".join(lines))
