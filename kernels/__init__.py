"""OpenCL C and GLSL sources (package data), loaded with importlib.resources."""
from importlib.resources import files


def source(name: str) -> str:
    """The text of kernel file ``name`` (for example ``"lod.cl"``)."""
    return files(__name__).joinpath(name).read_text(encoding="utf-8")
