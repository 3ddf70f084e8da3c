"""Reading and writing SH fields: 4D NIfTI volumes of SH coefficients (MRtrix3, MRtrix 0.2, dipy;
needs the ``dmri`` extra) and paramlod's own ``.npz`` field files (numpy and scipy only).

``ShField.save_npz`` writes a field's coefficients and ``save_synthetic_npz`` a synthetic field's
model; ``load_field_npz`` reads both. The NIfTI helpers (``load_nifti``, ``read_data``,
``mask_array``, ``neighbour_spacing``) are shared with ``paramlod.dmri.fit``.
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from paramlod.dmri.field import ShField
from paramlod.dmri.sh import (MAX_ORDER, allowed_counts, check_basis, coefficient_count, order_for_count,
                              pad_to_order, require_dipy, to_canonical)
from paramlod.dmri.synthetic import coeffs_from_model
from paramlod.errors import DmriError


# --- paramlod's .npz field files ---------------------------------------------------------------------

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
        coeffs = coeffs_from_model(d["directions"], d["fractions"], order, meta["evals"], meta["subtract_min"])
        return ShField(positions=d["positions"].astype(np.float64), coeffs=pad_to_order(coeffs), **common)
    raise DmriError(f"{path}: unknown field kind {kind!r}")


def save_synthetic_npz(fld: ShField, path) -> Path:
    """Write a synthetic field compactly: its model (fibre directions, fractions, float32) instead of
    its coefficients; ``load_field_npz`` refits them with numpy (same least squares as sf_to_sh)."""
    if not fld.synthetic or "directions" not in fld.metadata:
        raise DmriError("save_synthetic_npz: the field is not a synthetic_crossing_field")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, kind="synthetic-model", positions=fld.positions.astype(np.float32),
                        directions=fld.metadata["directions"].astype(np.float32),
                        fractions=fld.metadata["fractions"].astype(np.float32), **fld.npz_header())
    return path


# --- NIfTI SH volumes ------------------------------------------------------------------------------

def load_nifti(path: Path):
    """The NIfTI image at ``path`` (header read, data not yet), or a DmriError saying why not."""
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


def read_data(img, path: Path, index) -> np.ndarray:
    """``img``'s data at ``index`` as float64; a truncated or corrupt file is a DmriError naming ``path``."""
    try:
        return np.asarray(img.dataobj[index], dtype=np.float64)
    except Exception as e:  # noqa: BLE001 - truncated/corrupt data reads fail in many ways
        raise DmriError(f"{path}: the image data cannot be read; the file is truncated or corrupt "
                        f"({type(e).__name__}: {e})") from None


def neighbour_spacing(affine: np.ndarray, step) -> float:
    """Smallest world distance between a voxel centre and its 26 neighbours (with ``step``)."""
    lin = affine[:3, :3] * np.broadcast_to(np.asarray(step, np.float64), (3,))[None, :]
    offs = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)])
    return float(np.linalg.norm(offs @ lin.T, axis=1).min())


def mask_array(mask, shape, path_for_msg) -> np.ndarray:
    """A boolean mask of ``shape`` from None (all), an array or a NIfTI path; a wrong shape is a DmriError."""
    if mask is None:
        return np.ones(shape, bool)
    if isinstance(mask, (str, Path)):
        mpath = Path(mask)
        img = load_nifti(mpath)
        m = read_data(img, mpath, ...)
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
    check_basis(basis)
    require_dipy()
    path = Path(path)
    img = load_nifti(path)
    shape = tuple(int(s) for s in img.shape)
    if len(shape) == 5 and shape[3] == 1:       # NIfTI's (x, y, z, t=1, vector) layout
        shape = shape[:3] + shape[4:]
        squeeze = True
    else:
        squeeze = False
    if len(shape) == 3:
        raise DmriError(f"{path}: is a 3D volume {shape}; an SH volume needs a 4th dimension holding the "
                        f"coefficients, of size {allowed_counts()}")
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
                        f"count{hint}; allowed sizes: {allowed_counts()}")
    step = np.broadcast_to(np.asarray(stride), (3,)).astype(int)
    if np.any(step < 1):
        raise DmriError(f"stride must be a positive integer (or 3), got {stride!r}")
    region = tuple(region) if region is not None else (slice(None),) * 3
    if len(region) != 3 or not all(isinstance(s, slice) for s in region):
        raise DmriError(f"region must be a tuple of 3 slices, got {region!r}")
    grids = [np.arange(shape[a])[region[a]][::step[a]] for a in range(3)]
    if any(len(g) == 0 for g in grids):
        raise DmriError(f"{path}: region {region} with stride {tuple(step)} selects no voxels of {shape[:3]}")
    full_mask = mask_array(mask, shape[:3], path)
    sub = tuple(slice(g[0], g[-1] + 1, step[a]) for a, g in enumerate(grids))
    index = sub[:3] + ((0, slice(None)) if squeeze else (slice(None),))
    data = read_data(img, path, index)
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
                   frame=frame, affine=affine, ijk=ijk, spacing=neighbour_spacing(affine, step),
                   metadata={"source": str(path), "synthetic": False, "dropped_nonfinite": n_nonfinite,
                             "dropped_empty": n_empty, "stride": ",".join(map(str, step))})
