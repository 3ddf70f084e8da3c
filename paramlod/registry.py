"""Where functions come from: the built-ins in ``paramlod.functions`` (one module each).

Lookup is by name; a ParametricFunction object passes through unchanged.
"""
from __future__ import annotations

import importlib
import pkgutil
from functools import lru_cache

from .errors import FunctionError
from .function import ParametricFunction


@lru_cache(maxsize=1)
def builtin_functions() -> dict[str, ParametricFunction]:
    import paramlod.functions as pkg

    found: dict[str, ParametricFunction] = {}
    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{pkg.__name__}.{info.name}")
        for obj in vars(module).values():
            if isinstance(obj, ParametricFunction):
                if obj.name in found and found[obj.name] is not obj:
                    raise FunctionError(
                        f"two built-in functions are named '{obj.name}': "
                        f"{found[obj.name].source} and {obj.source}")
                found[obj.name] = obj
    return found


def all_functions() -> dict[str, ParametricFunction]:
    return dict(builtin_functions())


def get_function(fn_or_name) -> ParametricFunction:
    if isinstance(fn_or_name, ParametricFunction):
        return fn_or_name
    if not isinstance(fn_or_name, str):
        raise FunctionError(f"expected a function name or a @parametric function, got {fn_or_name!r}")
    funcs = all_functions()
    try:
        return funcs[fn_or_name]
    except KeyError:
        import difflib

        close = difflib.get_close_matches(fn_or_name, funcs, n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise FunctionError(
            f"unknown function '{fn_or_name}' (known: {', '.join(sorted(funcs))}){hint}") from None
