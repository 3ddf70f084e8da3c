"""numpy twin of the linear blend skinning kernel (kernels/meshlod/skin.cl, driven by
paramlod.meshlod.skin): the same float32 operations in the same order, so posed positions and
normals agree with the device's bit for bit (tests/meshlod/test_skin.py).

Per vertex: B = ((w0 M[j0] + w1 M[j1]) + w2 M[j2]) + w3 M[j3] (rows 0..2 of the frame's float32
skin matrices), position = B (x, y, z, 1), normal = normalize(sign(det A) cof(A) n) with A = B's
3x3 (the cofactor matrix is det(A) A^-T: exact for the blended matrix's non-uniform scale and shear,
and no division by the determinant). A zero normal comes out as +z.

Also the host's half shared with the driver: ``skin_records`` turns a rig's float64 skin matrices
into the float32 records the kernel (and the skinned cull, paramlod.meshlod.skin_cull) reads.
"""
from __future__ import annotations

import numpy as np

from paramlod.errors import MeshError


def skin_records(matrices) -> np.ndarray:
    """float32 [J, 4, 4] row-major skin matrices (the kernel reads rows 0..2), from float [J, 4, 4];
    MeshError when one does not fit float32."""
    m = np.asarray(matrices, np.float64)
    if m.ndim != 3 or m.shape[1:] != (4, 4):
        raise MeshError(f"skin matrices must be [J, 4, 4], got {m.shape}")
    if not np.isfinite(m).all() or np.abs(m).max(initial=0) > np.finfo(np.float32).max:
        raise MeshError("skin matrices must be finite and within float32 range (a joint is posed at infinity)")
    return np.ascontiguousarray(m, np.float32)


def skin(bind_v, bind_n, joints, weights, records) -> tuple[np.ndarray, np.ndarray]:
    """(positions float32 [V, 4] with w = 1, normals float32 [V, 4] with w = 0) of the bind pose
    ``bind_v`` / ``bind_n`` (float32 [V, 3] or [V, 4]), ``joints`` uint [V, 4], ``weights`` float32
    [V, 4] and ``records`` float32 [J, 4, 4] (skin_records)."""
    f = np.float32
    v = np.asarray(bind_v, f)[:, :3]
    n = np.asarray(bind_n, f)[:, :3]
    w = np.asarray(weights, f)
    m = np.asarray(records, f).reshape(-1, 16)[:, :12]
    j = np.asarray(joints, np.int64)
    b = ((w[:, 0:1] * m[j[:, 0]] + w[:, 1:2] * m[j[:, 1]]) + w[:, 2:3] * m[j[:, 2]]) + w[:, 3:4] * m[j[:, 3]]
    b = [b[:, k] for k in range(12)]
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    out_v = np.ones((len(v), 4), f)
    out_v[:, 0] = ((b[0] * x + b[1] * y) + b[2] * z) + b[3]
    out_v[:, 1] = ((b[4] * x + b[5] * y) + b[6] * z) + b[7]
    out_v[:, 2] = ((b[8] * x + b[9] * y) + b[10] * z) + b[11]
    c00, c01, c02 = b[5] * b[10] - b[6] * b[9], b[6] * b[8] - b[4] * b[10], b[4] * b[9] - b[5] * b[8]
    c10, c11, c12 = b[2] * b[9] - b[1] * b[10], b[0] * b[10] - b[2] * b[8], b[1] * b[8] - b[0] * b[9]
    c20, c21, c22 = b[1] * b[6] - b[2] * b[5], b[2] * b[4] - b[0] * b[6], b[0] * b[5] - b[1] * b[4]
    det = (b[0] * c00 + b[1] * c01) + b[2] * c02
    sg = np.where(det < 0, f(-1), f(1)).astype(f)
    nx, ny, nz = n[:, 0], n[:, 1], n[:, 2]
    ox = sg * ((c00 * nx + c01 * ny) + c02 * nz)
    oy = sg * ((c10 * nx + c11 * ny) + c12 * nz)
    oz = sg * ((c20 * nx + c21 * ny) + c22 * nz)
    ln = np.sqrt((ox * ox + oy * oy) + oz * oz)
    ok = ln > 0
    safe = np.where(ok, ln, f(1)).astype(f)
    out_n = np.zeros((len(v), 4), f)
    out_n[:, 0] = np.where(ok, ox / safe, f(0))
    out_n[:, 1] = np.where(ok, oy / safe, f(0))
    out_n[:, 2] = np.where(ok, oz / safe, f(1))
    return out_v, out_n
