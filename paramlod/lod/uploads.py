"""Device copies of a scene's parametric instance buffers and of each frame's camera records:
what the LOD stage and the parametric renderers read (per scene; re-sent only when the scene or
its time changed). A multi-view frame (a ``paramlod.core.views.Views``) sends one camera record
per view, one after another.

The instance uints sent carry the LOD stage's per-instance flags (INST_U ``flags``): bit 0
(``ONE_SIDED``) lets the stage cull the instance's back-facing patches (kernels/lod/lod.cl). It is
set for the instances of objects whose material says ``two_sided = False``, when their function
is smooth (``smooth_function``: the normal cone's bound assumes partials that do not jump);
materials are two-sided by default, so by default nothing is ever culled as back-facing. Bits 1
and 2 (``WRAP_U``, ``WRAP_V``) mark the axes over which the instance's function repeats (its
``periodic``): the point renderers skip the repeated last line of a grid that spans the domain
there (kernels/points/points.cl ``grid_axis``)."""
from __future__ import annotations

import warnings

import numpy as np
import pyopencl as cl
import sympy as sp
import pyopencl.array as cla

from paramlod.core.layouts import INSTANCE_U
from paramlod.core.views import as_views
from paramlod.device.context import cl_device

ONE_SIDED = np.uint32(INSTANCE_U.constant("INST_ONE_SIDED"))   # kernels/lod/lod.cl
WRAP_U = np.uint32(INSTANCE_U.constant("INST_WRAP_U"))          # kernels/points/points.cl
WRAP_V = np.uint32(INSTANCE_U.constant("INST_WRAP_V"))


# operations whose result or partials jump or kink: no Lipschitz bound of the partials can be read
# from samples across them (palm_trunk's sawtooth rings, the hearts' abs)
_NOT_SMOOTH = (sp.Piecewise, sp.Abs, sp.floor, sp.ceiling, sp.frac, sp.Min, sp.Max, sp.sign,
               sp.Heaviside, sp.Mod)


def smooth_function(fn) -> bool:
    """Whether the LOD stage may bound ``fn``'s normals from samples (docs/lod.md, "Back-face
    culling"): a sympy-defined function without operations that jump or kink (a snippet's body
    cannot be inspected: not smooth)."""
    if fn.exprs is None:
        return False
    for e in (*fn.exprs, *(b for _, b in fn.bindings)):
        if e.has(*_NOT_SMOOTH):
            return False
    return True


WRAP_CHECKED_BLOCKS = 1024   # distinct parameter blocks per function whose periodic edges are checked


def wrap_flags(scene, inst_u, params) -> np.ndarray:
    """WRAP_U / WRAP_V per instance: its function's periodic axes where the edges meet for the
    scene's parameter values (``ParametricFunction.edges_meet``, on up to WRAP_CHECKED_BLOCKS of
    the function's distinct parameter blocks, evenly picked). An axis that fails for one is
    dropped for all the function's instances, with a warning: their grids keep the seam's line.
    SceneBuffers checks when the scene changes, at its time then, not at every frame of an animation."""
    func = inst_u[:, INSTANCE_U.offset("func")]
    offsets = inst_u[:, INSTANCE_U.offset("params")].astype(np.int64)
    out = np.zeros(len(inst_u), np.uint32)
    for i, f in enumerate(scene.functions()):
        mine = func == i
        if not f.periodic or not mine.any():
            continue
        distinct = np.unique(offsets[mine])
        picked = distinct[np.linspace(0, len(distinct) - 1, min(len(distinct), WRAP_CHECKED_BLOCKS)).astype(np.int64)]
        blocks = np.asarray(params, np.float32)[picked[:, None] + np.arange(f.param_count)]
        for axis, bit in (("u", WRAP_U), ("v", WRAP_V)):
            if axis not in f.periodic:
                continue
            meet = f.edges_meet(axis, blocks)
            if meet.all():
                out[mine] |= bit
                continue
            values, defaults = f.param_values(blocks[int(np.argmin(meet))]), f.param_values(f.param_block())
            changed = {k: v for k, v in values.items() if not np.array_equal(v, defaults[k])}
            warnings.warn(f"'{f.name}' is declared periodic in {axis}, but its edges there do not meet with the "
                          f"parameters {changed or values}: its point grids keep their seam lines", stacklevel=3)
    return out


