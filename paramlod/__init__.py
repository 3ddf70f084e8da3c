"""paramlod: parametric objects and surfels rendered with per-frame level of detail."""
from paramlod.errors import CapacityError, DeviceError, FunctionError, ParamlodError, SceneError
from paramlod.function.define import ParametricFunction, Part, evaluate, parametric
from paramlod import dsl
from paramlod.core.camera import Camera
from paramlod.scene.scene import Material, Scene
from paramlod.core.transforms import matrix, rotate, scale, translate
from paramlod.core.frame import Frame
from paramlod.lod.stage import LodSettings
from paramlod.renderers.points import PointSettings
from paramlod.renderers.points_lfb import SsaaSettings
from paramlod.renderers.tess import TessSettings
from paramlod.pipeline.driver import RenderSettings, render

__all__ = [
    "CapacityError", "DeviceError", "FunctionError", "ParamlodError", "SceneError",
    "ParametricFunction", "Part", "dsl", "evaluate", "parametric", "Camera", "Material", "Scene",
    "matrix", "rotate", "scale", "translate", "Frame", "LodSettings", "PointSettings",
    "SsaaSettings", "TessSettings", "RenderSettings", "render",
]
