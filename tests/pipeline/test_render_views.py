"""Multi-view frames (paramlod.render_views): one LOD pass for N views, each view against a
single-view render of its camera, per-view stats, the refusals, and the CLI's --stereo, --cubemap
and --quilt."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import paramlod as pl
from paramlod import views
from paramlod.app import cli

SIZE = (96, 72)


def two_sides_scene():
    """A sphere on +x and a torus on -x: a camera at the origin looking +x sees only the sphere,
    one looking -x only the torus (the other object is behind it)."""
    s = pl.Scene()
    s.add("sphere", transform=pl.translate((4, 0, 0)), material=pl.Material((0.8, 0.3, 0.2)))
    s.add("torus", transform=pl.translate((-4, 0, 0)) @ pl.rotate(60, (1, 0, 0)), material=pl.Material((0.2, 0.5, 0.9)))
    return s


def facing(direction, size=SIZE):
    return pl.Camera.look_at((0, 0, 0), direction, size=size, near=0.05, far=50)


def demo_scene():
    s = pl.Scene()
    s.add("sphere", transform=pl.translate((-1.3, 0, 0)))
    s.add("torus", transform=pl.translate((1.2, 0, 0)) @ pl.rotate(65, (1, 0, 0)))
    return s


def neighbour_range(depth):
    """Per pixel: the spread of the finite depths over its 3x3 neighbourhood."""
    d = np.pad(depth, 1, constant_values=np.inf)
    stack = np.stack([d[1 + dy:d.shape[0] - 1 + dy, 1 + dx:d.shape[1] - 1 + dx]
                      for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    lo = np.where(np.isfinite(stack), stack, np.inf).min(axis=0)
    hi = np.where(np.isfinite(stack), stack, -np.inf).max(axis=0)
    return np.where(np.isfinite(depth), hi - lo, 0)


def same_frame(a, b):
    np.testing.assert_array_equal(a.rgb8(), b.rgb8())
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.object_id, b.object_id)


@pytest.mark.parametrize("aa", [None, "4xSS"])
def test_views_that_see_different_objects_equal_their_single_view_renders(aa):
    """Where no other view asks for more detail, a view of a multi-view frame is the single-view
    frame of its camera, bit for bit (keys, depth, ids)."""
    scene = two_sides_scene()
    settings = pl.RenderSettings()
    if aa:
        settings.apply_aa(aa, variant="points")
    cams = [facing((1, 0, 0)), facing((-1, 0, 0)), facing((0, 0, 1))]   # the last sees nothing
    frames = pl.render_views(scene, cams, variant="points", settings=settings)
    assert len(frames) == 3
    for cam, frame in zip(cams[:2], frames):
        same_frame(frame, pl.render(scene, cam, variant="points", settings=settings))
    assert frames[2].stats["pixels_written"] == 0
    assert frames[2].stats["nothing_drawn"]
    assert frames[0].stats["pixels_written"] == int(frames[0].coverage.sum()) > 100
    assert [f.stats["view"] for f in frames] == [0, 1, 2]
    assert all(f.stats["views"] == 3 for f in frames)
    single = [pl.render(scene, c, variant="points", settings=settings).stats["render_patches"] for c in cams[:2]]
    assert frames[0].stats["render_patches"] == sum(single)    # one shared list, no patch twice


def test_mixed_scenes_composite_each_view_like_a_single_view_frame():
    """Objects of two variants (points and tess passes) composited by depth in every view."""
    scene = pl.Scene()
    scene.add("sphere", transform=pl.translate((4, 0, 0)), variant="points")
    scene.add("torus", transform=pl.translate((4, 0, 1.2)), variant="tess")
    scene.add("torus", transform=pl.translate((-4, 0, 0)) @ pl.rotate(60, (1, 0, 0)), variant="tess")
    cams = [facing((1, 0, 0)), facing((-1, 0, 0))]
    frames = pl.render_views(scene, cams)
    for cam, frame in zip(cams, frames):
        single = pl.render(scene, cam)
        same_frame(frame, single)
        assert frame.stats["variant"] == single.stats["variant"]
    assert set(np.unique(frames[0].object_id)) == {0, 1, 2}      # both variants in the first view
    assert set(np.unique(frames[1].object_id)) == {0, 3}


def test_a_view_is_never_coarser_than_its_single_view_render():
    """Overlapping views (a stereo pair, a quilt): each view agrees with its own single-view frame
    in coverage and depth, and its LOD is at least as fine."""
    scene = demo_scene()
    base = pl.Camera.look_at((2.6, 2.2, 5.2), (0, -0.1, 0), size=SIZE)
    for cams in (views.stereo(base, 0.4, focus=6.0), views.quilt(base, 3, 1, view_cone=30)):
        frames = pl.render_views(scene, cams, variant="points")
        for cam, frame in zip(cams, frames):
            single = pl.render(scene, cam, variant="points")
            a, b = frame.coverage, single.coverage
            assert (a & b).sum() / (a | b).sum() > 0.98
            # the views sample the surface at other points (a finer grid), so a pixel's nearest
            # sample moves within the pixel: its depth stays within the single frame's depth range
            # over the pixel and its neighbours
            both = a & b
            with np.errstate(invalid="ignore"):   # inf - inf off the objects
                within = np.abs(frame.depth - single.depth) <= neighbour_range(single.depth) + 1e-5 * single.depth
            assert within[both].mean() > 0.99
            # each patch of the single view is in the shared list or split further in it
            assert frame.stats["render_patches"] >= single.stats["render_patches"]


def test_one_lod_pass_serves_every_view():
    scene = demo_scene()
    faces = views.cube_faces((0, 0.2, 4.0), size=48)
    frames = pl.render_views(scene, faces, variant="points")
    stats = frames[0].stats
    assert all(f.stats["render_patches"] == stats["render_patches"] for f in frames)
    assert all(f.stats["lod_steps"] == stats["lod_steps"] for f in frames)
    written = [f.stats["pixels_written"] for f in frames]
    assert written[5] > 0 and sum(1 for w in written if w) == 1   # only -z looks at the objects
    pano = views.equirect(frames, faces, height=32)
    assert pano.shape == (32, 64, 3)


def test_single_view_variants_are_refused_by_name():
    scene = demo_scene()
    cams = views.stereo(pl.Camera.look_at((0, 0, 5), (0, 0, 0), size=SIZE), 0.2)
    with pytest.raises(pl.SceneError, match="points-ssaa draws one view"):
        pl.render_views(scene, cams, variant="points-ssaa")
    with pytest.raises(pl.SceneError, match="same size"):
        pl.render_views(scene, [cams[0], cams[1].with_size((48, 36))])


SCENE = """
[camera]
eye = [2.6, 2.2, 5.2]
target = [0.0, -0.1, 0.0]
size = [64, 48]