def instance_flags(scene, inst_u, wraps) -> np.ndarray:
    """``inst_u`` (uint32 [n, INST_U]) with the per-instance flags set (a copy): ONE_SIDED for the
    instances (parts included) of objects whose material has ``two_sided`` False, where the
    instance's function is smooth; ``wraps``, the WRAP_U / WRAP_V bits (``wrap_flags``)."""
    one_sided = [o.object_id for o in scene.objects if not o.material.two_sided]
    out = np.array(inst_u, np.uint32, copy=True)
    if len(out):
        out[:, INSTANCE_U.offset("flags")] |= wraps
    if one_sided and len(out):
        functions = scene.functions()
        smooth = np.array([smooth_function(f) for f in functions], bool)
        sel = np.isin(out[:, INSTANCE_U.offset("object")], np.asarray(one_sided, np.uint32))
        rough = np.unique(out[sel & ~smooth[out[:, INSTANCE_U.offset("func")]], INSTANCE_U.offset("func")])
        if len(rough):   # the user asked for culling that cannot be done safely: say so once per upload
            names = ", ".join(sorted(functions[i].name for i in rough))
            warnings.warn(f"two_sided = false has no effect on {names}: back faces are culled only for "
                          "functions without Piecewise, Abs, floor, frac, Min, Max and the like, written in "
                          "sympy (docs/lod.md, 'Back-face culling')", stacklevel=2)
        sel &= smooth[out[:, INSTANCE_U.offset("func")]]
        out[sel, INSTANCE_U.offset("flags")] |= ONE_SIDED
    return out


class SceneBuffers:
    def __init__(self, light):
        self.light = light            # the shading record (paramlod.renderers.shading.LIGHT)
        self._key, self._dev = None, None
        self._wraps = (None, None)   # (scene version, wrap_flags): checked again when the scene changes
        self._cams: dict = {}   # slot -> (device buffer, host records, copy event)

    def upload(self, scene, camera) -> dict:
        """{"inst": (floats, uints, params), "materials", "light", "domains", "flags" and
        "one_sided" (host: the instances' domains and INST_U flags, whether one has ONE_SIDED),
        "cam" (the camera records), "n_views"}; ``camera``: a Camera or a Views."""
        q = cl_device().queue
        key = (scene._version, scene.time)
        if key != self._key:
            inst_f, inst_u, params = scene.instance_buffers()
            if self._wraps[0] != scene._version:   # not at every new time of an animation
                self._wraps = (scene._version, wrap_flags(scene, inst_u, params))
            inst_u = instance_flags(scene, inst_u, self._wraps[1])
            flags = inst_u[:, INSTANCE_U.offset("flags")]
            self._dev = {
                "inst": tuple(cla.to_device(q, a).data for a in (inst_f, inst_u, params)),
                "materials": cla.to_device(q, scene.materials()).data,
                "light": cla.to_device(q, self.light).data,
                "domains": inst_f[:, 28:32],
                "flags": flags,   # host copies, for the numpy twins
                "one_sided": bool((flags & ONE_SIDED).any()),   # the LOD stage's back-face test (LodStage.enqueue)
            }
            self._key = key
        return dict(self._dev, cam=self.camera(camera), n_views=len(as_views(camera)))

    def camera(self, camera, slot: int = 0) -> cl.Buffer:
        """The device copy of ``camera``'s records (a Camera or a Views) in buffer ``slot`` (0: the
        frame's; others: the same views at another target size, as a hybrid tier draws them)."""
        records = as_views(camera).records()
        buf = self._cams.get(slot, (None,))[0]
        if buf is None or buf.size < records.nbytes:
            buf = cl.Buffer(cl_device().context, cl.mem_flags.READ_ONLY, records.nbytes)
        # not waited for: every frame ends with a wait, so the host copy is free to change then
        # the event is kept with the host copy: a dropped event of a non-blocking copy makes
        # pyopencl wait for it (measured 585 ms behind a running kernel)
        self._cams[slot] = (buf, records, cl.enqueue_copy(cl_device().queue, buf, records, is_blocking=False))
        return buf
