"""points-ssaa honours the anti-aliasing mode: 4xSS and 9xSS draw 2x2 and 3x3 subsamples (the same
images as settings.ssaa.ss = 2 / 3), every other mode is an error naming the two it can do."""
import hashlib
import itertools

import pytest

import paramlod as pl
from paramlod.renderers.aa import parse_aa
from paramlod.renderers.points_lfb import SsaaSettings

SIZE = (48, 36)
SS = ["", "4xSS", "9xSS", "16xSS"]
MS = ["", "2xMS", "4xMS", "8xMS"]
# every mode the grammar accepts, in both spellings where there is an alias
MODES = ["noAA", "msaa2", "msaa4", "msaa8", "ssaa2x2", "ssaa3x3", "ssaa4x4"] + [
    "+".join(p for p in (s, m) if p) for s, m in itertools.product(SS, MS) if s or m]
CAN = {"4xSS": 2, "9xSS": 3}


def scene_and_camera():
    scene = pl.Scene()
    scene.add("torus")
    return scene, pl.Camera.look_at((0, 1.5, 2.5), (0, 0, 0), size=SIZE)


def digest(frame):
    return hashlib.sha256(frame.rgb8().tobytes()).hexdigest()


@pytest.fixture(scope="module")
def by_ss():
    """The images of settings.ssaa.ss = 2 and 3, set directly."""
    scene, cam = scene_and_camera()
    out = {}
    for ss in (2, 3):
        f = pl.render(scene, cam, variant="points-ssaa", settings=pl.RenderSettings(ssaa=SsaaSettings(ss=ss)))
        out[ss] = digest(f)
    assert out[2] != out[3]
    return out


@pytest.mark.parametrize("mode", MODES)
def test_every_mode_is_drawn_as_it_says_or_refused(mode, by_ss):
    scene, cam = scene_and_camera()
    aa = parse_aa(mode)
    rs = pl.RenderSettings()
    if aa.name in CAN:
        rs.apply_aa(mode, variant="points-ssaa")
        f = pl.render(scene, cam, variant="points-ssaa", settings=rs)
        assert f.stats["ss"] == CAN[aa.name] and rs.ssaa.ss == CAN[aa.name]
        assert digest(f) == by_ss[CAN[aa.name]]
    else:
        with pytest.raises(pl.SceneError, match="points-ssaa variant draws 4xSS or 9xSS only"):
            rs.apply_aa(mode, variant="points-ssaa")


@pytest.mark.parametrize("mode", [m for m in MODES if parse_aa(m).name not in CAN and parse_aa(m).name != "noAA"
                                  and not (parse_aa(m).ss in (2, 3) and parse_aa(m).msaa > 1)])
def test_a_mode_applied_without_the_variant_is_refused_when_points_ssaa_draws(mode):
    # the CLI's --aa reaches the settings before the frame's variant is known
    scene, cam = scene_and_camera()
    rs = pl.RenderSettings()
    rs.apply_aa(mode)
    with pytest.raises(pl.SceneError, match="points-ssaa variant draws 4xSS or 9xSS only"):
        pl.render(scene, cam, variant="points-ssaa", settings=rs)


@pytest.mark.parametrize("mode", ["4xSS", "9xSS", "ssaa3x3"])
def test_a_supersampling_mode_applied_without_the_variant_is_drawn(mode, by_ss):
    scene, cam = scene_and_camera()
    rs = pl.RenderSettings()
    rs.apply_aa(mode)
    assert digest(pl.render(scene, cam, variant="points-ssaa", settings=rs)) == by_ss[parse_aa(mode).ss]


def test_ss_changed_after_the_mode_is_a_contradiction():
    scene, cam = scene_and_camera()
    rs = pl.RenderSettings()
    rs.apply_aa("4xSS")
    rs.ssaa.ss = 3
    with pytest.raises(pl.SceneError, match="4xSS asks for 2x2 subsamples, but settings.ssaa.ss is 3"):
        pl.render(scene, cam, variant="points-ssaa", settings=rs)


def test_a_frame_mixed_with_tess_gives_tess_the_multisampling():
    scene = pl.Scene()
    scene.add("torus", variant="points-ssaa")
    scene.add("sphere", transform=pl.translate(0, 0, -2) @ pl.scale(0.5), variant="tess")
    cam = pl.Camera.look_at((0, 1.5, 2.5), (0, 0, 0), size=SIZE)
    rs = pl.RenderSettings()
    rs.apply_aa("9xSS+4xMS")
    f = pl.render(scene, cam, settings=rs)
    passes = {p["variant"]: p for p in f.stats["passes"]}
    assert passes["points-ssaa"]["ss"] == 3
    assert f.stats["pixels_written"] > 0
