"""Blue surfels on a real scanned mesh (the Stanford bunny shipped in the pymeshfix wheel):
blue-noise prefixes, samples on the surface, hole-free renders, progressive coverage."""
import importlib.resources

import numpy as np
import pytest

import trimesh  # noqa: E402
import scipy.spatial as spatial  # noqa: E402

from paramlod.core.camera import Camera  # noqa: E402
from paramlod.surfels import FixedCount, FixedSize, SurfelSet, render_surfels  # noqa: E402
from paramlod.surfels.build import load_mesh, mesh_gbuffer, sample_gbuffer  # noqa: E402
from paramlod.surfels.format import nearest_neighbour_distances  # noqa: E402
from paramlod.surfels.build.raster_reference import raster_keys  # noqa: E402
from paramlod.surfels.build.schedule import ALL_ONES  # noqa: E402

N = 10_000


def bunny_path() -> str:
    p = importlib.resources.files("pymeshfix").joinpath("examples/StanfordBunny.ply")
    assert p.is_file(), "pymeshfix (a test dependency) should ship examples/StanfordBunny.ply"
    return str(p)


@pytest.fixture(scope="module")
def bunny():
    path = bunny_path()
    return trimesh.load(path, process=False), load_mesh(path)


@pytest.fixture(scope="module")
def gbuf(bunny):
    return mesh_gbuffer(bunny[1], views=8, resolution=128)


@pytest.fixture(scope="module")
def surfels(gbuf):
    s = sample_gbuffer(gbuf, N, seed=0)
    assert len(s) == N
    return s


def nn(points):
    d, _ = spatial.cKDTree(points).query(points, k=2)
    return d[:, 1]


def test_prefixes_are_blue_noise(bunny, surfels):
    mesh, _ = bunny
    rnd, _ = trimesh.sample.sample_surface(mesh, N, seed=7)
    scaled = []
    for n in (100, 1000, 10_000):
        d = nn(surfels.positions[:n].astype(np.float64))
        dr = nn(rnd[:n])
        assert d.min() >= 1.5 * dr.min(), (n, d.min(), dr.min())
        scaled.append(d.mean() * np.sqrt(n))
    scaled = np.array(scaled)
    assert (scaled.max() - scaled.min()) / scaled.mean() < 0.20, scaled


def test_surfels_lie_on_the_surface(bunny, surfels):
    mesh, _ = bunny
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    tris = mesh.triangles
    _, cand = spatial.cKDTree(tris.mean(axis=1)).query(surfels.positions, k=8)
    pts = np.repeat(surfels.positions.astype(np.float64), 8, axis=0)
    closest = trimesh.triangles.closest_point(tris[cand.reshape(-1)], pts)
    dist = np.linalg.norm(closest - pts, axis=1).reshape(-1, 8).min(axis=1)  # an upper bound
    assert dist.max() < 0.01 * diag, dist.max() / diag


def test_set_contents(surfels, gbuf):
    assert np.allclose(np.linalg.norm(surfels.normals, axis=1), 1, atol=1e-4)
    assert surfels.radii[0] >= surfels.radii.max() - 1e-6
    assert np.all(surfels.radii[1:] > 0)
    m = 1000
    expect = np.mean(nearest_neighbour_distances(surfels.positions[:m])) ** 2 * m
    assert surfels.packing == pytest.approx(expect, rel=1e-9)
    assert surfels.meta["views"] == 8 and surfels.meta["resolution"] == 128
    # every surfel is a distinct G-buffer point
    assert len(np.unique(surfels.positions, axis=0)) == N


def nominal_camera(surfels, gbuf, k, size=128, fov=35.0):
    """A perspective camera along G-buffer view k at the distance where 2 px asks for the full set."""
    c, r = surfels.bounding_sphere()
    f = 1 / np.tan(np.radians(fov) / 2)
    depth = surfels.spacing(len(surfels)) * f * size / 2     # nearest depth of the object
    eye = c - gbuf.views.directions[k] * (depth + r)
    return Camera.look_at(eye, c, up=gbuf.views.ups[k], fov_y=fov, size=(size, size), near=1.0, far=1000.0)


