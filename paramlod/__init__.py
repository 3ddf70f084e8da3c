"""paramlod: parametric objects, meshes and surfels rendered with per-frame level of detail."""
from paramlod import dsl, meshlod, surfels, views  # noqa: F401  (meshlod and surfels register their object kinds and renderers)
from paramlod.core.camera import Camera
from paramlod.core.frame import Frame, FrameStats
from paramlod.core.transforms import matrix, rotate, scale, translate
from paramlod.errors import CapacityError, DeviceError, FunctionError, ParamlodError, SceneError
from paramlod.function.define import ParametricFunction, Part, evaluate, parametric
from paramlod.function.registry import register_builder
from paramlod.lod.stage import LodSettings
from paramlod.meshlod import MeshLod, MeshSettings, SkinnedMesh, load_mesh, load_skinned
from paramlod.pipeline.driver import render, render_on_device, render_views
from paramlod.pipeline.settings import RenderSettings
from paramlod.renderers.points_lfb import SsaaSettings
from paramlod.renderers.registry import variants
from paramlod.renderers.sampling import PointSettings
from paramlod.renderers.tess import TessSettings
from paramlod.scene.scene import Material, Scene
from paramlod.viewer.notebook import show

__all__ = [
    "CapacityError", "DeviceError", "FunctionError", "ParamlodError", "SceneError",
    "ParametricFunction", "Part", "dsl", "evaluate", "parametric", "Camera", "Material", "Scene",
    "matrix", "rotate", "scale", "translate", "Frame", "FrameStats", "LodSettings", "PointSettings",
    "SsaaSettings", "TessSettings", "RenderSettings", "render", "render_on_device", "render_views", "views", "variants",
    "MeshLod", "MeshSettings", "load_mesh", "SkinnedMesh", "load_skinned", "register_builder", "show",
]
