"""OpenCL programs that include the generated code of parametric functions (built by
``paramlod.device.programs``, which caches them)."""
from __future__ import annotations

from paramlod.device import programs
from paramlod.function.codegen_cl import cl_dispatch_source


def _generated(functions) -> tuple[str, str]:
    functions = list(functions)
    if not functions:
        return "", "none"
    return cl_dispatch_source(functions), ", ".join(f"'{f.name}' ({f.source})" for f in functions)


def build(files: list[str], functions=(), defines: dict | None = None, options: tuple = ()):
    """Compile common.cl + the functions' generated code + ``files`` (paths in kernels/)."""
    generated, describe = _generated(functions)
    return programs.build(files, defines, options, generated, describe)


def kernel(name: str, files: list[str], functions=(), defines: dict | None = None, options: tuple = ()):
    """A kernel object of ``build(files, functions, defines, options)``, retrieved once and reused."""
    generated, describe = _generated(functions)
    return programs.kernel(name, files, defines, options, generated, describe)
