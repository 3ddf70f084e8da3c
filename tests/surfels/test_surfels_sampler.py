"""The sampler's OpenCL passes against their numpy twins (bit for bit), determinism, the interior
cavity, parametric sources."""
import numpy as np
import pytest

import trimesh  # noqa: E402

import paramlod as pl  # noqa: E402
from paramlod.surfels import SurfelSet  # noqa: E402
from paramlod.surfels.build import (Sampler, mesh_gbuffer, sample_gbuffer, sample_mesh, sample_scene,  # noqa: E402
                                    soup_from_trimesh)
from paramlod.surfels.build import reference as ref  # noqa: E402
from paramlod.surfels.build.sampler import run_levels  # noqa: E402
from paramlod.surfels.build.schedule import (level_strides, pair_survivors, remap_keys, splat_r2,  # noqa: E402
                                             threshold_r2)


def two_parts():
    """A box and a capsule that partly hide each other (occlusion, two components)."""
    box = trimesh.creation.box((1.0, 0.6, 0.8))
    cap = trimesh.creation.capsule(height=1.2, radius=0.3, count=[12, 12])
    cap.apply_translation((0.5, 0.2, 0.3))
    return soup_from_trimesh(trimesh.util.concatenate([box, cap]), "box+capsule")


@pytest.fixture(scope="module")
def small_gbuf():
    return mesh_gbuffer(two_parts(), views=4, resolution=24)


@pytest.mark.parametrize("host", [True, False], ids=["host-survivors", "device-survivors"])
def test_every_pass_matches_numpy(small_gbuf, host):
    # CPU devices find the survivors on the host (conflicts from the candidates' pairs, compaction
    # and sort), GPUs with the disc splats, copy_if and radix sort: both must give the twin's keys
    s = Sampler(small_gbuf, 400, seed=3, host_survivors=host)
    pos = s.pos_host
    s.start()
    seed = s.seed_pixel()
    samples = np.zeros(400, np.uint64)
    samples[0] = seed
    vor = ref.voronoi_splat(np.full(len(pos), ref.ALL_ONES), pos, samples, 0, 1, np.float32(np.inf))
    assert np.array_equal(s.vor.get(), vor)
    for rnd in range(8):
        mx, uncovered = s.farthest()
        cand, unc_ref = ref.farthest(vor, pos, s.n)
        assert uncovered == unc_ref == 0
        assert np.array_equal(s.cand[:s.n].get(), cand), f"farthest, round {rnd}"
        assert mx == cand.max()
        r2max = ref.key_r2(mx)
        thr2 = threshold_r2(r2max)
        conf = ref.conflict_splat(pos, cand, thr2)
        if not host:
            s.conflicts(thr2, r2max)
            assert np.array_equal(s.conf.get(), conf), f"conflict removal, round {rnd}"
        keys, m = s.survivors(thr2, r2max)
        srt = ref.compact_sort(ref.survive(cand, thr2, conf))
        assert m == len(srt) > 0
        assert np.array_equal(keys.get()[:m], srt), f"compact and sort, round {rnd}"
        # survivors keep their distance: no survivor lies inside another survivor's disc
        p = pos[ref.key_pixel(srt), :3]
        d2 = ref.dist2(p[:, None, :], p[None, :, :])
        r2 = ref.key_r2(srt)
        np.fill_diagonal(d2, np.inf)
        assert np.all(d2 >= np.maximum(r2[:, None], r2[None, :]))
        first = s.append(keys, m)
        samples[first:first + m] = srt
        s.splat_voronoi(first, m, splat_r2(r2max))
        vor = ref.voronoi_splat(vor, pos, samples, first, m, splat_r2(r2max))
        assert np.array_equal(s.vor.get(), vor), f"Voronoi, round {rnd}"


@pytest.mark.parametrize("seed", range(4))
def test_pair_survivors_are_the_splats_survivors(seed):
    """Conflicts from the candidates' pairs (the CPU path) keep exactly the candidates that own
    their pixel after the twin's disc splats, also with equal radii and candidates at the edge of
    a disc."""
    rng = np.random.default_rng(seed)
    pos = np.zeros((3000, 4), np.float32)
    pos[:, :3] = rng.random((3000, 3)) * np.float32(4.0)
    pos[::3, 3] = 1.0
    covered = np.flatnonzero(pos[:, 3] > 0)
    pix = rng.choice(covered, 400, replace=False)
    r2 = rng.choice(np.float32([0.0, 0.1, 0.2, 0.2, 0.3]), 400).astype(np.float32)
    # candidates 20-39 lie exactly on the edge of the discs of 0-19, whose keys are larger: they
    # are outside (strictly inside drops)
    for a in range(20):
        d2 = ref.dist2(pos[covered], pos[pix[a]])
        d2[np.isin(covered, pix) | (d2 < 0.12)] = np.inf
        pix[20 + a] = covered[np.argmin(d2)]
        r2[a], r2[20 + a] = d2.min(), 0.1
    cand = (ref.f32_bits(r2) << np.uint64(32)) | pix.astype(np.uint64)
    thr2 = np.float32(0.1)
    expect = ref.survive(cand, thr2, ref.conflict_splat(pos, cand, thr2))
    out, eligible = pair_survivors(cand, pos, thr2)
    assert np.array_equal(out, expect)
    assert eligible == int(np.sum(r2 >= thr2)) and 0 < np.count_nonzero(out) < eligible


