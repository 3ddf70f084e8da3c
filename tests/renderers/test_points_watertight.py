"""The direct point renderer is watertight on LOD patch boundaries: each render patch's grid is
sized for what its four boundary lines need (w_u, w_v, kernels/lod/lod.cl), so two patches sharing
an edge both cover it. Hypothesis-generated steep smooth surfaces, the measure's twin, and the
boundary holes the interior measure alone leaves."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st
from sympy import cos, pi, sin

import paramlod as pl
from helpers.holes import count_holes, dense_silhouette
from helpers.stages import ParametricStage
from paramlod.core.layouts import camera_record
from paramlod.lod.patches import sort_key
from paramlod.lod.reference import BOUNDARY_CAP, run_lod
from paramlod.pipeline.driver import RenderSettings
from paramlod.renderers.sampling import MEASURE_SEGMENT, PointSettings, grid_counts, patch_measures, side_counts


@pl.parametric(u=(0, 1), v=(0, 2 * pi), params={"a": 0.3, "k": 6.0})
def steep_ripple_disc(u, v, a, k):
    """Disc of radius 1 (u from the centre to the rim) with radial ripples a sin(k pi u)."""
    return u * cos(v), u * sin(v), a * sin(k * pi * u)


@pl.parametric(u=(0, 1), v=(0, 1), params={"a": 0.3, "k": 3.0, "m": 2.0})
def steep_egg_crate(u, v, a, k, m):
    """Unit sheet with an egg-crate relief a sin(k pi u) cos(m pi v)."""
    return u - 0.5, v - 0.5, a * sin(k * pi * u) * cos(m * pi * v)


@pl.parametric(u=(0, 1), v=(0, 2 * pi), params={"amp": 0.3})
def wavy_rim_disc(u, v, amp):
    """Disc with three ripples (as the wavy_disc plugin), steep up to the rim."""
    z = sum(amp / (k + 1) * sin(2 * pi * (k + 2) * u) for k in range(3))
    return u * cos(v), u * sin(v), z


@pl.parametric(u=(0, 1), v=(0, 1))
def pole_sheet(u, v):
    """z = 0.05 / u: smooth on (0, 1], a pole at u = 0 (the sample there is infinite)."""
    return u - 0.5, v - 0.5, 0.05 / u


class Unraised(PointSettings):
    """The direct variant sized by the interior lines only (s_u, s_v), as before the boundary
    measure: what the boundary lines add is seen against it."""

    def measure(self, boundary):
        return np.uint32(MEASURE_SEGMENT) if not self.use_extent else super().measure(boundary)


def _scene(fn, params):
    s = pl.Scene()
    s.add(fn, params=params)
    return s


def _holes(frame, fn, cam, params, dist):
    mask, dmax, fu, fv = dense_silhouette(fn, cam, params)
    n = count_holes(frame, mask, dmax, tol=0.02 * dist)
    return n, mask, dmax, fu, fv


# the LOD stage resolves a surface whose screen speed changes little over one of its 8-sample
# lines' segments (1/7 of a patch side, patches up to the 84-pixel threshold): ripples down to a
# period of about 2 segments. Finer ones alias in the LOD stage itself (its lines step over them),
# which no sampling of the render patches can repair; they are outside this property.
# A random example (egg crate a 0.4375, k 5.75, m 1, elevation 1.25, azimuth 4, distance 2.5)
# leaves 6 holes where the relief folds: an open bug (docs/points.md); the examples are drawn
# derandomized (tests/conftest.py), so CI checks the same ones every run.
@settings(max_examples=14, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(disc=st.booleans(), a=st.floats(0.1, 0.5), k=st.floats(1.0, 6.0), m=st.floats(0.5, 3.0),
       elevation=st.floats(0.15, 1.45), azimuth=st.floats(0, 2 * np.pi), dist=st.floats(1.8, 3.2))
def test_steep_smooth_surfaces_have_no_holes_inside_their_silhouettes(disc, a, k, m, elevation, azimuth, dist):
    fn, params = (steep_ripple_disc, {"a": a, "k": k}) if disc else (steep_egg_crate, {"a": a, "k": k, "m": m})
    eye = (dist * np.cos(elevation) * np.cos(azimuth), dist * np.cos(elevation) * np.sin(azimuth),
           dist * np.sin(elevation))
    cam = pl.Camera.look_at(eye, (0, 0, 0), size=(144, 144))
    frame = pl.render(_scene(fn, params), cam)
    holes, mask, *_ = _holes(frame, fn, cam, params, dist)
    assert mask.sum() > 300
    assert holes == 0, f"{holes} holes in {fn.name} {params} from {np.round(eye, 3)}"


def _patch_edge_distance(render_list, fu, fv):
    """Per (u, v): distance to the nearest edge of the render patch holding it, as a fraction of
    that patch's side (0 on an edge, 0.5 in the middle)."""
    r = render_list["range"].astype(np.float64)
    out = np.full(len(fu), np.inf)
    for i, (u, v) in enumerate(zip(fu, fv)):
        inside = (r[:, 0] <= u) & (u <= r[:, 1]) & (r[:, 2] <= v) & (v <= r[:, 3])
        for u0, u1, v0, v1 in r[inside]:
            out[i] = min(out[i], min(u - u0, u1 - u) / (u1 - u0), min(v - v0, v1 - v) / (v1 - v0))
    return out


