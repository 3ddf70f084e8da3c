"""A synthetic crossing-fibre field: the stand-in for the dissertation's HARDI slice (docs/dmri.md,
"The synthetic 140 x 140 field"). ``synthetic_crossing_field`` fits with dipy; ``coeffs_from_model``
refits a stored model with numpy alone (what ``paramlod.dmri.io.load_field_npz`` uses)."""
from __future__ import annotations

import math

import numpy as np

from paramlod.dmri.field import ShField
from paramlod.dmri.sh import SH_ORDERS, fibonacci_sphere, pad_to_order, require_dipy, sh_matrix
from paramlod.errors import DmriError

SYNTHETIC_EVALS = (1.7e-3, 0.3e-3, 0.3e-3)   # mm^2/s, an axially symmetric tensor per fibre
SYNTHESIS_SPHERE = 900                        # directions the ODFs are sampled on before fitting


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
    xyz, _, _ = fibonacci_sphere(SYNTHESIS_SPHERE)
    odf = np.einsum("nk,nkp->np", fractions, tensor_odf(xyz, directions, evals))
    if subtract_min:
        odf -= odf.min(axis=1, keepdims=True)
    return odf, xyz


def _fit_sh_numpy(odf, order):
    """Least-squares SH fit on the synthesis sphere; the same solve as dipy's sf_to_sh(smooth=0)."""
    _, theta, phi = fibonacci_sphere(SYNTHESIS_SPHERE)
    return odf @ np.linalg.pinv(sh_matrix(order, theta, phi)).T


def coeffs_from_model(directions, fractions, order: int, evals=SYNTHETIC_EVALS,
                      subtract_min: bool = True) -> np.ndarray:
    """Canonical coefficients [n, order's count] of the mixture ODFs of fibres ``directions``
    [n, k, 3] with volume ``fractions`` [n, k], fitted with numpy (no dipy): the field a synthetic
    model file describes, agreeing with the sf_to_sh fit to about 1e-6 relative."""
    odf, _ = _crossing_odfs(np.asarray(directions, np.float64), np.asarray(fractions, np.float64),
                            tuple(evals), bool(subtract_min))
    return _fit_sh_numpy(odf, order)


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
    shm = require_dipy()
    from dipy.core.sphere import Sphere

    if order not in SH_ORDERS or order == 0:
        raise DmriError(f"order must be one of {SH_ORDERS[1:]}, got {order!r}")
    if nx < 1 or ny < 1:
        raise DmriError(f"field size must be positive, got {nx} x {ny}")
    dirs, frac = _synthetic_model(nx, ny, seed)
    xyz, _, _ = fibonacci_sphere(SYNTHESIS_SPHERE)
    sphere = Sphere(xyz=xyz)
    chunks = range(0, len(dirs), 4096)
    if progress:
        from tqdm import tqdm
        chunks = tqdm(chunks, desc="synthetic ODFs", unit="chunk")
    # sf_to_sh is linear in the samples: its matrix, once, is sf_to_sh of the identity
    fit = shm.sf_to_sh(np.eye(SYNTHESIS_SPHERE), sphere, sh_order_max=order, basis_type="descoteaux07", legacy=False)
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
