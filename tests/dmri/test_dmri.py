"""Diffusion-MRI data for SH glyphs (paramlod.dmri): the SH basis handling proven on dipy's and
MRtrix's own data, the NIfTI loader's errors, the dipy CSA fit, the synthetic crossing field and
the glyph scene it becomes."""
import gzip
import warnings
from pathlib import Path

import numpy as np
import pytest

import dipy  # noqa: F401,E402  (the dmri extra; installed with the test extra)
import nibabel as nib  # noqa: E402

from dipy.data import get_fnames, mrtrix_spherical_functions  # noqa: E402
from dipy.reconst.shm import real_sh_descoteaux_from_index, real_sh_tournier  # noqa: E402

import paramlod as pl  # noqa: E402
from paramlod import dmri  # noqa: E402
from paramlod.errors import DmriError  # noqa: E402

GALLERY_DATA = Path(__file__).resolve().parents[2] / "gallery" / "data"


def _quiet(fn, *a, **k):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # dipy's legacy-basis deprecation notices
        return fn(*a, **k)


def _write(path, data, affine=None):
    nib.Nifti1Image(np.asarray(data), np.eye(4) if affine is None else affine).to_filename(str(path))
    return path


@pytest.fixture(scope="module")
def sphere():
    return dmri.fibonacci_sphere(1000)


# --- SH evaluation and bases ---------------------------------------------------------------------

def test_evaluator_matches_dipy_non_legacy_descoteaux07():
    rng = np.random.default_rng(0)
    theta, phi = rng.uniform(0, np.pi, 200), rng.uniform(0, 2 * np.pi, 200)
    l, m = dmri.sh_degrees(12)
    ours = dmri.sh_matrix(12, theta, phi)
    dipy_new = real_sh_descoteaux_from_index(m, l, theta[:, None], phi[:, None], legacy=False)
    np.testing.assert_allclose(ours, dipy_new, rtol=0, atol=1e-12)
    # the legacy basis really is different (odd negative m), so the comparison above means something
    dipy_old = _quiet(real_sh_descoteaux_from_index, m, l, theta[:, None], phi[:, None], legacy=True)
    assert np.abs(ours - dipy_old).max() > 0.5


@pytest.mark.parametrize("basis,legacy", [("tournier07", False), ("tournier07", True), ("descoteaux07", True)])
def test_conversion_keeps_the_function(basis, legacy, sphere):
    """Coefficients in any of dipy's bases, converted, describe the same function on the sphere."""
    rng = np.random.default_rng(1)
    _, theta, phi = sphere
    for order in (2, 8, 12):
        c = rng.normal(size=(5, dmri.coefficient_count(order)))
        src = c @ dmri.dipy_basis_matrix(order, basis, legacy, theta, phi).T
        canon = dmri.to_canonical(c, basis, legacy)
        np.testing.assert_allclose(dmri.sh_evaluate(canon, theta, phi), src, atol=1e-10)
        np.testing.assert_allclose(dmri.from_canonical(canon, basis, legacy), c, atol=1e-10)
        assert np.abs(canon - c).max() > 0.1    # an identity "conversion" would have failed


def test_conversion_agrees_with_the_glyph_function_module():
    import paramlod.functions.sh_glyph as sh
    rng = np.random.default_rng(2)
    c = rng.normal(size=(3, 91))
    np.testing.assert_allclose(sh.convert_basis(c, "tournier07", "descoteaux07"),
                               dmri.to_canonical(c, "tournier07"), atol=1e-12)


# --- the MRtrix check ----------------------------------------------------------------------------

def _mrtrix_files():
    """(path of func_coef.nii.gz, MRtrix's samples [2, 3, 4, 81], the sphere_grad.txt directions)."""
    import dipy.data

    _, discrete, sph = mrtrix_spherical_functions()
    return Path(dipy.data.DATA_DIR) / "func_coef.nii.gz", discrete, sph


def test_mrtrix_coefficients_reproduce_mrtrix_samples():
    """dipy's func_coef.nii.gz (written by MRtrix's dwi2SH, lmax 8) evaluated by paramlod on the
    directions of sphere_grad.txt gives MRtrix's own func_discrete.nii.gz. dwi2SH is MRtrix 0.2,
    whose tournier07 variant dipy calls legacy (no sqrt2 on m != 0)."""
    path, discrete, sph = _mrtrix_files()
    fld = dmri.load_sh_volume(path, basis="tournier07", legacy=True)
    assert len(fld) == 2 * 3 * 4 and fld.order == 8 and fld.coeffs.shape == (24, 91)
    theta, phi = dmri.cart_to_angles(sph.vertices)
    got = fld.radii(theta, phi)
    want = discrete[tuple(fld.ijk.T)]
    assert np.abs(want).max() > 1
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-4)   # float32 data, values up to 5.7


