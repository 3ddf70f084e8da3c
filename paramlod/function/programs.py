"""OpenCL programs that include the generated code of parametric functions (built by
``paramlod.device.programs``, which caches them)."""
from __future__ import annotations

from paramlod import kernels
from paramlod.device import programs
from paramlod.function.codegen_cl import cl_dispatch_source
from paramlod.function.codegen_vector import cl_vector_source

POLY_TRIG = "PL_POLY_TRIG"   # a define: the generated code's sin, cos and sincos inline (kernels/common/poly_trig.cl)
# samples (or grid vertices) a work-item visits down a grid line of a split function, the split's
# steps evaluated once a run (the point sampler's PL_RUN, the grid tessellator's): runs on CPU
# devices; one on GPUs, whose frames runs made slower (docs/points.md, "The surface split")
RUN_GPU, RUN_CPU = 1, 16
VECTOR = "PL_VECTOR"   # a define: the generated code on vector lanes too (paramlod.function.codegen_vector)


def sample_run(is_gpu: bool) -> int:
    """RUN_GPU or RUN_CPU for a device."""
    return RUN_GPU if is_gpu else RUN_CPU


def _generated(functions, defines: dict | None) -> tuple[str, str]:
    functions = list(functions)
    if not functions:
        return "", "none"
    source = cl_dispatch_source(functions)
    if VECTOR in (defines or {}):
        source += "\n" + cl_vector_source(functions)
    return source, ", ".join(f"'{f.name}' ({f.source})" for f in functions)


def _with_trig(generated: str, defines: dict | None) -> str:
    """``generated`` with inline sin, cos and sincos where ``defines`` holds POLY_TRIG."""
    if not generated or POLY_TRIG not in (defines or {}):
        return generated
    restore = [f"#undef {name}\n#pragma pop_macro(\"{name}\")" for name in ("sincos", "sin", "cos")]
    return "\n".join([kernels.source("common/poly_trig.cl"), generated, *restore])


def build(files: list[str], functions=(), defines: dict | None = None, options: tuple = ()):
    """Compile common.cl + the functions' generated code + ``files`` (paths in kernels/)."""
    generated, describe = _generated(functions, defines)
    return programs.build(files, defines, options, _with_trig(generated, defines), describe)


def kernel(name: str, files: list[str], functions=(), defines: dict | None = None, options: tuple = ()):
    """A kernel object of ``build(files, functions, defines, options)``, retrieved once and reused."""
    generated, describe = _generated(functions, defines)
    return programs.kernel(name, files, defines, options, _with_trig(generated, defines), describe)
