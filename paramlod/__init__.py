"""paramlod: parametric objects and surfels rendered with per-frame level of detail."""
from .errors import CapacityError, DeviceError, FunctionError, ParamlodError, SceneError
from .function import ParametricFunction, Part, evaluate, parametric
from . import dsl
from .camera import Camera
from .scene import Material, Scene
from .transforms import matrix, rotate, scale, translate
from .frame import Frame
from .lod import LodSettings
from .points import PointSettings
from .points_lfb import SsaaSettings
from .tess import TessSettings
from .render import RenderSettings, render

__all__ = [
    "CapacityError", "DeviceError", "FunctionError", "ParamlodError", "SceneError",
    "ParametricFunction", "Part", "dsl", "evaluate", "parametric", "Camera", "Material", "Scene",
    "matrix", "rotate", "scale", "translate", "Frame", "LodSettings", "PointSettings",
    "SsaaSettings", "TessSettings", "RenderSettings", "render",
]
