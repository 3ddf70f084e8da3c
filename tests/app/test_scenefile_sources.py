"""Scene-file fields that an object's source takes none of are refused by name: they used to be
ignored without a word (instances of a surfel set drew one copy; a .npz glyph field drew every
glyph whatever its stride)."""
from pathlib import Path

import pytest

import paramlod as pl
from paramlod.app.scenefile import load_scene

DATA = Path(__file__).resolve().parents[2] / "gallery" / "data"
HEAD = "[camera]\neye = [0, 0, 4]\nsize = [48, 36]\n\n[[objects]]\n"
SURFELS = f'surfels = {{ path = "{DATA / "bunny.surfels"}", px = 2 }}\n'
FIELD = f'sh_field = {{ path = "{DATA / "small64d_csa_o8.npz"}" }}\n'


@pytest.mark.parametrize("source,extra,field", [
    (SURFELS, "instances = { grid = [2, 1, 1], spacing = 3 }\n", "instances"),
    (SURFELS, "params = { radius = 2 }\n", "params"),
    (SURFELS, 'variant = "tess"\n', "variant"),
    (FIELD, "instances = { grid = [3, 1, 1], spacing = 10 }\n", "instances"),
    (FIELD, "params = { scale = 2 }\n", "params"),
])
def test_fields_a_source_takes_none_of_are_named(tmp_path, source, extra, field):
    p = tmp_path / "s.toml"
    p.write_text(HEAD + source + extra)
    kind = "surfels" if "surfels" in source else "sh_field"
    with pytest.raises(pl.SceneError, match=rf"s\.toml:\d+: objects\[0\]\.{field}: does not apply to a {kind} object"):
        load_scene(p)


def test_a_glyph_fields_own_fields_are_checked(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(HEAD + FIELD.replace(" }", ", strid = 2 }"))
    with pytest.raises(pl.SceneError, match=r"objects\[0\]\.sh_field\.strid: unknown field \(sh_field takes path, "
                                            r"color_by, normalize, scale, subtract_min"):
        load_scene(p)
    p.write_text(HEAD + FIELD.replace(" }", ", stride = 0 }"))
    with pytest.raises(pl.SceneError, match=r"objects\[0\]\.sh_field\.stride: is for NIfTI volumes"):
        load_scene(p)
    p.write_text(HEAD + FIELD.replace(" }", ", scale = 0.5 }"))
    assert load_scene(p).scene.objects[0].count == 1000
