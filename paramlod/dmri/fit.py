"""Fitting diffusion data with dipy: the constant-solid-angle Q-ball model (``fit_csa_odf``), its ODF
field converted from dipy's legacy descoteaux07 to the canonical basis. Needs the ``dmri`` extra."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from paramlod.dmri.field import ShField
from paramlod.dmri.io import load_nifti, mask_array, neighbour_spacing, read_data
from paramlod.dmri.sh import SH_ORDERS, coefficient_count, pad_to_order, require_dipy, to_canonical
from paramlod.errors import DmriError


def fit_csa_odf(dwi="small_64D", bvals=None, bvecs=None, order: int = 8, mask=None, *, affine=None,
                smooth: float = 0.006) -> ShField:
    """Fit dipy's constant-solid-angle Q-ball model (CsaOdfModel) and return its ODF field.

    ``dwi``: 'small_64D' (dipy's bundled 10x10x10 scan, 64 directions; the default), a NIfTI path
    (then ``bvals``/``bvecs`` are FSL-style text files or arrays), or a 4D array (then ``affine``
    too). ``mask``: boolean array of the spatial shape; by default voxels whose mean b0 signal is
    positive. dipy's Q-ball models fit in the *legacy* descoteaux07 basis; the coefficients are
    converted to the canonical non-legacy basis here.
    """
    shm = require_dipy()
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
        img = load_nifti(Path(dwi))
        data = read_data(img, Path(dwi), ...)
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
    m = (b0 > 0) if mask is None else mask_array(mask, data.shape[:3], label)
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
                   ijk=ijk, spacing=neighbour_spacing(affine, 1),
                   metadata={"source": label, "synthetic": False, "model": f"dipy CsaOdfModel order {order}",
                             "smooth": smooth})
