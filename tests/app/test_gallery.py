"""Every gallery scene renders, small, and is framed; the gallery command writes its outputs."""
import json
from pathlib import Path

import numpy as np
import pytest

from paramlod.app.cli import main
from paramlod.app.gallery import render_scene_file
from paramlod.meshlod.build.worm_rig import write_worm

GALLERY = Path(__file__).resolve().parents[2] / "gallery"
SCENES = sorted(GALLERY.glob("*.toml"))


def test_the_gallery_has_the_scenes_the_issue_names():
    names = {p.stem for p in SCENES}
    assert {"sh_glyph_o12", "hardi_field", "csa_small64d", "yarn_curtain", "fiber_curtain", "seashells",
            "giant_worm", "hearts", "palm_trunk", "bunny_surfels"} <= names


def _prepared(path, tmp_path):
    """The scene file, or for the skinned worm (its data is generated, not committed) a copy beside
    a small worm made by the same generator."""
    if path.stem != "skinned_worm":
        return path
    (tmp_path / "data").mkdir()
    write_worm(tmp_path / "data" / "skinned_worm.glb", "small")
    copy = tmp_path / path.name
    copy.write_text(path.read_text())
    return copy


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_scene_renders_non_empty_and_framed(path, tmp_path):
    sf, frames, _ = render_scene_file(_prepared(path, tmp_path), size=(96, 96))
    for f in frames:
        cov = f.coverage
        share = cov.mean()
        assert 0.03 < share < 0.97, f"{path.stem}: the object covers {share:.1%} of the frame"
        ys, xs = np.nonzero(cov)
        # framed: the object is not cut off on more than one side
        touching = sum([ys.min() == 0, ys.max() == 95, xs.min() == 0, xs.max() == 95])
        assert touching <= 1, f"{path.stem}: the object touches {touching} image borders"
        assert np.isfinite(f.depth[cov]).all() and (f.object_id[cov] > 0).all()
    if sf.animation:
        assert len(frames) == sf.animation["frames"]
        assert not np.array_equal(frames[0].depth, frames[-1].depth), "the animation does not move"


def test_gallery_command_writes_images_captions_and_markdown(tmp_path):
    assert main(["gallery", "--scenes", str(GALLERY), "--out", str(tmp_path), "--size", "64x48",
                 "--only", "hearts"]) == 0
    for name in ("hearts.png", "hearts.exr", "captions.json", "README.md"):
        assert (tmp_path / name).stat().st_size > 0
    (cap,) = json.loads((tmp_path / "captions.json").read_text())
    assert cap["variant"].startswith("mixed") and cap["size"] == [64, 48] and cap["device"]
    assert "hearts.png" in (tmp_path / "README.md").read_text()
    assert main(["gallery", "--scenes", str(GALLERY), "--out", str(tmp_path), "--only", "nope"]) == 2


def test_gallery_outside_the_repository_says_where_the_scenes_are(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)   # an installed paramlod run elsewhere: no gallery/ folder here
    assert main(["gallery", "--out", "g"]) == 2
    err = capsys.readouterr().err
    assert "--scenes gallery: no such folder" in err and "repository" in err and not (tmp_path / "g").exists()


def test_a_scene_whose_data_is_not_prepared_names_the_command(tmp_path, capsys):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    (scenes / "skinned_worm.toml").write_text((GALLERY / "skinned_worm.toml").read_text())
    out = tmp_path / "out"
    assert main(["gallery", "--scenes", str(scenes), "--out", str(out), "--size", "64x48"]) == 2
    err = capsys.readouterr().err
    assert "data/skinned_worm.glb" in err and "python gallery/prepare_skinned_worm.py" in err
    assert not out.exists() or not any(out.iterdir())
