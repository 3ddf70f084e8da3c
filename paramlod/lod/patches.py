"""The LOD stage's patch records on the host (declared in paramlod.core.layouts: EVAL_PATCH,
RENDER_PATCH, the EvalPatch and RenderPatch structs of the kernels' prelude)."""
import numpy as np

from paramlod.core.layouts import EVAL_PATCH, RENDER_PATCH

EVAL_DTYPE = EVAL_PATCH.dtype       # 32 bytes: range, inst, pad
RENDER_DTYPE = RENDER_PATCH.dtype   # 64 bytes: range, bbox, ext, inst, flags, pad
FLAG_FORCED = RENDER_PATCH.constant("FLAG_FORCED")   # RenderPatch.flags bit: forced out at the last step
TIER_SHIFT = RENDER_PATCH.constant("TIER_SHIFT")     # RenderPatch.flags >> TIER_SHIFT & 3: the hybrid tier


def render_tiers(render_list: np.ndarray) -> np.ndarray:
    """The hybrid anti-aliasing tier of each render patch (0, 1, 2; 0 without hybrid)."""
    return (render_list["flags"] >> np.uint32(TIER_SHIFT)) & np.uint32(3)


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
