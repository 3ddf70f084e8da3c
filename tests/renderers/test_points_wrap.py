"""Periodic axes (``@parametric(periodic=...)``): a point grid that spans the domain along an axis
over which the function repeats does not draw its last line, a copy of its first
(kernels/points/points.cl grid_axis, patch_wraps; twin paramlod.renderers.sampling)."""
import numpy as np
import pytest
from sympy import cos, pi, sin

import paramlod as pl
from paramlod.lod.uploads import WRAP_U, WRAP_V, wrap_flags
from paramlod.renderers.points import grid_counts, patch_wraps

from helpers.stages import ParametricStage


@pl.parametric(u=(0, 2 * pi), v=(0, 2 * pi), params={"major": 1.0, "minor": 0.35})
def torus_open(u, v, major, minor):
    """The built-in torus without its periodic axes."""
    ring = major + minor * cos(v)
    return ring * cos(u), ring * sin(u), minor * sin(v)


def _scene(fn):
    scene = pl.Scene()
    for k, z in enumerate((0.0, -2.5, -9.0, -30.0)):   # near to far: split patches, and whole ones
        scene.add(fn, transform=pl.translate(1.6 * k - 2.4, 0.0, z) @ pl.rotate(35 * k + 20, (1, 0.3, 0)),
                  material=pl.Material(color=(0.9, 0.5, 0.2)))
    return scene


CAM = pl.Camera.look_at((0.0, 1.2, 3.2), (0.0, 0.0, -2.0), size=(200, 140))


@pytest.mark.parametrize("coverage", ["pixel", "centre"])
def test_wrapped_grids_draw_the_same_frame_with_fewer_samples(coverage):
    rs = pl.RenderSettings()
    rs.points.coverage = coverage
    wrapped, plain = (pl.render(_scene(fn), CAM, "points", rs) for fn in ("torus", torus_open))
    # the samples left out are exactly the repeated lines the twin predicts
    scene = _scene("torus")
    stage = ParametricStage(scene)
    dev = stage.upload(scene, CAM)
    _, n, _, _ = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], rs.lod)
    rl = stage.lod.read_render_list(n)
    wraps = patch_wraps(rl, dev["flags"], dev["domains"])
    assert wraps[:, 0].any() and wraps[:, 1].any() and not wraps.all(), "the scene must mix whole and split patches"
    nu, nv = grid_counts(rl, rs.points, wraps=wraps)
    nu0, nv0 = grid_counts(rl, rs.points)
    assert wrapped.stats["samples"] == int((nu * nv).sum())
    assert plain.stats["samples"] == int((nu0 * nv0).sum()) > wrapped.stats["samples"]
    # the dropped sample lay on the first one (to float rounding of f at 2 pi): same coverage,
    # and an image that differs at most by a level where the two samples' keys tied differently
    _assert_same_frame(wrapped, plain)


def test_the_local_framebuffer_variant_wraps_too():
    wrapped, plain = (pl.render(_scene(fn), CAM, "points-ssaa") for fn in ("torus", torus_open))
    assert wrapped.stats["samples_unique"] < plain.stats["samples_unique"]
    _assert_same_frame(wrapped, plain)


def _assert_same_frame(wrapped, plain):
    assert np.array_equal(np.isfinite(wrapped.depth), np.isfinite(plain.depth))
    a, b = wrapped.rgb8().astype(int), plain.rgb8().astype(int)
    assert np.abs(a - b).max() <= 1 and (a != b).any(-1).mean() < 1e-3


def test_wrap_flags_mark_the_periodic_axes():
    scene = pl.Scene()
    for fn in ("torus", "sphere", "plane", torus_open):
        scene.add(fn)
    _, inst_u, params = scene.instance_buffers()
    assert wrap_flags(scene, inst_u, params).tolist() == [WRAP_U | WRAP_V, WRAP_V, 0, 0]


def test_parameters_that_open_a_periodic_surface_keep_its_seam():
    scene = pl.Scene()
    scene.add("spiky_heart", params={"spikes_v": 21.0})
    scene.add("spiky_heart", params={"spikes_v": 20.5})   # the spikes no longer meet at v = 0 and 2 pi
    _, inst_u, params = scene.instance_buffers()
    with pytest.warns(UserWarning, match=r"'spiky_heart' is declared periodic in v.*spikes_v.*20\.5"):
        flags = wrap_flags(scene, inst_u, params)
    assert not (flags & WRAP_V).any()
    scene = pl.Scene()
    scene.add("spiky_heart", params={"spikes_v": 21.0})
    _, inst_u, params = scene.instance_buffers()
    assert (wrap_flags(scene, inst_u, params) & WRAP_V).all()


def test_a_wrong_periodic_claim_names_the_axis_and_the_gap():
    with pytest.raises(pl.FunctionError, match=r"declared periodic in u.*u = 0 and u = 1 differ by 1 at v"):
        @pl.parametric(periodic="u")
        def ramp(u, v):
            return u, v, 0 * u
    with pytest.raises(pl.FunctionError, match="periodic must name the axes"):
        @pl.parametric(periodic="w")
        def other(u, v):
            return u, v, 0 * u
