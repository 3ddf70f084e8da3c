"""The built-in function library: OpenCL against numpy for every function, SH glyphs against dipy,
Crane's yarn and fibres against the closed form, curtains, seashell presets, the giant worm's
parts, and one render with every built-in."""
import ast
import math
from pathlib import Path

import numpy as np
import pytest

import paramlod as pl
from paramlod.function.plugins import evaluate_cl
from paramlod.function.registry import builtin_functions, describe_functions

FUNCTIONS_DIR = Path(__file__).resolve().parents[2] / "functions"
LIBRARY = ["plane", "sphere", "torus", "cone", "johis_heart", "spiky_heart", "palm_trunk", "sh_glyph",
           "sh_glyph_tournier", "yarn", "fiber", "seashell1", "seashell2", "seashell3", "giant_worm",
           "giant_worm_jaw_outer", "giant_worm_jaw_inner", "giant_worm_tongue"]


@pytest.fixture(scope="module")
def builtins():
    funcs = builtin_functions()
    return [funcs[n] for n in sorted(funcs)]


def grid(fn, nu=13, nv=11):
    """A parameter grid covering the whole domain, in float32 (what the kernels receive)."""
    u = np.linspace(*fn.u_range, nu).astype(np.float32)
    v = np.linspace(*fn.v_range, nv).astype(np.float32)
    return np.meshgrid(u, v, indexing="ij")


def test_the_library_is_complete_and_documented():
    rows = {r["name"]: r for r in describe_functions()}
    missing = [n for n in LIBRARY if n not in rows]
    assert not missing, f"missing built-ins: {missing}"
    for name in LIBRARY:
        r = rows[name]
        assert r["origin"] == "built-in" and r["summary"], name
        assert r["u"][0] < r["u"][1] and r["v"][0] < r["v"][1], name
    # every module says where it comes from, its domain and what each parameter does
    for path in sorted(FUNCTIONS_DIR.glob("*.py")):
        if path.name.startswith("_"):
            continue
        doc = ast.get_docstring(ast.parse(path.read_text())) or ""
        assert "Domain" in doc or "Domains" in doc, f"{path.name}: no domain in the docstring"
        for f in builtin_functions().values():
            if Path(f.source).resolve() == path.resolve():
                for p in f.params:
                    if p.name != "t":
                        assert f"``{p.name}``" in doc, f"{path.name}: parameter {p.name} undocumented"


def test_builtins_that_close_on_themselves_say_so(builtins):
    """A built-in whose edges meet along an axis declares it periodic (the point renderers then
    skip the repeated line, docs/points.md "Periodic axes"), and only those."""
    t = np.linspace(0, 1, 17)
    for fn in builtins:
        (u0, u1), (v0, v1) = fn.u_range, fn.v_range
        across_v, across_u = v0 + (v1 - v0) * t, u0 + (u1 - u0) * t
        closes = {"u": np.allclose(fn.evaluate(np.full_like(t, u0), across_v), fn.evaluate(np.full_like(t, u1), across_v),
                                   atol=1e-9),
                  "v": np.allclose(fn.evaluate(across_u, np.full_like(t, v0)), fn.evaluate(across_u, np.full_like(t, v1)),
                                   atol=1e-9)}
        assert fn.periodic == tuple(a for a in "uv" if closes[a]), fn.name


def test_every_builtin_matches_numpy_on_opencl(builtins):
    """pl_surface and pl_position of each built-in, compiled together once, against the numpy
    evaluation on a grid: positions within 1e-5 of the object's size, partials within 1e-3."""
    for fn in builtins:
        u, v = grid(fn)
        pos, du, dv, pos_only = evaluate_cl(fn, u, v, functions=builtins)
        ref, rdu, rdv = fn.surface(u.astype(np.float64), v.astype(np.float64))
        ok = np.all(np.isfinite(ref), axis=-1)
        assert ok.mean() > 0.9, f"{fn.name}: numpy gives NaN on most of the grid"
        size = np.ptp(ref[ok], axis=0).max()
        err = np.abs(pos - ref)[ok].max() / size
        assert err <= 1e-5, f"{fn.name}: OpenCL position differs by {err:.2e} of the object's size"
        assert np.array_equal(np.isfinite(pos), np.isfinite(ref)), f"{fn.name}: NaN pattern differs"
        np.testing.assert_allclose(pos_only[ok], pos[ok], rtol=0, atol=1e-6 * size, err_msg=fn.name)
        for name, a, b in (("df/du", du, rdu), ("df/dv", dv, rdv)):
            fin = np.all(np.isfinite(b) & np.isfinite(a), axis=-1)
            scale = np.abs(b[fin]).max() + 1e-12
            bad = np.abs(a - b)[fin].max(axis=-1) > 1e-3 * scale
            # kinks (where(), Abs) may sit exactly on a grid line: allow a few points there
            assert bad.mean() <= 0.02, f"{fn.name}: {name} differs at {bad.sum()} of {fin.sum()} points"