def silhouette(soup, cam):
    """The pixels whose centre the mesh covers in ``cam`` (the G-buffer raster's numpy twin on the
    perspective projection of the corners)."""
    w, h = cam.size
    p = np.concatenate([soup.positions.astype(np.float64), np.ones((*soup.positions.shape[:2], 1))], axis=-1)
    clip = p @ (cam.projection @ cam.view).T
    ndc = clip[..., :3] / clip[..., 3:]
    window = np.stack([(ndc[..., 0] + 1) / 2 * w, (1 - ndc[..., 1]) / 2 * h, clip[..., 3]], axis=-1)
    assert w == h and np.all(clip[..., 3] > 0)
    return raster_keys(window[None].astype(np.float32), w)[0] != ALL_ONES


def erode(mask):
    m = mask.copy()
    m[1:, :] &= mask[:-1, :]
    m[:-1, :] &= mask[1:, :]
    m[:, 1:] &= mask[:, :-1]
    m[:, :-1] &= mask[:, 1:]
    return m


@pytest.mark.parametrize("k", [0, 5])
def test_full_prefix_has_no_holes_at_nominal_distance(bunny, gbuf, surfels, k):
    cam = nominal_camera(surfels, gbuf, k)
    frame = render_surfels(surfels, cam, FixedSize(2.0))
    st = frame.stats["surfels"]
    assert st["prefix"] == N and not st["saturated"]
    mask = silhouette(bunny[1], cam)
    inner = erode(mask)
    assert inner.sum() > 500
    holes = inner & ~frame.coverage
    assert holes.sum() == 0, np.argwhere(holes)[:10]
    # and the discs stay on the object: little spills past the silhouette
    assert (frame.coverage & ~mask).sum() < 0.05 * mask.sum()


def test_growing_prefixes_cover_progressively(bunny, gbuf, surfels):
    cam = nominal_camera(surfels, gbuf, 0)
    mask = silhouette(bunny[1], cam)
    # discs of the full prefix's size: coverage grows with the prefix
    r_full = surfels.spacing(N)
    cov = []
    for n in (100, 1000, 10_000):
        from paramlod.renderers.targets import KeyBuffer
        from paramlod.surfels import draw_surfels

        keys = KeyBuffer(*cam.size)
        keys.clear()
        s = surfels.prefix(n)
        s.packing = r_full ** 2 * n      # same disc size for every prefix
        draw_surfels(keys, cam, s, FixedCount(n))
        cov.append((keys.resolve().coverage & mask).sum() / mask.sum())
    assert cov[0] < cov[1] < cov[2]
    assert cov[0] < 0.2 and cov[2] > 0.99, cov
    # discs sized by the render law: every prefix covers the silhouette, ever more tightly
    ious = []
    for n in (100, 1000, 10_000):
        c = render_surfels(surfels, cam, FixedCount(n)).coverage
        assert (c & mask).sum() / mask.sum() > 0.98
        ious.append((c & mask).sum() / (c | mask).sum())
    assert ious[0] < ious[1] < ious[2] and ious[2] > 0.95, ious


def test_orthographic_render_matches_the_gbuffer_view(gbuf, surfels):
    k = 3
    cam = gbuf.views.camera(k)
    frame = render_surfels(surfels, cam, FixedSize(2.0))
    valid = gbuf.valid[k]
    cov = frame.coverage
    assert (cov & valid).sum() / (cov | valid).sum() > 0.95
    assert np.all(frame.object_id[cov] == 1)


def test_file_round_trip(tmp_path, surfels):
    p = surfels.save(tmp_path / "bunny.surfels")
    back = SurfelSet.load(p)
    for name in ("positions", "normals", "colors", "radii"):
        assert np.array_equal(getattr(back, name), getattr(surfels, name))
    assert back.packing == surfels.packing and back.meta == surfels.meta