def test_interior_measure_leaves_holes_on_patch_edges_the_boundary_measure_closes():
    """The defect this fixes, kept as a check that the property test can fail: a disc steep up to
    its rim, seen from above, sampled by the interior lines only, shows holes, all beside patch
    edges; sized for the boundary lines, none."""
    fn, params, dist = wavy_rim_disc, {"amp": 0.2}, 2.4
    cam = pl.Camera.look_at((0.3, 0.2, dist), (0, 0, 0), size=(320, 240))
    scene = _scene(fn, params)
    # without the detail split too, which also closes these holes by splitting the steep rim
    unsplit = pl.LodSettings(detail_angle=180)
    old = pl.render(scene, cam, settings=RenderSettings(points=Unraised(), lod=unsplit))
    new = pl.render(scene, cam)
    n_old, mask, dmax, fu, fv = _holes(old, fn, cam, params, dist)
    n_new = count_holes(new, mask, dmax, tol=0.02 * dist)
    assert n_old >= 5 and n_new == 0
    # where the old holes are: within a tenth of a patch side of a render patch's edge
    stage = ParametricStage(scene)
    dev = stage.upload(scene, cam)
    _, n, _, _ = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], unsplit)
    rl = stage.lod.read_render_list(n)
    bad = (~np.isfinite(old.depth) | (old.depth > dmax + 0.02 * dist)) & mask
    ys, xs = np.nonzero(bad)
    known = np.isfinite(fu[ys, xs])
    d = _patch_edge_distance(rl, fu[ys, xs][known], fv[ys, xs][known])
    assert known.sum() >= 5 and np.all(d < 0.1), d
    # the cost: only the patches whose boundary needs it sample more
    nu0, nv0 = grid_counts(rl, PointSettings(), boundary=False)
    nu1, nv1 = grid_counts(rl, PointSettings())
    assert np.all(nu1 >= nu0) and np.all(nv1 >= nv0) and (nu1 * nv1).sum() > (nu0 * nv0).sum()


@pytest.mark.parametrize("fn, params, eye", [
    (steep_ripple_disc, {"a": 0.4, "k": 5.0}, (0.4, -2.0, 1.1)),
    (steep_egg_crate, {"a": 0.3, "k": 3.0, "m": 2.0}, (1.2, -1.0, 1.6)),
    ("sphere", None, (0.6, 0.4, 2.6)),
    (pole_sheet, None, (0.3, -2.0, 1.2)),   # lines with bad and good samples split (lod.cl)
])
def test_boundary_measure_matches_its_twin_and_its_bounds(fn, params, eye):
    scene = pl.Scene()
    scene.add(fn, **({"params": params} if params else {}))
    cam = pl.Camera.look_at(eye, (0, 0, 0), size=(200, 160))
    lod = pl.LodSettings()
    stage = ParametricStage(scene)
    dev = stage.upload(scene, cam)
    _, n, steps, _ = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], lod)
    got = stage.lod.read_render_list(n)
    ref, ref_steps = run_lod(scene, camera_record(cam), lod)
    assert steps == ref_steps
    got, ref = got[sort_key(got)], ref[sort_key(ref)]
    np.testing.assert_array_equal(got["range"], ref["range"])
    wg, wr = patch_measures(got, 2), patch_measures(ref, 2)
    # function values differ in the last bits between OpenCL and numpy (paramlod/lod/reference.py)
    np.testing.assert_allclose(wg, wr, rtol=1e-3, atol=1e-3)
    s = got["ext"][:, 2:4]
    assert np.all(wg >= s) and np.all(wg <= BOUNDARY_CAP * s * (1 + 1e-6))
    # the kernels' sample counts from these measures (integers; the recorded samples equal them,
    # tests/renderers/test_points.py): between the interior measure's and a uniform grid for w
    ps = PointSettings()
    nu, nv = grid_counts(got, ps)
    for n, col in ((nu, 0), (nv, 1)):
        assert np.all(n >= side_counts(got["ext"][:, 2 + col], ps))
        assert np.all(n <= side_counts(wg[:, col], ps))
    # the strips' arithmetic by hand for one raised patch (grid_axes mirrors grid_axis in points.cl)
    raised = np.flatnonzero(wg[:, 0] > s[:, 0])
    for i in raised[:3]:
        w_, s_ = np.float32(wg[i, 0]), np.float32(s[i, 0])
        na = max(np.ceil(np.float32(w_ * np.float32(1.5)) * np.float32(1 / 7)), 1)
        nm = max(np.ceil(np.float32(s_ * np.float32(1.5)) * np.float32(5 / 7)), 1)
        uniform = min(int(np.ceil(w_ * np.float32(1.5))) + 1, 1024)
        assert nu[i] == (2 * na + nm + 1 if 2 * na + nm + 1 < min(uniform, 1024) else uniform)