@pytest.mark.parametrize("basis", ["descoteaux07", "tournier07"])
def test_sh_glyph_radius_matches_dipy(basis):
    from dipy.reconst.shm import real_sh_descoteaux, real_sh_tournier
    from paramlod.functions.sh_glyph import coefficient_count, make_sh_glyph

    dipy_basis = real_sh_descoteaux if basis == "descoteaux07" else real_sh_tournier
    rng = np.random.default_rng(7)
    theta, phi = rng.uniform(0, np.pi, 64), rng.uniform(0, 2 * np.pi, 64)
    direction = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    for order in range(2, 13, 2):
        glyph = make_sh_glyph(order, basis)
        assert glyph.params[0].size == coefficient_count(order)
        coeffs = rng.normal(size=coefficient_count(order))
        block = glyph.param_block({"coeffs": coeffs})
        B, _, _ = dipy_basis(order, theta, phi, legacy=False)
        r = B @ block.astype(np.float64)            # the glyph's radius per dipy
        points = glyph.evaluate(theta, phi, block)
        np.testing.assert_allclose(points, r[:, None] * direction, atol=1e-9 * np.abs(r).max(),
                                   err_msg=f"{basis} order {order}")


def test_sh_glyph_order_12_on_opencl_matches_dipy():
    from dipy.reconst.shm import real_sh_descoteaux, real_sh_tournier
    from paramlod.functions.sh_glyph import sh_glyph, sh_glyph_tournier

    rng = np.random.default_rng(3)
    theta, phi = rng.uniform(0, np.pi, 200), rng.uniform(0, 2 * np.pi, 200)
    theta, phi = theta.astype(np.float32), phi.astype(np.float32)
    funcs = [sh_glyph, sh_glyph_tournier]
    for fn, basis in ((sh_glyph, real_sh_descoteaux), (sh_glyph_tournier, real_sh_tournier)):
        block = fn.param_block({"coeffs": rng.normal(size=91)})
        B, _, _ = basis(12, theta.astype(np.float64), phi.astype(np.float64), legacy=False)
        r = B @ block.astype(np.float64)
        pos = evaluate_cl(fn, theta, phi, block, functions=funcs)[0]
        r_cl = np.sum(pos * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                      np.cos(theta)], -1), axis=-1)
        assert np.abs(r_cl - r).max() <= 1e-5 * np.abs(r).max(), fn.name


def test_sh_coefficient_helpers():
    from paramlod.functions.sh_glyph import convert_basis, pad_coefficients, sh_glyph, sh_glyph_tournier

    rng = np.random.default_rng(5)
    c45 = rng.normal(size=45)                       # an lmax-8 set, as MRtrix files hold
    c91 = pad_coefficients(c45)
    assert c91.shape == (91,) and np.array_equal(c91[:45], c45) and not c91[45:].any()
    theta, phi = np.meshgrid(np.linspace(0.1, 3.0, 7), np.linspace(0, 6.2, 9))
    d = sh_glyph.evaluate(theta, phi, coeffs=c91)
    t = sh_glyph_tournier.evaluate(theta, phi, coeffs=convert_basis(c91, "descoteaux07", "tournier07"))
    np.testing.assert_allclose(d, t, atol=1e-5)     # same glyph after conversion
    back = convert_basis(convert_basis(c91, "descoteaux07", "tournier07"), "tournier07", "descoteaux07")
    np.testing.assert_allclose(back, c91)
    with pytest.raises(pl.FunctionError, match="not a full even-band"):
        pad_coefficients(np.ones(44))


def crane_gamma(s, a, h, d):
    return np.stack([s + a * np.sin(2 * s), h * np.cos(s), d * np.cos(2 * s)], -1)


def crane_frame(s, a, h, d):
    """Crane's closed-form Frenet frame (e1, e2, e3), written out independently of the library."""
    g1 = np.stack([1 + 2 * a * np.cos(2 * s), -h * np.sin(s), -2 * d * np.sin(2 * s)], -1)
    g2 = np.stack([-4 * a * np.sin(2 * s), -h * np.cos(s), -4 * d * np.cos(2 * s)], -1)
    e1 = g1 / np.linalg.norm(g1, axis=-1, keepdims=True)
    e2 = g2 - np.sum(g2 * e1, -1, keepdims=True) * e1
    e2 /= np.linalg.norm(e2, axis=-1, keepdims=True)
    return e1, e2, np.cross(e1, e2)


