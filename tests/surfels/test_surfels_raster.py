"""The mesh G-buffers' OpenCL raster (kernels/surfels/surfels_raster.cl) against its numpy twin,
and what the sampler needs of it: closed meshes without cracks, the nearest surface, positions
on the mesh, normals towards the viewer."""
import numpy as np
import pytest
import trimesh

from paramlod.surfels.build import raster, raster_reference as rr
from paramlod.surfels.build.schedule import ALL_ONES
from paramlod.surfels.build.sources import TriangleSoup, soup_from_trimesh
from paramlod.surfels.build.views import make_views


def ball(subdivisions=3):
    return soup_from_trimesh(trimesh.creation.icosphere(subdivisions=subdivisions), "ball")


def odd_soup(seed=3):
    """Random triangles of every size, slivers, zero-area ones and both windings, coloured per corner."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(300, 3, 3)).astype(np.float32)
    p[:100] = p[:100, :1] + 0.02 * (p[:100] - p[:100, :1])    # small
    p[100:120, 2] = p[100:120, 0] + 1e-4 * (p[100:120, 1] - p[100:120, 0])   # slivers
    p[120:130, 1] = p[120:130, 2] = p[120:130, 0]              # no area
    n = rng.normal(size=p.shape).astype(np.float32)
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    c = rng.random(size=(300, 3, 4)).astype(np.float32)
    return TriangleSoup(p, n, c, "odd")


def twin_keys(soup, views):
    return rr.raster_keys(rr.window_coords(soup.positions, rr.view_matrices(views)), views.resolution)


@pytest.mark.parametrize("case", ["ball", "odd", "cropped"])
def test_keys_match_the_twin(case):
    soup = ball() if case == "ball" else odd_soup()
    c, r = soup.bounding_sphere()
    # cropped: views of a third of the object, so triangles cross and leave the views' borders
    views = make_views(c, r / 3 if case == "cropped" else r, 5, 40)
    keys = raster.gbuffer_keys(soup, views)
    expect = twin_keys(soup, views)
    assert (expect != ALL_ONES).sum() > 1000
    assert np.array_equal(keys, expect)


def test_arrays_match_the_twin_and_chunks_change_nothing(monkeypatch):
    soup = odd_soup()
    c, r = soup.bounding_sphere()
    views = make_views(c, r, 5, 40)
    whole = raster.gbuffer_arrays(soup, views)
    expect = rr.resolve(twin_keys(soup, views), soup.positions, soup.normals, soup.colors,
                        rr.view_matrices(views), views.directions)
    for a, b in zip(whole, expect):
        np.testing.assert_allclose(a, b, rtol=0, atol=2e-6)
    monkeypatch.setattr(raster, "CHUNK_BYTES", 2 * 40 * 40 * 16)   # two views at a time
    for a, b in zip(raster.gbuffer_arrays(soup, views), whole):
        assert np.array_equal(a, b)


def test_a_closed_ball_has_no_cracks_and_shows_its_near_side():
    soup = ball()
    c, r = soup.bounding_sphere()
    views = make_views(c, r, 6, 64)
    pos, nrm, col = raster.gbuffer_arrays(soup, views)
    # the icosphere lies between its inscribed radius (faces' centres) and 1 (its corners)
    inner = float(np.linalg.norm(soup.positions.mean(axis=1), axis=1).min())
    for k in range(views.count):
        d = views.directions[k]
        rel = views.pixel_world(k, np.zeros((64, 64))) - c                  # pixel centres
        off = np.linalg.norm(rel - (rel @ d)[..., None] * d, axis=-1)      # from the view's axis
        covered = pos[k, ..., 3] > 0
        assert covered[off < inner - views.pixel_size].all(), "a crack between triangles"
        assert not covered[off > 1.0 + 1e-4].any(), "a pixel outside the ball"
        p = pos[k][covered, :3]
        np.testing.assert_allclose(np.linalg.norm(p - c, axis=1), 1.0, atol=0.02)   # on the surface
        # the near side: depth along d as on the unit sphere's near half (the far half is at +sqrt)
        # (inside 0.9 of the radius, where the halves are at least 0.87 apart)
        mid = off[covered] < 0.9
        near = -np.sqrt(1.0 - off[covered][mid] ** 2)
        assert np.abs((p[mid] - c) @ d - near).max() < 0.02, "a far-side point won the depth test"
        n = nrm[k][covered]
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
        assert np.all(n @ d <= 0), "a normal turned away from the viewer"
        assert np.all(col[k][covered, 3] == pytest.approx(1.0))
        assert np.all(pos[k][~covered] == 0) and np.all(nrm[k][~covered] == 0)


def test_positions_lie_on_their_triangle():
    """Even at near edge-on triangles the position is a convex combination of its corners."""
    soup = odd_soup()
    c, r = soup.bounding_sphere()
    views = make_views(c, r, 4, 48)
    keys = raster.gbuffer_keys(soup, views)
    pos, _, _ = raster.gbuffer_arrays(soup, views)
    covered = keys != ALL_ONES
    t = (keys[covered] & np.uint64(0xFFFFFFFF)).astype(np.int64)
    tri = soup.positions[t].astype(np.float64)
    closest = trimesh.triangles.closest_point(tri, pos[covered][:, :3].astype(np.float64))
    gap = np.linalg.norm(closest - pos[covered][:, :3], axis=1)
    assert gap.max() < 1e-5 * r
