"""The direct points' debug colouring (PointSettings.color_by "patch" / "level",
kernels/points/points.cl debug_material) against its numpy twin
(paramlod.renderers.sampling.patch_debug_materials): drawn with the twin's colours as materials,
the kernel's recorded colour keys are the same, bit for bit."""
import numpy as np
import pyopencl.array as cla
import pytest

import paramlod as pl
from helpers.stages import ParametricStage
from paramlod.device.context import cl_device
from paramlod.renderers.points import DirectPointRenderer, grid_counts, patch_wraps
from paramlod.renderers.sampling import patch_debug_materials
from paramlod.renderers.targets import KeyBuffer


def _glyph_row():
    """Small spheres far apart: the LOD stage gives each its own render patches."""
    scene = pl.Scene()
    t = np.stack([pl.translate(2.5 * (i - 3.5), 0.3 * (i % 3), 0) @ pl.scale(0.6 + 0.05 * i) for i in range(8)])
    scene.add_instances("sphere", 8, transforms=t)
    cam = pl.Camera.look_at((0, 3, 22), (0, 0, 0), size=(160, 48))
    return scene, cam


def _record(stage, dev, rbuf, n, materials_buf, settings, total, counts):
    q = cl_device().queue
    rec = DirectPointRenderer(stage.scene.functions(), record=True)
    off = cla.to_device(q, np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.uint32))
    pix = cla.empty(q, total, np.uint32)
    key = cla.empty(q, total, np.uint64)
    keys = KeyBuffer(*stage.camera.size)
    keys.clear()
    rec.draw(rbuf, n, dev["inst"], materials_buf, dev["cam"], dev["light"], keys, settings,
             record_args=(off.data, pix.data, key.data))
    return pix.get(), key.get()


@pytest.mark.parametrize("color_by", ["patch", "level"])
def test_debug_colours_equal_the_twin(color_by):
    scene, cam = _glyph_row()
    stage = ParametricStage(scene)
    stage.scene, stage.camera = scene, cam
    dev = stage.upload(scene, cam)
    rbuf, n, _, _ = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], pl.LodSettings(), one_sided=dev["one_sided"])
    rl = stage.lod.read_render_list(n)
    # one render patch per instance, so that per-instance materials can carry per-patch colours
    assert len(rl) == 8 and len(set(rl["inst"].tolist())) == 8, "the LOD split a far sphere"
    nu, nv = grid_counts(rl, pl.PointSettings(), wraps=patch_wraps(rl, dev["flags"], dev["domains"]))
    counts = nu * nv
    total = int(counts.sum())
    debug = pl.PointSettings(color_by=color_by)
    pix_d, key_d = _record(stage, dev, rbuf, n, dev["materials"], debug, total, counts)
    twin = np.zeros((8, 4), np.float32)
    twin[rl["inst"]] = patch_debug_materials(rl, scene.materials(), color_by)
    q = cl_device().queue
    pix_m, key_m = _record(stage, dev, rbuf, n, cla.to_device(q, twin).data, pl.PointSettings(), total, counts)
    drawn = pix_m != 0xFFFFFFFF
    assert drawn.sum() > 100
    assert np.array_equal(pix_d, pix_m)
    assert np.array_equal(key_d[drawn], key_m[drawn])
    # the colours differ between patches (patch) or name the LOD step (level)
    assert len({tuple(c) for c in twin[:, :3]}) == (8 if color_by == "patch" else len(set((rl["flags"] & 15).tolist())))


def test_a_frame_coloured_by_patch_differs_and_points_ssaa_refuses_it():
    scene, cam = _glyph_row()
    s = pl.RenderSettings()
    plain = pl.render(scene, cam, "points", s).rgb8()
    s.points.color_by = "patch"
    coloured = pl.render(scene, cam, "points", s).rgb8()
    assert (np.abs(plain.astype(int) - coloured.astype(int)).sum(axis=-1) > 30).mean() > 0.02
    with pytest.raises(pl.SceneError, match="color_by 'patch' is drawn by the direct variant"):
        pl.render(scene, cam, "points-ssaa", s)
    s.points.color_by = "rainbow"
    with pytest.raises(pl.SceneError, match="color_by must be one of material, patch, level"):
        pl.render(scene, cam, "points", s)