def test_yarn_surface_is_a_tube_around_cranes_centreline():
    from paramlod.functions.yarn import yarn

    params = {"a": 1.354, "h": 3.71, "d": 0.619, "radius": 0.7}
    s = np.linspace(0, 2 * np.pi, 41)
    v = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    p = yarn.evaluate(s[:, None], v[None, :], **params)
    gamma = crane_gamma(s, params["a"], params["h"], params["d"])[:, None, :]
    np.testing.assert_allclose(np.linalg.norm(p - gamma, axis=-1), params["radius"], rtol=1e-6)
    e1, e2, _ = crane_frame(s, params["a"], params["h"], params["d"])
    # each ring lies in the normal plane and starts at e2 (v = 0)
    assert np.abs(np.sum((p - gamma) * e1[:, None, :], -1)).max() < 1e-6
    np.testing.assert_allclose(p[:, 0], gamma[:, 0] + params["radius"] * e2, atol=1e-6)
    # one loop ends where the next starts (shifted by 2 pi along x)
    end = yarn.evaluate(2 * np.pi, v, **params)
    start = yarn.evaluate(0.0, v, **params) + [2 * np.pi, 0, 0]
    np.testing.assert_allclose(end, start, atol=1e-9)


def test_fiber_centreline_matches_the_closed_form():
    from paramlod.functions.fiber import fiber, fiber_centerline

    a, h, d, r, omega, phi = 1.5, 4.0, 1.0, 0.5, 5.0, 0.7
    s = np.linspace(0, 2 * np.pi, 37)
    e1, e2, e3 = crane_frame(s, a, h, d)
    theta = (omega * s - 2 * np.cos(s) + phi)[:, None]
    eta = crane_gamma(s, a, h, d) + r * (np.cos(theta) * e2 + np.sin(theta) * e3)
    np.testing.assert_allclose(fiber_centerline(s, a, h, d, r, omega, phi), eta, atol=1e-9)
    # the tube: ring centres on eta, constant radius, rings normal to eta'
    v = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    p = fiber.evaluate(s[:, None], v[None, :], a=a, h=h, d=d, r=r, omega=omega, phi=phi, radius=0.2)
    np.testing.assert_allclose(p.mean(axis=1), eta, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(p - eta[:, None], axis=-1), 0.2, rtol=1e-5)
    step = 1e-5
    deta = (fiber_centerline(s + step, a, h, d, r, omega, phi) - fiber_centerline(s - step, a, h, d, r, omega, phi))
    deta /= np.linalg.norm(deta, axis=-1, keepdims=True)
    assert np.abs(np.sum((p - eta[:, None]) * deta[:, None], -1)).max() < 1e-5


def test_curtains_are_built_as_arrays():
    from paramlod.functions.fiber import fiber, fiber_curtain
    from paramlod.functions.yarn import yarn_curtain

    y = yarn_curtain()
    assert y["count"] == 235 * 254 == 59_690 and y["transforms"].shape == (59_690, 4, 4)
    f = fiber_curtain()
    assert f["count"] == 59_690 * 6 == 358_140
    assert f["per_instance"]["phi"].shape == (358_140,) and f["transforms"].shape == (358_140, 4, 4)
    # loop 1 of row 2 (row-major): shifted by one loop along x and two rows along y
    m = y["transforms"][2 * 235 + 1]
    np.testing.assert_allclose(m[:3, 3], [2 * np.pi, 2 * (4.0 + 0.5), 0], rtol=1e-6)
    with pytest.raises(pl.FunctionError, match=r"unknown fibre parameter\(s\) \['omgea'\]"):
        fiber_curtain(loops=2, rows=2, omgea=3)
    with pytest.raises(pl.FunctionError, match="at least one loop and one row, got 0 x 5"):
        yarn_curtain(loops=0, rows=5)
    # a fibre runs on across loops, also for a twist that is not a whole number of turns
    small = fiber_curtain(loops=3, rows=1, fibers=4, omega=4.5)
    per = small["per_instance"]["phi"]
    for k in range(4):
        i0, i1 = k, 4 + k   # fibre k in loops 0 and 1
        params = dict(small["params"])
        end = fiber.evaluate(2 * np.pi, 0.3, **params, phi=per[i0]) @ small["transforms"][i0][:3, :3].T \
            + small["transforms"][i0][:3, 3]
        start = fiber.evaluate(0.0, 0.3, **params, phi=per[i1]) + small["transforms"][i1][:3, 3]
        np.testing.assert_allclose(end, start, atol=1e-4)


