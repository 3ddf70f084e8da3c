"""Scenes: objects (a function, its parameters, a transform and a material), and the flat instance
buffers the kernels read."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import SceneError
from .function import ParametricFunction
from .registry import get_function
from .transforms import matrix as _as_matrix

# Per-instance float record (see kernels/common.cl, INST_* offsets): 4x4 model matrix (row-major),
# 3x4 normal matrix rows, domain (u0, u1, v0, v1), material (r, g, b, specular).
INST_FLOATS = 32
# Per-instance uint record: function index, parameter-block offset, object id, flags.
INST_UINTS = 4
MAX_OBJECTS = 4095  # object ids are carried in 12 bits of the attribute key (docs/frame.md)


@dataclass
class Material:
    color: tuple[float, float, float] = (0.8, 0.8, 0.8)  # linear RGB
    specular: float = 0.25

    def __post_init__(self):
        c = np.asarray(self.color, dtype=np.float64)
        if c.shape != (3,) or not np.all((c >= 0) & (c <= 1)):
            raise SceneError(f"material color must be three numbers in [0, 1], got {self.color!r}")
        if not 0 <= self.specular <= 1:
            raise SceneError(f"material specular must be in [0, 1], got {self.specular!r}")
        self.color = tuple(float(x) for x in c)


@dataclass
class SceneObject:
    function: ParametricFunction
    params: dict
    transform: np.ndarray
    material: Material
    object_id: int
    block: np.ndarray = field(repr=False, default=None)


class Scene:
    def __init__(self, background=(0.12, 0.12, 0.14)):
        self.objects: list[SceneObject] = []
        self.background = tuple(float(x) for x in background)

    def add(self, fn_or_name, params: dict | None = None, transform=None, material: Material | None = None) -> SceneObject:
        fn = get_function(fn_or_name)
        if len(self.objects) >= MAX_OBJECTS:
            raise SceneError(f"a scene holds at most {MAX_OBJECTS} objects (object ids use 12 bits)")
        block = fn.param_block(params)  # validates names, shapes and finiteness
        m = np.eye(4) if transform is None else _as_matrix(transform)
        obj = SceneObject(fn, dict(params or {}), m, material or Material(), len(self.objects) + 1, block)
        self.objects.append(obj)
        return obj

    def functions(self) -> list[ParametricFunction]:
        """Distinct functions in first-use order; their index is the kernel's function id."""
        out: list[ParametricFunction] = []
        for o in self.objects:
            if all(o.function is not f for f in out):
                out.append(o.function)
        return out

    def instance_buffers(self):
        """(inst_f float32 [n, 32], inst_u uint32 [n, 4], params float32 [...]) for the kernels."""
        funcs = self.functions()
        n = len(self.objects)
        inst_f = np.zeros((n, INST_FLOATS), np.float32)
        inst_u = np.zeros((n, INST_UINTS), np.uint32)
        blocks, offset = [], 0
        for i, o in enumerate(self.objects):
            m = o.transform
            nrm = np.linalg.inv(m[:3, :3]).T
            inst_f[i, 0:16] = m.reshape(-1)
            inst_f[i, 16:28] = np.hstack([nrm, np.zeros((3, 1))]).reshape(-1)
            inst_f[i, 28:32] = [*o.function.u_range, *o.function.v_range]
            fidx = next(k for k, f in enumerate(funcs) if f is o.function)
            inst_u[i] = (fidx, offset, o.object_id, 0)
            blocks.append(o.block)
            offset += o.block.size
        params = np.concatenate(blocks + [np.zeros(1, np.float32)]).astype(np.float32)
        return inst_f, inst_u, params

    def materials(self) -> np.ndarray:
        """float32 [n, 4]: linear RGB and specular per instance."""
        return np.array([[*o.material.color, o.material.specular] for o in self.objects], np.float32).reshape(-1, 4)