@pytest.mark.parametrize("basis,legacy", [("tournier07", False), ("descoteaux07", False), ("descoteaux07", True)])
def test_mrtrix_coefficients_in_a_wrong_basis_do_not_reproduce(basis, legacy):
    path, discrete, sph = _mrtrix_files()
    fld = dmri.load_sh_volume(path, basis=basis, legacy=legacy)
    theta, phi = dmri.cart_to_angles(sph.vertices)
    err = np.abs(fld.radii(theta, phi) - discrete[tuple(fld.ijk.T)]).max()
    assert err > 0.2, f"{basis} legacy={legacy} reproduced MRtrix's samples (max error {err})"


# --- the loader ----------------------------------------------------------------------------------

def test_loader_places_voxels_and_converts(tmp_path, sphere):
    rng = np.random.default_rng(3)
    c = rng.normal(size=(4, 5, 3, 15)).astype(np.float32)
    aff = np.array([[0, -2.0, 0, 10], [1.5, 0, 0, -3], [0, 0, 2.5, 7], [0, 0, 0, 1]])
    path = _write(tmp_path / "fod.nii.gz", c, aff)
    fld = dmri.load_sh_volume(path, basis="tournier07")
    assert len(fld) == 60 and fld.order == 4 and fld.frame == "world" and not fld.synthetic
    i, j, k = fld.ijk.T
    np.testing.assert_allclose(fld.positions, np.stack([-2 * j + 10, 1.5 * i - 3, 2.5 * k + 7], axis=1))
    assert fld.spacing == pytest.approx(1.5)
    assert np.all(fld.coeffs[:, 15:] == 0)
    _, theta, phi = sphere
    want = c[i, j, k].astype(np.float64) @ real_sh_tournier(4, theta, phi, legacy=False)[0].T
    np.testing.assert_allclose(fld.radii(theta, phi), want, atol=1e-5)


def test_loader_mask_stride_region(tmp_path):
    c = np.ones((6, 6, 4, 6), np.float32)
    path = _write(tmp_path / "sh.nii", c, np.diag([2.0, 2.0, 2.0, 1.0]))
    fld = dmri.load_sh_volume(path, stride=2)
    assert len(fld) == 3 * 3 * 2 and np.all(fld.ijk % 2 == 0) and fld.spacing == pytest.approx(4.0)
    mask = np.zeros((6, 6, 4), bool)
    mask[1:3, 2, 0] = True
    fld = dmri.load_sh_volume(path, mask=mask)
    assert sorted(map(tuple, fld.ijk)) == [(1, 2, 0), (2, 2, 0)]
    mpath = _write(tmp_path / "mask.nii.gz", mask.astype(np.uint8))
    assert len(dmri.load_sh_volume(path, mask=mpath)) == 2
    fld = dmri.load_sh_volume(path, region=(slice(None), slice(None), slice(1, 2)))
    assert len(fld) == 36 and set(fld.ijk[:, 2]) == {1}
    with pytest.raises(DmriError, match=r"mask shape \(6, 6\) does not match"):
        dmri.load_sh_volume(path, mask=np.ones((6, 6), bool))


def test_loader_rejects_a_non_sh_4th_dimension(tmp_path):
    path = _write(tmp_path / "dwi.nii.gz", np.zeros((3, 3, 3, 65), np.float32))
    with pytest.raises(DmriError) as e:
        dmri.load_sh_volume(path)
    msg = str(e.value)
    assert "dwi.nii.gz" in msg and "65" in msg and "45 (order 8)" in msg and "91 (order 12)" in msg
    full = _write(tmp_path / "full.nii.gz", np.zeros((2, 2, 2, 81), np.float32))
    with pytest.raises(DmriError, match="full odd-and-even basis"):
        dmri.load_sh_volume(full)
    big = _write(tmp_path / "o14.nii.gz", np.zeros((2, 2, 2, 120), np.float32))
    with pytest.raises(DmriError, match="orders above 12"):
        dmri.load_sh_volume(big)


def test_loader_rejects_a_3d_file(tmp_path):
    path = _write(tmp_path / "fa.nii.gz", np.zeros((4, 4, 4), np.float32))
    with pytest.raises(DmriError, match=r"fa\.nii\.gz: is a 3D volume \(4, 4, 4\).*4th dimension"):
        dmri.load_sh_volume(path)


