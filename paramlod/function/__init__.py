"""Parametric functions: definition, code generation (OpenCL, GLSL), registry and plugins.

Modules, bottom up: ``bindings`` (the binding stack of ``dsl.let``), ``define`` (ParametricFunction,
Part, @parametric), ``codegen_cl`` / ``codegen_glsl``, ``programs`` (OpenCL programs with generated
code), ``plugins`` (loading and load-time checks), ``registry`` (functions by name), ``probes``
(the generated GLSL evaluated on the GL device).
"""
from paramlod.function import registry
from paramlod.function.define import ParametricFunction, Part, PlacedPart, evaluate, parametric, set_name_lookup
from paramlod.function.registry import add_plugin_path, all_functions, describe_functions, get_function

# A Part (and ``evaluate``) may name a function; ``define`` finds it through the registry, which
# sits above it, so the two are connected here instead of by an import in ``define``. The lambda
# looks ``registry.get_function`` up at each call (tests replace it with monkeypatch).
set_name_lookup(lambda name: registry.get_function(name))

__all__ = [
    "ParametricFunction", "Part", "PlacedPart", "evaluate", "parametric",
    "add_plugin_path", "all_functions", "describe_functions", "get_function",
]