def test_seashell_presets_are_the_anchor_values():
    from paramlod.functions.seashell import PARAMS, seashell1, seashell2, seashell3

    want = {
        seashell1: (87, 29, 4.309, 4.7, -39.944, 58.839, 9, 20, 1, 1.5, 2),
        seashell2: (86.5, 10, 6.071, 5.153, -39.944, 1, 9, 11, 1, 1.5, 1.5),
    }
    for fn, values in want.items():
        got = fn.param_values(fn.param_block())
        assert [got[k] for k in PARAMS] == pytest.approx(values, rel=1e-6), fn.name
    assert fn.u_range == pytest.approx((0, 16 * math.pi))   # 8 coils
    # shell 3 has many tiny bumps: far more surface relief (second differences) than shells 1 and 2
    u, v = np.meshgrid(np.linspace(40, 40 + 2 * np.pi, 401), np.linspace(0, 2 * np.pi, 201), indexing="ij")
    relief = {}
    for fn in (seashell1, seashell2, seashell3):
        p = fn.evaluate(u, v)
        relief[fn] = np.abs(np.diff(p, 2, axis=0)).sum() + np.abs(np.diff(p, 2, axis=1)).sum()
    assert relief[seashell3] > 3 * max(relief[seashell1], relief[seashell2])


def test_giant_worm_parts_follow_the_animation():
    from paramlod.functions.giant_worm import giant_worm

    parts = giant_worm.expand_parts({"t": 0.0})
    names = [p.function.name for p in parts]
    assert names.count("cone") == 57
    assert names.count("giant_worm_jaw_outer") == 3 and names.count("giant_worm_jaw_inner") == 3
    assert names.count("giant_worm_tongue") == 1
    later = giant_worm.expand_parts({"t": 1.0})
    moved = [np.abs(a.transform[:3, 3] - b.transform[:3, 3]).max() for a, b in zip(parts, later)]
    assert min(moved) > 0.05   # every part moves with the swaying, opening mouth
    # each tooth stands on its inner jaw and points into the mouth (towards the body's axis)
    jaws = [p for p in parts if p.function.name == "giant_worm_jaw_inner"]
    axis = giant_worm.evaluate(0.0, np.linspace(0, 2 * np.pi, 64, endpoint=False), t=0.0).mean(axis=0)
    for p in parts:
        if p.function.name != "cone":
            continue
        jaw = next(j for j in jaws if p.path.startswith(j.path + "/"))
        values = jaw.function.param_values(jaw.function.param_block(jaw.params))
        on = [np.linalg.norm(jaw.transform[:3, :3] @ jaw.function.evaluate(uu, vv, **values)
                             + jaw.transform[:3, 3] - p.transform[:3, 3])
              for uu, vv in [part.at for part in jaw.function.parts]]
        assert min(on) < 1e-9
        assert np.dot(p.transform[:3, 2], axis - p.transform[:3, 3]) > 0


def test_hearts_are_symmetric_with_a_dip_on_top():
    from paramlod.functions.johis_heart import johis_heart

    u, v = np.meshgrid(np.linspace(0, np.pi, 31), np.linspace(0, 2 * np.pi, 41))
    p = johis_heart.evaluate(u, v)
    mirror = johis_heart.evaluate(u, 2 * np.pi - v) * [-1, 1, 1]   # x -> -x
    np.testing.assert_allclose(p, mirror, atol=1e-9)
    top_centre = johis_heart.evaluate(0.3, 0.0)[1]    # on the plane x = 0
    lobe = johis_heart.evaluate(0.3, np.pi / 2)[1]
    assert lobe > top_centre + 0.2                      # a dip between ...
    top = p.reshape(-1, 3)[np.argmax(p[..., 1])]
    assert abs(top[0]) > 0.2                            # ... two lobes, the highest points off-centre
    assert johis_heart.evaluate(np.pi, 0.0)[1] == pytest.approx(-1.0)   # the tip


def test_every_builtin_renders_in_one_scene(builtins):
    """All built-ins side by side (each scaled to a unit box), one 96x96 point render: every
    object covers pixels."""
    scene = pl.Scene()
    n = len(builtins)
    cols = math.ceil(math.sqrt(n))
    objs = []
    for k, fn in enumerate(builtins):
        lo, hi = fn.bounds(samples=17)
        scale = 0.8 / max(np.ptp(np.stack([lo, hi]), axis=0).max(), 1e-6)
        place = pl.translate((k % cols) - (cols - 1) / 2, (cols - 1) / 2 - (k // cols), 0)
        objs.append(scene.add(fn, transform=place @ pl.scale(scale) @ pl.translate(-(lo + hi) / 2)))
    cam = pl.Camera.look_at((0, 0, 1.2 * cols + 1), (0, 0, 0), size=(96, 96), fov_y=50)
    frame = pl.render(scene, cam)
    ids = np.bincount(frame.object_id.ravel(), minlength=len(objs) + 1)
    empty = [fn.name for fn, o in zip(builtins, objs) if ids[o.object_id] < 3]
    assert not empty, f"not drawn: {empty}"