def test_loader_rejects_corrupt_and_missing_files(tmp_path):
    junk = tmp_path / "junk.nii"
    junk.write_bytes(b"this is not a NIfTI file" * 10)
    with pytest.raises(DmriError, match=r"junk\.nii: not a readable NIfTI file"):
        dmri.load_sh_volume(junk)
    bad_gz = tmp_path / "badzip.nii.gz"
    bad_gz.write_bytes(b"\x1f\x8b\x08\x00garbage")
    with pytest.raises(DmriError, match=r"badzip\.nii\.gz: not a readable NIfTI file"):
        dmri.load_sh_volume(bad_gz)
    # a valid header whose data was cut off
    good = _write(tmp_path / "good.nii", np.random.default_rng(0).normal(size=(8, 8, 8, 45)).astype(np.float32))
    cut = tmp_path / "cut.nii.gz"
    cut.write_bytes(gzip.compress(good.read_bytes())[:4000])
    with pytest.raises(DmriError, match=r"cut\.nii\.gz: .*(truncated or corrupt|not a readable)"):
        dmri.load_sh_volume(cut)
    with pytest.raises(DmriError, match="no such file"):
        dmri.load_sh_volume(tmp_path / "nothere.nii.gz")
    with pytest.raises(DmriError, match="unknown SH basis 'mrtrix'"):
        dmri.load_sh_volume(good, basis="mrtrix")
    assert issubclass(DmriError, pl.ParamlodError)


def test_loader_drops_nan_and_empty_voxels(tmp_path):
    c = np.ones((2, 2, 1, 6), np.float32)
    c[0, 0, 0, 3] = np.nan
    c[1, 1, 0] = 0
    path = _write(tmp_path / "nan.nii.gz", c)
    with pytest.warns(UserWarning, match="dropped 1 voxels with NaN"):
        fld = dmri.load_sh_volume(path)
    assert len(fld) == 2 and fld.metadata["dropped_nonfinite"] == 1 and fld.metadata["dropped_empty"] == 1
    assert np.all(np.isfinite(fld.coeffs))
    allnan = _write(tmp_path / "allnan.nii.gz", np.full((2, 1, 1, 6), np.nan, np.float32))
    with pytest.raises(DmriError, match="no voxels left.*2 not finite"), pytest.warns(UserWarning):
        dmri.load_sh_volume(allnan)


# --- dipy CSA fit ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def csa():
    return dmri.fit_csa_odf("small_64D", order=8)


def test_csa_fit_on_small_64d(csa, sphere):
    assert len(csa) == 1000 and csa.order == 8 and csa.coeffs.shape == (1000, 91)
    assert np.all(np.isfinite(csa.coeffs)) and np.all(csa.coeffs[:, 45:] == 0)
    _, theta, phi = sphere
    r = csa.radii(theta, phi)
    assert r.mean() > 0 and np.all(r.mean(axis=1) > 0)
    assert csa.spacing == pytest.approx(2.0, rel=1e-6)        # small_64D has 2 mm voxels
    aff = nib.load(str(get_fnames(name="small_64D")[0])).affine
    np.testing.assert_allclose(csa.positions, csa.ijk @ aff[:3, :3].T + aff[:3, 3])


def test_csa_coefficients_are_converted_from_dipys_legacy_basis(csa):
    """dipy's Q-ball models fit in the legacy descoteaux07 basis: paramlod's evaluation of the
    field must equal dipy's own ODF, and reading dipy's raw coefficients as non-legacy must not."""
    from dipy.core.gradients import gradient_table
    from dipy.core.sphere import Sphere
    from dipy.io import read_bvals_bvecs
    from dipy.reconst.shm import CsaOdfModel

    fdwi, fbval, fbvec = get_fnames(name="small_64D")
    bvals, bvecs = read_bvals_bvecs(str(fbval), str(fbvec))
    data = np.asarray(nib.load(str(fdwi)).dataobj, np.float64)
    xyz, theta, phi = dmri.fibonacci_sphere(500)
    fit = _quiet(lambda: CsaOdfModel(gradient_table(bvals, bvecs=bvecs), sh_order_max=8).fit(data))
    want = _quiet(fit.odf, Sphere(xyz=xyz))[tuple(csa.ijk.T)]
    np.testing.assert_allclose(csa.radii(theta, phi), want, atol=1e-9)
    raw = np.asarray(fit.shm_coeff)[tuple(csa.ijk.T)]
    assert np.abs(dmri.sh_evaluate(raw, theta, phi) - want).max() > 1e-2


# --- synthetic field ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def synthetic():
    return dmri.synthetic_crossing_field(140, 140, order=12, seed=0)


