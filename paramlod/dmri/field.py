"""Diffusion-MRI data for SH glyphs: NIfTI SH volumes, a dipy Q-ball fit, a synthetic crossing field.

Every field ends up as an ``ShField``: voxel centres in world millimetres and SH coefficients in the
project's canonical basis, dipy's **non-legacy descoteaux07** (ARCHITECTURE.md, "SH glyphs"), padded
to order 12 (91 coefficients). Coefficients are converted on the way in, never reinterpreted: MRtrix
files are in ``tournier07``, dipy fits in ``descoteaux07`` -- and dipy's own Q-ball models still fit
in the *legacy* descoteaux07 basis, which ``fit_csa_odf`` converts as well.

Convention (shared with ``sh_glyph`` and dipy): theta is the polar angle from +z, phi the azimuth
from +x; even l only; coefficient index l(l+1)/2 + m for m = -l..l.

Needs the optional extra ``paramlod[dmri]`` (dipy, nibabel) for loading and fitting; evaluating a
field (``sh_matrix``, ``ShField.radii``) and reading the gallery's ``.npz`` files need only numpy
and scipy. See docs/dmri.md.
"""
from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from paramlod.errors import DmriError, ParamlodError

CANONICAL_BASIS = "descoteaux07"
BASES = ("descoteaux07", "tournier07")
SH_ORDERS = (0, 2, 4, 6, 8, 10, 12)
MAX_ORDER = 12
GLYPH_FUNCTION = "sh_glyph"


# --- SH bookkeeping and evaluation (numpy/scipy only) --------------------------------------------

def coefficient_count(order: int) -> int:
    """(order+1)(order+2)/2: 1, 6, 15, 28, 45, 66, 91 for orders 0..12."""
    return (order + 1) * (order + 2) // 2


def order_for_count(n: int) -> int | None:
    """The even order whose basis has ``n`` coefficients, or None."""
    for order in SH_ORDERS:
        if coefficient_count(order) == n:
            return order
    return None


def _allowed_counts() -> str:
    return ", ".join(f"{coefficient_count(o)} (order {o})" for o in SH_ORDERS)


def sh_degrees(order: int) -> tuple[np.ndarray, np.ndarray]:
    """(l, m) of each coefficient in dipy's order: l = 0, 2, .., order; m = -l..l."""
    ls, ms = [], []
    for l in range(0, order + 1, 2):
        for m in range(-l, l + 1):
            ls.append(l)
            ms.append(m)
    return np.array(ls), np.array(ms)


def _complex_sh(l, m, theta, phi):
    """Complex orthonormal Y_l^m (Condon-Shortley phase), theta polar, phi azimuth."""
    import scipy.special as sps

    if hasattr(sps, "sph_harm_y"):          # scipy >= 1.15
        return sps.sph_harm_y(l, m, theta, phi)
    return sps.sph_harm(m, l, phi, theta)   # older scipy: (order, degree, azimuth, polar)


def sh_matrix(order: int, theta, phi) -> np.ndarray:
    """Canonical basis (non-legacy descoteaux07) sampled at the directions: [P, n_coeffs].

    m > 0: sqrt2 Im(Y_l^m); m = 0: Y_l^0; m < 0: sqrt2 Re(Y_l^m) (m itself, not |m|).
    """
    if order not in SH_ORDERS:
        raise DmriError(f"SH order must be one of {SH_ORDERS}, got {order!r}")
    theta = np.asarray(theta, dtype=np.float64).reshape(-1, 1)
    phi = np.asarray(phi, dtype=np.float64).reshape(-1, 1)
    l, m = sh_degrees(order)
    y = _complex_sh(l[None, :], m[None, :], theta, phi)
    return np.where(m > 0, math.sqrt(2) * y.imag, np.where(m == 0, y.real, math.sqrt(2) * y.real))


def sh_evaluate(coeffs, theta, phi) -> np.ndarray:
    """Values of canonical-basis SH series [..., n] at P directions: [..., P]."""
    c = np.asarray(coeffs, dtype=np.float64)
    order = order_for_count(c.shape[-1])
    if order is None:
        raise DmriError(f"{c.shape[-1]} coefficients is not an even-order SH set; allowed: {_allowed_counts()}")
    return c @ sh_matrix(order, theta, phi).T


def pad_to_order(coeffs, order: int = MAX_ORDER) -> np.ndarray:
    """Zero-pad [..., n] coefficients to ``order`` (lower bands come first in dipy's ordering)."""
    c = np.asarray(coeffs, dtype=np.float64)
    have = order_for_count(c.shape[-1])
    if have is None or have > order:
        raise DmriError(f"cannot pad {c.shape[-1]} coefficients to order {order}")
    out = np.zeros(c.shape[:-1] + (coefficient_count(order),))
    out[..., :c.shape[-1]] = c
    return out