def test_whole_run_matches_numpy(small_gbuf):
    s = Sampler(small_gbuf, 600, seed=1)
    keys = s.run()
    expect = ref.sample(s.pos_host, 600, s.seed_pixel())
    assert np.array_equal(keys, expect)
    # each round appends its survivors by decreasing radius
    r = ref.key_r2(keys)
    start = 1
    for rs in s.rounds:
        seg = r[start:start + rs.inserted]
        assert np.all(np.diff(seg) <= 0)
        start += rs.inserted
    assert start == len(keys)


def test_coarse_to_fine_levels_match_numpy():
    g = mesh_gbuffer(two_parts(), views=4, resolution=64)
    keys, rounds, strides = run_levels(g, 700, seed=2)
    assert strides == [2, 1] and {r.stride for r in rounds} == {1, 2}
    assert np.array_equal(keys, ref.run_levels(g, 700, seed=2))
    s = sample_gbuffer(g, 700, seed=2, relax_iterations=0)
    assert s.meta["levels"] == [2, 1] and s.meta["relax_iterations"] == 0
    assert np.array_equal(s.positions, g.position.reshape(-1, 4)[ref.key_pixel(keys), :3])


def test_level_schedule():
    assert level_strides(512) == [8, 4, 2, 1]
    assert level_strides(128) == [4, 2, 1]
    assert level_strides(100) == [2, 1]
    assert level_strides(24) == [1]
    keys = np.array([(np.uint64(7) << np.uint64(32)) | np.uint64((1 * 4 + 2) * 4 + 3)], np.uint64)
    out = remap_keys(keys, (2, 16, 16), 4, 1)      # layer 1, row 2, column 3 of a 4x4 level
    assert out[0] >> np.uint64(32) == 7 and ref.key_pixel(out)[0] == (1 * 16 + 8) * 16 + 12


def test_runs_out_of_pixels_gracefully():
    g = mesh_gbuffer(two_parts(), views=2, resolution=8)
    with pytest.warns(UserWarning, match="every covered G-buffer pixel is taken"):
        s = sample_gbuffer(g, 100_000)
    distinct = len(np.unique(g.position[g.valid][:, :3], axis=0))
    assert 0 < len(s) <= distinct
    assert s.meta["requested"] == 100_000


def test_two_runs_write_identical_files(tmp_path):
    soup = two_parts()
    paths = []
    for i in range(2):
        s = sample_mesh(soup, 1500, views=6, resolution=48, seed=5)
        paths.append(s.save(tmp_path / f"run{i}.surfels"))
    assert paths[0].read_bytes() == paths[1].read_bytes()
    other = sample_mesh(soup, 1500, views=6, resolution=48, seed=6)
    assert not np.array_equal(other.positions, SurfelSet.load(paths[0]).positions)


def test_interior_cavity_gets_no_samples():
    outer = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    inner = trimesh.creation.icosphere(subdivisions=2, radius=0.5)
    inner.invert()  # a closed ball with a closed cavity inside
    s = sample_mesh(trimesh.util.concatenate([outer, inner]), 2000, views=8, resolution=64)
    assert len(s) == 2000
    r = np.linalg.norm(s.positions, axis=1)
    assert r.min() > 0.95


def test_parametric_scene_source():
    scene = pl.Scene()
    scene.add("sphere", material=pl.Material(color=(0.9, 0.2, 0.1)))
    s = sample_scene(scene, 400, views=6, resolution=96)
    assert len(s) == 400
    diag = 2 * np.sqrt(3)
    assert np.abs(np.linalg.norm(s.positions, axis=1) - 1).max() < 0.01 * diag
    # normals point outwards (the visible side), colours are the material's, in sRGB
    outward = np.sum(s.normals * s.positions, axis=1) / np.linalg.norm(s.positions, axis=1)
    assert np.mean(outward > 0.9) > 0.97
    assert np.all(s.colors == [243, 124, 89, 255])


def test_mesh_colours_reach_the_surfels(tmp_path):
    from trimesh.visual.material import PBRMaterial

    box = trimesh.creation.box()
    box.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(baseColorFactor=[200, 50, 50, 255]))
    box.export(tmp_path / "material.glb")
    ball = trimesh.creation.icosphere(subdivisions=2)
    ball.visual.vertex_colors = np.tile([10, 200, 30, 255], (len(ball.vertices), 1)).astype(np.uint8)
    ball.export(tmp_path / "vertex.ply")
    cube = trimesh.creation.box()
    cube.visual.face_colors = np.tile([0, 0, 255, 255], (12, 1)).astype(np.uint8)
    cube.export(tmp_path / "faces.obj")
    for name, rgb in [("material.glb", (200, 50, 50)), ("vertex.ply", (10, 200, 30)), ("faces.obj", (0, 0, 255))]:
        s = sample_mesh(tmp_path / name, 200, views=4, resolution=32)
        assert np.abs(s.colors[:, :3].astype(int) - rgb).max() <= 1, name
        assert np.all(s.colors[:, 3] == 255)