def test_synthetic_field_shape_and_label(synthetic):
    s = synthetic
    assert len(s) == 19_600 and s.order == 12 and s.coeffs.shape == (19_600, 91)
    assert s.synthetic and s.metadata["synthetic"] is True and s.metadata["source"] == "synthetic"
    assert np.all(np.isfinite(s.coeffs))
    assert s.spacing == 1.0 and np.ptp(s.positions[:, 0]) == 139 and np.ptp(s.positions[:, 2]) == 0
    frac = s.metadata["fractions"]
    n_fibres = (frac > 0.2).sum(axis=1)
    assert {1, 2, 3} <= set(n_fibres.tolist())          # single fibres, crossings and three-way crossings


def test_synthetic_odf_model_is_dipys_multi_tensor_odf(synthetic):
    from dipy.sims.voxel import multi_tensor_odf

    xyz, _, _ = dmri.fibonacci_sphere(200)
    d, f = synthetic.metadata["directions"], synthetic.metadata["fractions"]
    for i in (0, 7_777, 19_599):
        want = multi_tensor_odf(xyz, np.array([dmri.SYNTHETIC_EVALS] * 3), d[i], 100 * f[i])
        got = np.einsum("k,kp->p", f[i], dmri.tensor_odf(xyz, d[i]))
        np.testing.assert_allclose(got, want, rtol=1e-12)


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.abs(a @ b), 0, 1)))