[[objects]]
function = "sphere"
translate = [-1.3, 0.0, 0.0]

[[objects]]
function = "torus"
translate = [1.2, 0.0, 0.0]
"""


def run(argv, capsys):
    try:
        rc = cli.main(argv)
    except SystemExit as exc:
        rc = exc.code
    out, err = capsys.readouterr()
    return rc, out, err


def test_cli_writes_assembled_images_and_one_file_per_view(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    rc, out, err = run(["render", str(scene), "--stereo", "0.3", "-o", str(tmp_path / "pair.png")], capsys)
    assert rc == 0, err
    assert Image.open(tmp_path / "pair.png").size == (128, 48)
    assert "2 views of 64x48" in out
    rc, out, err = run(["render", str(scene), "--quilt", "3x2", "-o", str(tmp_path / "quilt.png"),
                        "--stats", str(tmp_path / "q.json")], capsys)
    assert rc == 0, err
    assert Image.open(tmp_path / "quilt.png").size == (192, 96)
    rc, out, err = run(["render", str(scene), "--cubemap", "-o", str(tmp_path / "face_{view}.exr"),
                        "-o", str(tmp_path / "pano.png")], capsys)
    assert rc == 0, err
    assert sorted(p.name for p in tmp_path.glob("face_*.exr")) == [f"face_{i}.exr" for i in range(6)]
    assert Image.open(tmp_path / "pano.png").size == (192, 96)   # 2 x 48 high, twice as wide


def test_cli_checks_multi_view_outputs_before_any_work(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    rc, _, err = run(["render", str(scene), "--stereo", "0.3", "-o", str(tmp_path / "pair.exr")], capsys)
    assert rc != 0 and "{view}" in err
    rc, _, err = run(["render", str(scene), "--quilt", "9by9"], capsys)
    assert rc != 0 and "COLSxROWS" in err
    rc, _, err = run(["render", str(scene), "--stereo", "0.3", "--cubemap"], capsys)
    assert rc != 0 and "not allowed with" in err
    rc, _, err = run(["render", str(scene), "--stereo", "0.3", "--turntable", "4"], capsys)
    assert rc != 0 and "one multi-view frame" in err
    assert not list(tmp_path.glob("*.png")) and not list(tmp_path.glob("*.exr"))