def fibonacci_sphere(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` near-uniform unit vectors and their (theta, phi)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.mod(k * math.pi * (3 - math.sqrt(5)), 2 * math.pi)
    theta = np.arccos(z)
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1), theta, phi


def cart_to_angles(xyz) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) of the directions [..., 3] (need not be unit length)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    r = np.linalg.norm(xyz, axis=-1)
    theta = np.arccos(np.clip(xyz[..., 2] / np.where(r > 0, r, 1), -1, 1))
    phi = np.mod(np.arctan2(xyz[..., 1], xyz[..., 0]), 2 * math.pi)
    return theta, phi


# --- basis conversion through dipy's own basis functions -----------------------------------------

def _dipy():
    try:
        import dipy.reconst.shm as shm
        import nibabel  # noqa: F401  (checked here so the message names both)
    except ImportError as e:
        raise DmriError("diffusion-MRI support needs dipy and nibabel: pip install 'paramlod[dmri]' "
                        f"({e})") from None
    return shm


def _check_basis(basis: str) -> None:
    if basis not in BASES:
        raise DmriError(f"unknown SH basis {basis!r}; use 'descoteaux07' (dipy) or 'tournier07' (MRtrix3)")


def dipy_basis_matrix(order: int, basis: str, legacy: bool, theta, phi) -> np.ndarray:
    """dipy's real SH basis ``basis`` (legacy or not) sampled at the directions: [P, n]."""
    _check_basis(basis)
    shm = _dipy()
    fn = shm.real_sh_descoteaux if basis == "descoteaux07" else shm.real_sh_tournier
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # dipy warns that the legacy bases are deprecated
        B, m, l = fn(order, np.asarray(theta, np.float64), np.asarray(phi, np.float64), legacy=legacy)
    want_l, want_m = sh_degrees(order)
    if not (np.array_equal(l, want_l) and np.array_equal(m, want_m)):
        raise DmriError(f"dipy's {basis} basis has an unexpected coefficient order")  # dipy changed?
    return np.asarray(B, np.float64)


@lru_cache(maxsize=None)
def conversion_matrix(order: int, source: str, legacy: bool = False) -> np.ndarray:
    """K with c_canonical = K @ c_source, for dipy's ``source`` basis (``legacy`` as dipy means it).

    Found by least squares between dipy's basis functions on 1200 directions, so it holds for any
    pair of bases spanning the even bands (for the orthonormal ones K is a signed permutation).
    """
    xyz, theta, phi = fibonacci_sphere(1200)
    b_src = dipy_basis_matrix(order, source, legacy, theta, phi)
    b_can = dipy_basis_matrix(order, CANONICAL_BASIS, False, theta, phi)
    K, *_ = np.linalg.lstsq(b_can, b_src, rcond=None)
    K[np.abs(K) < 1e-12] = 0.0
    K.setflags(write=False)
    return K


def _sh_set(coeffs, basis: str) -> tuple[np.ndarray, int]:
    """(coefficients as float64, their order), checking the basis name and the count."""
    _check_basis(basis)
    c = np.asarray(coeffs, dtype=np.float64)
    order = order_for_count(c.shape[-1])
    if order is None:
        raise DmriError(f"{c.shape[-1]} coefficients is not an even-order SH set; allowed: {_allowed_counts()}")
    return c, order


def to_canonical(coeffs, basis: str, legacy: bool = False) -> np.ndarray:
    """Coefficients [..., n] in dipy's ``basis`` -> the canonical non-legacy descoteaux07."""
    c, order = _sh_set(coeffs, basis)
    if basis == CANONICAL_BASIS and not legacy:
        return c.copy()
    return c @ conversion_matrix(order, basis, bool(legacy)).T


def from_canonical(coeffs, basis: str, legacy: bool = False) -> np.ndarray:
    """Inverse of ``to_canonical``."""
    c, order = _sh_set(coeffs, basis)
    if basis == CANONICAL_BASIS and not legacy:
        return c.copy()
    return c @ np.linalg.inv(conversion_matrix(order, basis, bool(legacy))).T


# --- the field ------------------------------------------------------------------------------------

def _polar_rotation(linear: np.ndarray) -> np.ndarray:
    """The rotation nearest to ``linear`` (3x3). A reflection is replaced by its negative: even SH
    functions are antipodally symmetric, so -R draws the same glyph as R."""
    u, _, vt = np.linalg.svd(np.asarray(linear, np.float64))
    r = u @ vt
    return -r if np.linalg.det(r) < 0 else r


@dataclass
class ShField:
    """SH glyphs at voxel centres.

    ``positions`` [n, 3] float64 world mm; ``coeffs`` [n, 91] float64 canonical basis (non-legacy
    descoteaux07), zero above ``order``; ``source_basis``/``source_legacy`` say what the input was;
    ``frame`` is 'world' when the SH directions are world (scanner) axes (MRtrix) and 'voxel' when
    they are the image axes (dipy fits with FSL-style bvecs); ``affine`` maps voxel indices to
    world; ``ijk`` [n, 3] are the voxel indices; ``spacing`` is the smallest distance between two
    glyph centres (mm).
    """
    positions: np.ndarray
    coeffs: np.ndarray
    order: int
    source_basis: str
    source_legacy: bool = False
    frame: str = "world"
    affine: np.ndarray = field(default_factory=lambda: np.eye(4))
    ijk: np.ndarray | None = None
    spacing: float = 1.0
    metadata: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def synthetic(self) -> bool:
        return bool(self.metadata.get("synthetic", False))

    def radii(self, theta, phi) -> np.ndarray:
        """Signed glyph radii [n, P] at the directions (in the coefficients' own frame)."""
        return sh_evaluate(self.coeffs[:, :coefficient_count(self.order)], theta, phi)

    def glyph_rotation(self) -> np.ndarray:
        """3x3 rotation from the coefficients' frame to world."""
        return np.eye(3) if self.frame == "world" else _polar_rotation(self.affine[:3, :3])

    def radius_extremes(self, samples: int = 2000, chunk: int = 4096):
        """Sampled extremes of each glyph's signed radius over ``samples`` directions:
        (min [n], max [n], direction of the largest |r| [n, 3], direction of the max [n, 3]),
        directions as unit vectors in the coefficients' frame."""
        xyz, theta, phi = fibonacci_sphere(samples)
        B = sh_matrix(self.order, theta, phi)
        k, n = coefficient_count(self.order), len(self)
        lo, hi, d_abs, d_hi = np.empty(n), np.empty(n), np.empty((n, 3)), np.empty((n, 3))
        for a in range(0, n, chunk):
            r = self.coeffs[a:a + chunk, :k] @ B.T
            rows = np.arange(len(r))
            i_lo, i_hi = np.argmin(r, axis=1), np.argmax(r, axis=1)
            lo[a:a + chunk], hi[a:a + chunk] = r[rows, i_lo], r[rows, i_hi]
            d_hi[a:a + chunk] = xyz[i_hi]
            d_abs[a:a + chunk] = np.where((-r[rows, i_lo] > r[rows, i_hi])[:, None], xyz[i_lo], xyz[i_hi])
        return lo, hi, d_abs, d_hi

    def to_scene(self, scene=None, scale: float = 0.9, normalize: bool = True, color_by: str | None = None,
                 material=None, transform=None, subtract_min: bool = False):
        """Add the field to ``scene`` (a new Scene if None) as 'sh_glyph' instances; returns the scene.

        Each glyph sits at its voxel centre, rotated into world for a 'voxel'-frame field. ``scale``
        is the largest glyph radius as a fraction of half the spacing between glyph centres, so
        with scale < 1 neighbours do not overlap (the default 0.9 leaves a margin for the sampling). ``normalize=True`` gives every glyph that same
        largest radius (shape only); ``normalize=False`` keeps relative sizes, the field's largest
        glyph reaching ``scale``. Largest radii are sampled on 2000 directions. ``subtract_min``
        lowers each glyph's radius by its minimum (min-max display normalization: no negative lobes,
        sharper shapes; for ODFs such as CSA's, which dip below zero).

        The field is ONE object. ``color_by=None`` gives every glyph the material's colour;
        ``color_by='direction'`` colours each glyph by the |x|, |y|, |z| of its largest lobe's world
        direction (the usual dMRI colour code), as per-instance colours.
        """
        import paramlod as pl
        from paramlod.function.registry import get_function

        try:
            fn = get_function(GLYPH_FUNCTION)
        except ParamlodError as e:
            raise DmriError(f"ShField.to_scene needs the '{GLYPH_FUNCTION}' parametric function, "
                            f"which is not available: {e}") from None
        pmap = {p.name: p for p in fn.params}
        want = coefficient_count(MAX_ORDER)
        if "coeffs" not in pmap or pmap["coeffs"].size != want:
            raise DmriError(f"'{GLYPH_FUNCTION}' must take 'coeffs' with {want} floats (order {MAX_ORDER})")
        if not 0 < scale:
            raise DmriError(f"to_scene: scale must be positive, got {scale!r}")
        if color_by not in (None, "direction"):
            raise DmriError(f"to_scene: color_by must be None or 'direction', got {color_by!r}")
        if len(self) == 0:
            raise DmriError("to_scene: the field has no glyphs")
        lo, hi, peak_dir, hi_dir = self.radius_extremes()
        coeffs = self.coeffs.copy()
        if subtract_min:
            coeffs[:, 0] -= lo * (2 * math.sqrt(math.pi))   # Y_0^0 = 1 / (2 sqrt(pi))
            rmax, peak_dir = hi - lo, hi_dir
        else:
            rmax = np.maximum(np.abs(lo), np.abs(hi))
        keep = np.isfinite(rmax) & (rmax > 0)
        if not keep.any():
            raise DmriError("to_scene: every glyph has zero radius")
        half = 0.5 * self.spacing * scale
        size = half / rmax[keep] if normalize else np.full(int(keep.sum()), half / rmax[keep].max())
        rot = self.glyph_rotation()
        n = int(keep.sum())
        tr = np.zeros((n, 4, 4))
        tr[:, :3, :3] = rot[None] * size[:, None, None]
        tr[:, :3, 3] = self.positions[keep]
        tr[:, 3, 3] = 1.0
        coeffs = coeffs[keep].astype(np.float32)
        scene = scene if scene is not None else pl.Scene()
        colors = None
        if color_by == "direction":
            rgb = np.abs(peak_dir[keep] @ rot.T)
            colors = 0.15 + 0.85 * rgb / rgb.max(axis=1, keepdims=True)
        scene.add_instances(fn, n, per_instance={"coeffs": coeffs}, transforms=tr, transform=transform,
                            material=material or pl.Material(color=(0.8, 0.75, 0.7)), colors=colors)
        return scene

    # -- npz round trip (the gallery's data files) --
    def save_npz(self, path) -> Path:
        """Write positions and native-order coefficients (float32) plus metadata to ``path``."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        k = coefficient_count(self.order)
        np.savez_compressed(
            path, kind="coeffs", positions=self.positions.astype(np.float32),
            coeffs=self.coeffs[:, :k].astype(np.float32), **self._header())
        return path

    def _header(self) -> dict:
        return dict(order=self.order, basis=CANONICAL_BASIS, source_basis=self.source_basis,
                    source_legacy=self.source_legacy, frame=self.frame, affine=self.affine,
                    ijk=(self.ijk if self.ijk is not None else np.zeros((0, 3))).astype(np.int32), spacing=self.spacing,
                    metadata=json.dumps(_jsonable(self.metadata)))


def _jsonable(meta: dict) -> dict:
    """Scalars and strings only (arrays stay out of the file's JSON header)."""
    out = {}
    for k, v in meta.items():
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, (list, tuple)) and all(isinstance(x, (int, float, str)) for x in v):
            out[k] = list(v)
        elif isinstance(v, (str, int, float, bool, type(None))):
            out[k] = v
    return out


def load_field_npz(path) -> ShField:
    """Read a field written by ``ShField.save_npz`` or ``save_synthetic_npz`` (numpy/scipy only)."""
    path = Path(path)
    if not path.is_file():
        raise DmriError(f"{path}: no such file (make it with: python gallery/prepare_dmri.py)")
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
        kind = str(d["kind"])
        meta = json.loads(str(d["metadata"]))
        order = int(d["order"])
    except Exception as e:  # noqa: BLE001 - any unreadable file becomes one clear error
        raise DmriError(f"{path}: not a paramlod SH field file ({type(e).__name__}: {e})") from None
    common = dict(order=order, source_basis=str(d["source_basis"]), source_legacy=bool(d["source_legacy"]),
                  frame=str(d["frame"]), affine=np.asarray(d["affine"], np.float64),
                  ijk=np.asarray(d["ijk"]) if len(d["ijk"]) else None, spacing=float(d["spacing"]), metadata=meta)
    if kind == "coeffs":
        return ShField(positions=d["positions"].astype(np.float64),
                       coeffs=pad_to_order(d["coeffs"].astype(np.float64)), **common)
    if kind == "synthetic-model":
        coeffs = _fit_sh_numpy(_crossing_odfs(d["directions"].astype(np.float64), d["fractions"].astype(np.float64),
                                              tuple(meta["evals"]), bool(meta["subtract_min"]))[0], order)
        return ShField(positions=d["positions"].astype(np.float64), coeffs=pad_to_order(coeffs), **common)
    raise DmriError(f"{path}: unknown field kind {kind!r}")


# --- NIfTI SH volumes ------------------------------------------------------------------------------

def _load_nifti(path: Path):
    import nibabel as nib

    if not path.exists():
        raise DmriError(f"{path}: no such file")
    try:
        img = nib.load(str(path))
        _ = img.shape, img.affine
    except Exception as e:  # noqa: BLE001
        raise DmriError(f"{path}: not a readable NIfTI file ({type(e).__name__}: {e})") from None
    if not isinstance(img, (nib.Nifti1Image, nib.Nifti2Image)):
        raise DmriError(f"{path}: is a {type(img).__name__}, not NIfTI (.nii / .nii.gz); convert .mif files "
                        "with MRtrix's mrconvert")
    return img


def _read(img, path: Path, index) -> np.ndarray:
    try:
        return np.asarray(img.dataobj[index], dtype=np.float64)
    except Exception as e:  # noqa: BLE001 - truncated/corrupt data reads fail in many ways
        raise DmriError(f"{path}: the image data cannot be read; the file is truncated or corrupt "
                        f"({type(e).__name__}: {e})") from None


def _neighbour_spacing(affine: np.ndarray, step) -> float:
    """Smallest world distance between a voxel centre and its 26 neighbours (with ``step``)."""
    lin = affine[:3, :3] * np.broadcast_to(np.asarray(step, np.float64), (3,))[None, :]
    offs = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)])
    return float(np.linalg.norm(offs @ lin.T, axis=1).min())


def _mask_array(mask, shape, path_for_msg) -> np.ndarray:
    if mask is None:
        return np.ones(shape, bool)
    if isinstance(mask, (str, Path)):
        mpath = Path(mask)
        img = _load_nifti(mpath)
        m = _read(img, mpath, ...)
        if m.ndim == 4 and m.shape[3] == 1:
            m = m[..., 0]
        src = mpath
    else:
        m, src = np.asarray(mask), "mask array"
    if m.shape != tuple(shape):
        raise DmriError(f"{src}: mask shape {m.shape} does not match the volume {path_for_msg} {tuple(shape)}")
    return np.asarray(m) != 0


def load_sh_volume(path, basis: str = "descoteaux07", mask=None, stride=1, *, legacy: bool = False,
                   region=None, frame: str | None = None) -> ShField:
    """Load a 4D NIfTI of SH coefficients (one voxel's set along the 4th axis) as an ShField.

    ``basis``: the file's basis as dipy names it: 'tournier07' for MRtrix3 files (dwi2fod, mrconvert
    to .nii), 'descoteaux07' for dipy. ``legacy=True`` for dipy's legacy descoteaux07 (what dipy's
    Q-ball models and ``legacy=True`` writers produce) or MRtrix 0.2's tournier07.
    ``mask``: a boolean array or a NIfTI path of the volume's spatial shape; ``stride``: keep every
    stride-th voxel (int or 3 ints); ``region``: a tuple of 3 slices applied first (e.g. one axial
    slice: ``(slice(None), slice(None), slice(30, 31))``). Voxels whose coefficients are all zero
    (outside the brain in MRtrix output) or not finite (NaN/inf) are dropped; the counts are in
    ``metadata`` and a warning names the non-finite count.
    ``frame``: 'world' or 'voxel' axes for the SH directions; default 'world' for tournier07
    (MRtrix defines its SH in scanner space), 'voxel' for descoteaux07 (dipy fits in bvec space).
    """
    _check_basis(basis)
    _dipy()
    path = Path(path)
    img = _load_nifti(path)
    shape = tuple(int(s) for s in img.shape)
    if len(shape) == 5 and shape[3] == 1:       # NIfTI's (x, y, z, t=1, vector) layout
        shape = shape[:3] + shape[4:]
        squeeze = True
    else:
        squeeze = False
    if len(shape) == 3:
        raise DmriError(f"{path}: is a 3D volume {shape}; an SH volume needs a 4th dimension holding the "
                        f"coefficients, of size {_allowed_counts()}")
    if len(shape) != 4:
        raise DmriError(f"{path}: has {len(shape)} dimensions {shape}; an SH volume is 4D (x, y, z, coefficients)")
    n = shape[3]
    order = order_for_count(n)
    if order is None:
        hint = ""
        if n in {(k + 1) ** 2 for k in range(1, 13)}:
            hint = " (that is a full odd-and-even basis, which SH glyphs do not use)"
        elif n > coefficient_count(MAX_ORDER):
            hint = f" (orders above {MAX_ORDER} are not supported)"
        raise DmriError(f"{path}: the 4th dimension has {n} values, which is not an even-order SH coefficient "
                        f"count{hint}; allowed sizes: {_allowed_counts()}")
    step = np.broadcast_to(np.asarray(stride), (3,)).astype(int)
    if np.any(step < 1):
        raise DmriError(f"stride must be a positive integer (or 3), got {stride!r}")
    region = tuple(region) if region is not None else (slice(None),) * 3
    if len(region) != 3 or not all(isinstance(s, slice) for s in region):
        raise DmriError(f"region must be a tuple of 3 slices, got {region!r}")
    grids = [np.arange(shape[a])[region[a]][::step[a]] for a in range(3)]
    if any(len(g) == 0 for g in grids):
        raise DmriError(f"{path}: region {region} with stride {tuple(step)} selects no voxels of {shape[:3]}")
    full_mask = _mask_array(mask, shape[:3], path)
    sub = tuple(slice(g[0], g[-1] + 1, step[a]) for a, g in enumerate(grids))
    index = sub[:3] + ((0, slice(None)) if squeeze else (slice(None),))
    data = _read(img, path, index)
    m = full_mask[sub]
    finite = np.all(np.isfinite(data), axis=-1)
    empty = finite & np.all(data == 0, axis=-1)
    n_nonfinite = int((m & ~finite).sum())
    n_empty = int((m & empty).sum())
    keep = m & finite & ~empty
    if n_nonfinite:
        warnings.warn(f"{path}: dropped {n_nonfinite} voxels with NaN or infinite coefficients", stacklevel=2)
    if not keep.any():
        raise DmriError(f"{path}: no voxels left to draw (of {m.size} selected: {int((~m).sum())} outside the "
                        f"mask, {n_empty} all zero, {n_nonfinite} not finite)")
    ii, jj, kk = np.nonzero(keep)
    ijk = np.stack([grids[0][ii], grids[1][jj], grids[2][kk]], axis=1)
    affine = np.asarray(img.affine, np.float64)
    positions = ijk @ affine[:3, :3].T + affine[:3, 3]
    coeffs = pad_to_order(to_canonical(data[keep], basis, legacy))
    if frame is None:
        frame = "world" if basis == "tournier07" else "voxel"
    if frame not in ("world", "voxel"):
        raise DmriError(f"frame must be 'world' or 'voxel', got {frame!r}")
    return ShField(positions=positions, coeffs=coeffs, order=order, source_basis=basis, source_legacy=legacy,
                   frame=frame, affine=affine, ijk=ijk, spacing=_neighbour_spacing(affine, step),
                   metadata={"source": str(path), "synthetic": False, "dropped_nonfinite": n_nonfinite,
                             "dropped_empty": n_empty, "stride": ",".join(map(str, step))})


# --- constant-solid-angle Q-ball fit with dipy ------------------------------------------------------

def fit_csa_odf(dwi="small_64D", bvals=None, bvecs=None, order: int = 8, mask=None, *, affine=None,
                smooth: float = 0.006) -> ShField:
    """Fit dipy's constant-solid-angle Q-ball model (CsaOdfModel) and return its ODF field.

    ``dwi``: 'small_64D' (dipy's bundled 10x10x10 scan, 64 directions; the default), a NIfTI path
    (then ``bvals``/``bvecs`` are FSL-style text files or arrays), or a 4D array (then ``affine``
    too). ``mask``: boolean array of the spatial shape; by default voxels whose mean b0 signal is
    positive. dipy's Q-ball models fit in the *legacy* descoteaux07 basis; the coefficients are
    converted to the canonical non-legacy basis here.
    """
    shm = _dipy()
    from dipy.core.gradients import gradient_table
    from dipy.io import read_bvals_bvecs

    if order not in SH_ORDERS or order == 0:
        raise DmriError(f"CSA order must be one of {SH_ORDERS[1:]}, got {order!r}")
    label = "array"
    if isinstance(dwi, str) and dwi == "small_64D":
        from dipy.data import get_fnames
        dwi, bvals, bvecs = get_fnames(name="small_64D")
    if isinstance(dwi, (str, Path)):
        label = str(dwi)
        img = _load_nifti(Path(dwi))
        data = _read(img, Path(dwi), ...)
        affine = np.asarray(img.affine, np.float64)
    else:
        data = np.asarray(dwi, np.float64)
        if affine is None:
            raise DmriError("fit_csa_odf: an array input needs affine= (voxel -> world mm)")
        affine = np.asarray(affine, np.float64)
    if data.ndim != 4:
        raise DmriError(f"{label}: diffusion data must be 4D (x, y, z, volumes), got shape {data.shape}")
    if bvals is None or bvecs is None:
        raise DmriError(f"{label}: bvals and bvecs are needed")
    try:
        if isinstance(bvals, (str, Path)) or isinstance(bvecs, (str, Path)):
            bvals, bvecs = read_bvals_bvecs(str(bvals), str(bvecs))
        bvals = np.asarray(bvals, np.float64).reshape(-1)
        bvecs = np.asarray(bvecs, np.float64)
        if bvecs.shape == (3, len(bvals)):
            bvecs = bvecs.T
        gtab = gradient_table(bvals, bvecs=bvecs)
    except DmriError:
        raise
    except Exception as e:  # noqa: BLE001
        raise DmriError(f"{label}: unusable bvals/bvecs ({type(e).__name__}: {e})") from None
    if len(bvals) != data.shape[3]:
        raise DmriError(f"{label}: {data.shape[3]} volumes but {len(bvals)} b-values")
    n_dirs = int((~gtab.b0s_mask).sum())
    if n_dirs < coefficient_count(order) or not gtab.b0s_mask.any():
        raise DmriError(f"{label}: order {order} needs {coefficient_count(order)} diffusion directions and a "
                        f"b0 volume; the scan has {n_dirs} directions and {int(gtab.b0s_mask.sum())} b0s")
    b0 = data[..., gtab.b0s_mask].mean(axis=-1)
    m = (b0 > 0) if mask is None else _mask_array(mask, data.shape[:3], label)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # legacy-basis deprecation notices from dipy
        fit = shm.CsaOdfModel(gtab, sh_order_max=order, smooth=smooth).fit(data, mask=m)
    coef = np.asarray(fit.shm_coeff)[m]
    ijk = np.argwhere(m)
    keep = np.all(np.isfinite(coef), axis=1)
    if not keep.all():
        warnings.warn(f"{label}: dropped {int((~keep).sum())} voxels whose fit is not finite", stacklevel=2)
    coef, ijk = coef[keep], ijk[keep]
    positions = ijk @ affine[:3, :3].T + affine[:3, 3]
    return ShField(positions=positions, coeffs=pad_to_order(to_canonical(coef, "descoteaux07", legacy=True)),
                   order=order, source_basis="descoteaux07", source_legacy=True, frame="voxel", affine=affine,
                   ijk=ijk, spacing=_neighbour_spacing(affine, 1),
                   metadata={"source": label, "synthetic": False, "model": f"dipy CsaOdfModel order {order}",
                             "smooth": smooth})


# --- synthetic crossing-fibre field -------------------------------------------------------------

SYNTHETIC_EVALS = (1.7e-3, 0.3e-3, 0.3e-3)   # mm^2/s, an axially symmetric tensor per fibre
_SYN_SPHERE = 900                             # directions the ODFs are sampled on before fitting


def tensor_odf(directions, fibre, evals=SYNTHETIC_EVALS) -> np.ndarray:
    """ODF of one axially symmetric diffusion tensor along ``fibre`` [..., 3] at unit ``directions``
    [P, 3]: 1 / (4 pi sqrt(det D) (u^T D^-1 u)^(3/2)), as dipy.sims.voxel.single_tensor_odf.
    Returns [..., P]."""
    l1, l2, l3 = evals
    if not np.isclose(l2, l3):
        raise DmriError("tensor_odf: only axially symmetric tensors (evals[1] == evals[2])")
    q = np.asarray(fibre, np.float64) @ np.asarray(directions, np.float64).T
    q *= q
    q *= 1 / l1 - 1 / l2
    q += 1 / l2                         # q = u^T D^-1 u = cos^2/l1 + sin^2/l2
    out = np.sqrt(q)
    out *= q
    out *= 4 * math.pi * math.sqrt(l1 * l2 * l3)
    return np.reciprocal(out, out=out)


def _crossing_odfs(directions, fractions, evals, subtract_min):
    """Mixture ODFs [n, P] on the synthesis sphere for fibres [n, k, 3] with fractions [n, k]."""
    xyz, _, _ = fibonacci_sphere(_SYN_SPHERE)
    odf = np.einsum("nk,nkp->np", fractions, tensor_odf(xyz, directions, evals))
    if subtract_min:
        odf -= odf.min(axis=1, keepdims=True)
    return odf, xyz


def _fit_sh_numpy(odf, order):
    """Least-squares SH fit on the synthesis sphere; the same solve as dipy's sf_to_sh(smooth=0)."""
    _, theta, phi = fibonacci_sphere(_SYN_SPHERE)
    return odf @ np.linalg.pinv(sh_matrix(order, theta, phi)).T


def _synthetic_model(nx, ny, seed):
    """Fibre directions [n, 3, 3] and volume fractions [n, 3] of the synthetic phantom."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid((np.arange(nx) + 0.5) / nx, (np.arange(ny) + 0.5) / ny, indexing="ij")
    x, y = x.reshape(-1), y.reshape(-1)
    n = x.size
    # bundle 1, everywhere: arcs around the corner (-0.15, -0.15), in plane
    ax, ay = x + 0.15, y + 0.15
    d1 = np.stack([-ay, ax, np.zeros(n)], axis=1)
    # bundle 2: a straight band, 30 degrees from +y, in plane, centred on the line x + tan(30) y = 0.62
    t = math.radians(30)
    d2 = np.broadcast_to([math.sin(t), math.cos(t), 0.0], (n, 3)).copy()
    dist = (x * math.cos(t) - y * math.sin(t)) - 0.62 * math.cos(t)
    w2 = np.clip(1.2 - np.abs(dist) / 0.12, 0, 1)
    # bundle 3: through the plane (+z, tilted), a disc around (0.72, 0.3)
    d3 = np.broadcast_to([0.25, 0.0, 1.0], (n, 3)).copy()
    w3 = 0.9 * np.clip(1.5 - np.hypot(x - 0.72, y - 0.3) / 0.14, 0, 1)
    dirs = np.stack([d1, d2, d3], axis=1)
    dirs += rng.normal(scale=math.radians(3), size=dirs.shape) * np.linalg.norm(dirs, axis=-1, keepdims=True)
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    w = np.stack([np.ones(n), w2, w3], axis=1)
    return dirs, w / w.sum(axis=1, keepdims=True)


def synthetic_crossing_field(nx: int = 140, ny: int = 140, order: int = 12, seed: int = 0, *,
                             subtract_min: bool = True, progress: bool = False) -> ShField:
    """A synthetic nx x ny field of crossing-fibre ODFs fitted to ``order`` with dipy's sf_to_sh.

    Model (docs/dmri.md): up to three fibre bundles per voxel -- arcs everywhere, a straight band
    crossing them at angles that vary along the band, and a through-plane disc -- each an axially
    symmetric tensor with eigenvalues SYNTHETIC_EVALS; directions jittered by 3 degrees (``seed``).
    The voxel ODF is the fraction-weighted sum of the tensors' ODFs (the formula of
    dipy.sims.voxel.multi_tensor_odf, vectorized), minus its minimum when ``subtract_min`` (the usual
    min-max display normalization), sampled on 900 directions and fitted with
    dipy.reconst.shm.sf_to_sh(basis_type='descoteaux07', legacy=False). Labelled synthetic in
    ``metadata``; ``metadata['directions']`` [n, 3, 3] and ``['fractions']`` [n, 3] hold the truth.
    """
    shm = _dipy()
    from dipy.core.sphere import Sphere

    if order not in SH_ORDERS or order == 0:
        raise DmriError(f"order must be one of {SH_ORDERS[1:]}, got {order!r}")
    if nx < 1 or ny < 1:
        raise DmriError(f"field size must be positive, got {nx} x {ny}")
    dirs, frac = _synthetic_model(nx, ny, seed)
    xyz, _, _ = fibonacci_sphere(_SYN_SPHERE)
    sphere = Sphere(xyz=xyz)
    chunks = range(0, len(dirs), 4096)
    if progress:
        from tqdm import tqdm
        chunks = tqdm(chunks, desc="synthetic ODFs", unit="chunk")
    # sf_to_sh is linear in the samples: its matrix, once, is sf_to_sh of the identity
    fit = shm.sf_to_sh(np.eye(_SYN_SPHERE), sphere, sh_order_max=order, basis_type="descoteaux07", legacy=False)
    parts = []
    for a in chunks:
        odf, _ = _crossing_odfs(dirs[a:a + 4096], frac[a:a + 4096], SYNTHETIC_EVALS, subtract_min)
        parts.append(odf @ fit)
    coeffs = np.concatenate(parts)
    affine = np.eye(4)
    affine[:3, 3] = [-(nx - 1) / 2, -(ny - 1) / 2, 0.0]     # centred on the origin, 1 mm voxels
    ijk = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), [0], indexing="ij"), axis=-1).reshape(-1, 3)
    return ShField(positions=ijk + affine[:3, 3], coeffs=pad_to_order(coeffs), order=order,
                   source_basis="descoteaux07", source_legacy=False, frame="world", affine=affine, ijk=ijk,
                   spacing=1.0,
                   metadata={"synthetic": True, "source": "synthetic",
                             "model": "multi-tensor crossing-fibre ODFs (dipy.sims.voxel formula), sf_to_sh fit",
                             "seed": seed, "nx": nx, "ny": ny, "evals": list(SYNTHETIC_EVALS),
                             "subtract_min": subtract_min, "directions": dirs, "fractions": frac})


def save_synthetic_npz(fld: ShField, path) -> Path:
    """Write a synthetic field compactly: its model (fibre directions, fractions, float32) instead of
    its coefficients; ``load_field_npz`` refits them with numpy (same least squares as sf_to_sh)."""
    if not fld.synthetic or "directions" not in fld.metadata:
        raise DmriError("save_synthetic_npz: the field is not a synthetic_crossing_field")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, kind="synthetic-model", positions=fld.positions.astype(np.float32),
                        directions=fld.metadata["directions"].astype(np.float32),
                        fractions=fld.metadata["fractions"].astype(np.float32), **fld._header())
    return path


# --- command line: ``paramlod glyphs`` ------------------------------------------------------------

def add_subparser(sub):
    g = sub.add_parser("glyphs", help="render the SH glyph field of a NIfTI SH volume (or a field .npz)")
    g.add_argument("path", help="4D NIfTI of SH coefficients (.nii/.nii.gz) or a paramlod field .npz")
    g.add_argument("--basis", choices=BASES, default="descoteaux07",
                   help="the file's SH basis: tournier07 for MRtrix3, descoteaux07 for dipy (default)")
    g.add_argument("--legacy", action="store_true", help="dipy's legacy variant of the basis (MRtrix 0.2, "
                                                         "dipy's Q-ball fits)")
    g.add_argument("--mask", help="a 3D NIfTI mask (non-zero = keep) of the volume's spatial shape")
    g.add_argument("--stride", type=int, default=1, help="keep every stride-th voxel along each axis")
    g.add_argument("--slice", type=int, metavar="K", help="only axial slice K")
    g.add_argument("--color", choices=["direction", "none"], default="direction",
                   help="colour by the largest lobe's direction (default) or plain")
    g.add_argument("--variant", default="points", help="render variant (points, points-ssaa, tess)")
    g.add_argument("--size", default="960x960", help="image size (default 960x960)")
    g.add_argument("-o", "--output", action="append", required=True, help="output .png or .exr (repeatable)")
    g.set_defaults(func=run_glyphs)


def run_glyphs(args) -> int:
    from paramlod.app.cli import _size
    from paramlod.scene.framing import framing_camera
    from paramlod.pipeline.driver import render

    path = Path(args.path)
    if path.suffix == ".npz":
        field = load_field_npz(path)
    else:
        mask = args.mask
        region = (slice(None), slice(None), slice(args.slice, args.slice + 1)) if args.slice is not None else None
        field = load_sh_volume(path, args.basis, mask=mask, stride=args.stride, legacy=args.legacy, region=region)
    scene = field.to_scene(color_by=None if args.color == "none" else "direction")
    size = _size(args.size)
    camera = framing_camera(scene, (0.0, -0.35, 1.0), (0, 1, 0), 40.0, size)
    frame = render(scene, camera, args.variant)
    for out in args.output:
        frame.save(out)
    print(f"{', '.join(args.output)}: {len(field)} glyphs of order {field.order} ({field.source_basis}"
          f"{', legacy' if field.source_legacy else ''}), {frame.stats.get('render_patches', '?')} render patches")
    return 0
