"""Errors paramlod raises for user mistakes. The CLI prints these without a traceback."""


class ParamlodError(Exception):
    """Base class: a problem the user can fix, with a message that says what and where."""


class FunctionError(ParamlodError):
    """A parametric function (plugin) is malformed or called with bad parameters."""


class DeviceError(ParamlodError):
    """No usable OpenCL or OpenGL device."""


class SceneError(ParamlodError):
    """A scene, camera or scene file is invalid."""


class CapacityError(ParamlodError):
    """A buffer limit was reached; the message names the limit and how to raise it."""


class SurfelError(ParamlodError):
    """A mesh, scene, sampling parameter or .surfels file that cannot be used for surfels."""


class DmriError(ParamlodError):
    """A diffusion-MRI input (file, basis, mask, field) is unusable; the message names it and why."""


class MeshError(ParamlodError):
    """A mesh file, array or LOD build that cannot be used; the message names it and why."""