def test_synthetic_odf_maxima_lie_on_the_fibres(synthetic):
    from dipy.core.sphere import Sphere
    from dipy.direction.peaks import peak_directions

    d, f = synthetic.metadata["directions"], synthetic.metadata["fractions"]
    strong = f > 0.3
    crossing = [i for i in np.flatnonzero(strong.sum(1) >= 2)
                if all(_angle_deg(d[i, a], d[i, b]) > 60 for a in range(3) for b in range(a) if strong[i, a] and strong[i, b])]
    picks = [int(np.flatnonzero(f[:, 0] > 0.999)[123]), *crossing[::max(1, len(crossing) // 4)][:4]]
    assert len(picks) >= 4
    xyz, theta, phi = dmri.fibonacci_sphere(2000)
    dense = Sphere(xyz=xyz)
    r = synthetic.coeffs[picks] @ dmri.sh_matrix(12, theta, phi).T
    for row, i in zip(r, picks):
        peaks, _, _ = peak_directions(row, dense, relative_peak_threshold=0.3, min_separation_angle=20)
        for k in np.flatnonzero(strong[i]):
            assert _angle_deg(peaks, d[i, k]).min() < 8, f"glyph {i}: no ODF maximum near fibre {k}"
        assert len(peaks) == strong[i].sum(), f"glyph {i}: {len(peaks)} maxima for {strong[i].sum()} fibres"


def test_npz_round_trips(tmp_path, csa):
    path = csa.save_npz(tmp_path / "csa.npz")
    back = dmri.load_field_npz(path)
    assert len(back) == 1000 and back.order == 8 and back.frame == "voxel" and back.source_legacy
    np.testing.assert_allclose(back.coeffs, csa.coeffs, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(back.ijk, csa.ijk)
    small = dmri.synthetic_crossing_field(12, 9, order=12, seed=4)
    back = dmri.load_field_npz(dmri.save_synthetic_npz(small, tmp_path / "syn.npz"))
    assert back.synthetic and len(back) == 108
    np.testing.assert_allclose(back.coeffs, small.coeffs, atol=1e-5 * np.abs(small.coeffs).max())
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK\x03\x04 nope")
    with pytest.raises(DmriError, match=r"bad\.npz: not a paramlod SH field file"):
        dmri.load_field_npz(bad)


@pytest.mark.skipif(not (GALLERY_DATA / "small64d_csa_o8.npz").exists(), reason="run gallery/prepare_dmri.py")
def test_gallery_data_files():
    total = sum(p.stat().st_size for p in GALLERY_DATA.glob("*.npz"))
    assert total < 2e6
    csa = dmri.load_field_npz(GALLERY_DATA / "small64d_csa_o8.npz")
    assert len(csa) == 1000 and csa.order == 8 and not csa.synthetic
    syn = dmri.load_field_npz(GALLERY_DATA / "synthetic_140x140_o12.npz")
    assert len(syn) == 19_600 and syn.order == 12 and syn.synthetic


# --- the glyph scene ------------------------------------------------------------------------------

def _glyph_function():
    from paramlod.function.registry import get_function

    return get_function("sh_glyph")


def test_glyph_function_draws_the_canonical_basis():
    """The renderer's sh_glyph and this module's evaluator agree: no basis mix-up between them."""
    fn = _glyph_function()
    rng = np.random.default_rng(5)
    c = rng.normal(size=91)
    u, v = rng.uniform(0, np.pi, 60), rng.uniform(0, 2 * np.pi, 60)
    p = pl.evaluate(fn, u, v, coeffs=c)
    unit = np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)], axis=1)
    np.testing.assert_allclose(np.sum(p * unit, axis=1), dmri.sh_evaluate(c, u, v), atol=1e-5)
    np.testing.assert_allclose(np.cross(p, unit), 0, atol=1e-5)


def _world_max_radius(obj):
    xyz, theta, phi = dmri.fibonacci_sphere(4000)
    r = np.abs(obj.per_instance["coeffs"].astype(np.float64) @ dmri.sh_matrix(12, theta, phi).T).max(axis=1)
    size = np.abs(np.linalg.det(obj.transforms[:, :3, :3])) ** (1 / 3)
    return r * size


def test_to_scene_places_one_object_without_overlap(csa):
    fn = _glyph_function()
    scene = csa.to_scene()
    assert len(scene.objects) == 1
    obj = scene.objects[0]
    assert obj.function is fn and obj.count == 1000 and obj.per_instance["coeffs"].shape == (1000, 91)
    np.testing.assert_allclose(obj.transforms[:, :3, 3], csa.positions)
    lin = obj.transforms[:, :3, :3] / np.abs(np.linalg.det(obj.transforms[:, :3, :3]))[:, None, None] ** (1 / 3)
    np.testing.assert_allclose(lin @ np.transpose(lin, (0, 2, 1)), np.broadcast_to(np.eye(3), lin.shape), atol=1e-9)
    assert np.all(np.linalg.det(lin) > 0)                           # a rotation, never a mirror
    world = _world_max_radius(obj)
    assert world.max() < 0.5 * csa.spacing and world.min() > 0.85 * 0.5 * csa.spacing   # normalized, apart
    kept = csa.to_scene(normalize=False, subtract_min=True).objects[0]
    w = _world_max_radius(kept)
    assert w.max() < 0.5 * csa.spacing and w.min() < 0.6 * w.max()    # relative sizes survive


def test_to_scene_colours_each_glyph_by_direction(synthetic):
    _glyph_function()
    sub = dmri.ShField(synthetic.positions[:400], synthetic.coeffs[:400], 12, "descoteaux07", spacing=1.0)
    scene = sub.to_scene(color_by="direction")
    (obj,) = scene.objects
    assert obj.count == 400 and obj.colors.shape == (400, 3)
    assert np.allclose(obj.colors.max(axis=1), 1.0)               # the dominant axis is full colour
    assert len(np.unique(obj.colors.argmax(axis=1))) >= 2          # glyphs point different ways
    mats = scene.materials()
    np.testing.assert_allclose(mats[:, :3], obj.colors)


def test_to_scene_without_the_glyph_function_says_so(monkeypatch, csa):
    import paramlod.function.registry as reg

    def missing(name):
        raise pl.FunctionError(f"no function named '{name}'")

    monkeypatch.setattr(reg, "get_function", missing)
    with pytest.raises(DmriError, match="needs the 'sh_glyph' parametric function"):
        csa.to_scene()


def test_glyphs_command_renders_an_sh_volume_and_names_bad_files(tmp_path, capsys):
    import importlib.resources

    from paramlod.app.cli import main

    coef = str(importlib.resources.files("dipy") / "data" / "files" / "func_coef.nii.gz")
    out = tmp_path / "g.png"
    assert main(["glyphs", coef, "--basis", "tournier07", "--legacy", "--size", "64x64", "-o", str(out)]) == 0
    assert "24 glyphs of order 8" in capsys.readouterr().out and out.stat().st_size > 0
    bad = tmp_path / "bad.nii.gz"
    bad.write_bytes(b"not a nifti")
    assert main(["glyphs", str(bad), "-o", str(tmp_path / "x.png")]) == 2
    assert str(bad) in capsys.readouterr().err
    # a field .npz is stored sampled: the volume's options were ignored (every glyph drawn)
    npz = str(Path(__file__).resolve().parents[2] / "gallery" / "data" / "small64d_csa_o8.npz")
    assert main(["glyphs", npz, "--stride", "2", "--slice", "3", "-o", str(tmp_path / "n.png")]) == 2
    assert "--stride, --slice apply to NIfTI SH volumes" in capsys.readouterr().err
    assert not (tmp_path / "n.png").exists()
