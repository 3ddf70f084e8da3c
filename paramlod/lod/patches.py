"""numpy mirrors of the patch records in kernels/common.cl."""
import numpy as np

EVAL_DTYPE = np.dtype([("range", "<f4", 4), ("inst", "<u4"), ("pad", "<u4", 3)])
RENDER_DTYPE = np.dtype([("range", "<f4", 4), ("bbox", "<f4", 4), ("ext", "<f4", 4),
                         ("inst", "<u4"), ("flags", "<u4"), ("pad", "<u4", 2)])
FLAG_FORCED = 16
assert EVAL_DTYPE.itemsize == 32 and RENDER_DTYPE.itemsize == 64


def initial_patches(domains: np.ndarray, grid=(1, 1)) -> np.ndarray:
    """PATCH INITIALIZATION: one patch per instance, optionally a uniform grid (gu x gv) of them.

    ``domains`` is float32 [n, 4] (u0, u1, v0, v1).
    """
    gu, gv = (int(g) for g in grid)
    n = len(domains)
    d = np.asarray(domains, np.float32)
    fu = (np.arange(gu + 1, dtype=np.float32) / np.float32(gu))
    fv = (np.arange(gv + 1, dtype=np.float32) / np.float32(gv))
    out = np.zeros(n * gu * gv, EVAL_DTYPE)
    du, dv = d[:, 1] - d[:, 0], d[:, 3] - d[:, 2]
    k = 0
    for j in range(gv):
        for i in range(gu):
            sl = slice(k * n, (k + 1) * n)
            u_hi = d[:, 1] if i == gu - 1 else d[:, 0] + du * fu[i + 1]
            v_hi = d[:, 3] if j == gv - 1 else d[:, 2] + dv * fv[j + 1]
            out["range"][sl] = np.stack([d[:, 0] + du * fu[i], u_hi, d[:, 2] + dv * fv[j], v_hi], axis=1)
            out["inst"][sl] = np.arange(n, dtype=np.uint32)
            k += 1
    return out


def sort_key(patches: np.ndarray) -> np.ndarray:
    """Order-independent view of a patch list (for comparing GPU output with the reference)."""
    r = patches["range"]
    return np.lexsort((r[:, 3], r[:, 2], r[:, 1], r[:, 0], patches["inst"]))
