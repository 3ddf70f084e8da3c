"""The final relaxation (surfels/build/relax.py): a more even full set, prefixes that stay even,
surfels that stay on their surface and sheet, and the resolution chosen from the count."""
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from paramlod.errors import SurfelError
from paramlod.surfels.build import mesh_gbuffer, sample_gbuffer, sample_mesh, soup_from_trimesh
from paramlod.surfels.build.relax import auto_iterations
from paramlod.surfels.build.schedule import auto_resolution


def nn(p):
    d, _ = cKDTree(p).query(p, k=2)
    return d[:, 1]


def evenness(p):
    d = nn(p)
    return d.min() / d.mean(), d.std() / d.mean()


@pytest.fixture(scope="module")
def ball_runs():
    g = mesh_gbuffer(soup_from_trimesh(trimesh.creation.icosphere(subdivisions=4), "ball"), views=8, resolution=128)
    return g, sample_gbuffer(g, 3000, seed=4, relax_iterations=0), sample_gbuffer(g, 3000, seed=4)


def test_relaxation_evens_the_full_set(ball_runs):
    _, raw, relaxed = ball_runs
    m0, cv0 = evenness(raw.positions)
    m1, cv1 = evenness(relaxed.positions)
    assert relaxed.meta["relax_iterations"] > 0 and len(relaxed) == len(raw) == 3000
    assert cv1 < 0.75 * cv0 and m1 > m0 + 0.03, (m0, cv0, m1, cv1)


def test_relaxation_keeps_the_order_and_the_prefixes(ball_runs):
    _, raw, relaxed = ball_runs
    # same surfels in the same order: insertion radii untouched, each moved a fraction of the spacing
    assert np.array_equal(raw.radii, relaxed.radii)
    moved = np.linalg.norm(relaxed.positions - raw.positions, axis=1)
    assert moved.max() < 0.5 * nn(raw.positions).mean()
    for m in (30, 300):
        m0, cv0 = evenness(raw.positions[:m])
        m1, cv1 = evenness(relaxed.positions[:m])
        assert m1 > 0.85 * m0 and cv1 < cv0 + 0.02, (m, m0, cv0, m1, cv1)


def test_relaxed_surfels_stay_on_the_surface(ball_runs):
    _, raw, relaxed = ball_runs
    r = np.linalg.norm(relaxed.positions, axis=1)
    assert np.abs(r - 1).max() < 0.01                      # the icosphere's facets are within 0.005
    # the normal of the pixel each surfel ends on (a few silhouette pixels of the G-buffer itself
    # face the wrong way; the relaxation adds none)
    outward = np.sum(relaxed.normals * relaxed.positions, axis=1) / r
    raw_out = np.sum(raw.normals * raw.positions, axis=1) / np.linalg.norm(raw.positions, axis=1)
    assert np.sum(outward < 0.95) <= max(np.sum(raw_out < 0.95), 3)


def test_a_thin_plate_keeps_its_two_sheets():
    # the two faces are 0.02 apart, far closer than the spacing: pairs across the plate repel along
    # the normal, which the relaxation must not turn into moves off or through the plate
    plate = trimesh.creation.box((1.0, 1.0, 0.02))
    g = mesh_gbuffer(soup_from_trimesh(plate, "plate"), views=8, resolution=96)
    s = sample_gbuffer(g, 1500, seed=1)
    p, n = s.positions, s.normals
    outside = np.max(np.abs(p) - [0.5, 0.5, 0.01], axis=1)
    # on the box surface: within half a pixel (past a rim a surfel may overhang its pixel's plane)
    assert np.abs(outside).max() < 0.5 * g.views.pixel_size
    inner = np.max(np.abs(p[:, :2]), axis=1) < 0.5 - g.views.pixel_size    # off the rim faces
    top, bottom = inner & (np.abs(p[:, 2] - 0.01) < 1e-3), inner & (np.abs(p[:, 2] + 0.01) < 1e-3)
    assert top.sum() > 500 and bottom.sum() > 500
    assert np.all(n[top, 2] > 0.9) and np.all(n[bottom, 2] < -0.9)


@pytest.mark.parametrize("bad", [-1, 1.5, True, "4"])
def test_bad_relaxation_count_is_named(bad):
    g = mesh_gbuffer(soup_from_trimesh(trimesh.creation.box(), "box"), views=2, resolution=16)
    with pytest.raises(SurfelError, match="relax_iterations"):
        sample_gbuffer(g, 10, relax_iterations=bad)


def test_resolution_follows_the_count():
    assert [auto_resolution(n) for n in (500, 10_000, 30_000, 100_000, 200_000)] == [64, 128, 256, 384, 512]
    assert [auto_iterations(n, auto_resolution(n)) for n in (10_000, 100_000, 200_000)] == [16, 24, 24]
    s = sample_mesh(trimesh.creation.icosphere(subdivisions=2), 500, views=4)
    assert s.meta["resolution"] == 64 and len(s) == 500
