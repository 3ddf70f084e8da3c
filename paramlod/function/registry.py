"""Where functions come from, by name: the built-ins in ``paramlod.functions`` (one module each),
the ``paramlod.functions`` entry points of installed distributions, and plugin folders given with
``add_plugin_path(dir)`` (the CLI's ``--functions DIR``) or ``PARAMLOD_FUNCTIONS_PATH``
(folders separated by ``:``).

Two functions with one name are an error that names both sources. A ParametricFunction object
passes through ``get_function`` unchanged. Loading (and the compile check of plugins) happens once
per source; ``refresh()`` forgets everything loaded from plugins.

Instance builders (what a scene file's ``instances = { builder = "..." }`` names) are registered
here too, by name: ``register_builder(name, fn)``, or a built-in module's ``BUILDERS = {"f": f}``
(registered as ``"paramlod.functions.<module>:f"``). A scene file is data: it may name only a
registered builder (``get_builder``), never an arbitrary importable callable.
"""
from __future__ import annotations

import difflib
import importlib
import os
import pkgutil
import sys
from functools import lru_cache
from pathlib import Path

from paramlod.errors import FunctionError
from paramlod.function.define import ParametricFunction, built_in_definitions
from paramlod.function.plugins import load_entry_points, load_plugin_folder, validate

ENV_VAR = "PARAMLOD_FUNCTIONS_PATH"
BUILTIN_PACKAGE = "paramlod.functions"   # the built-in plugins: loaded as data, by name, on first use

_plugin_paths: list[Path] = []                          # from add_plugin_path, in call order
_folder_cache: dict[Path, list[ParametricFunction]] = {}
_entry_point_cache: dict[tuple, list[ParametricFunction]] = {}
_builders: dict[str, object] = {}                       # name -> callable returning instance arrays


@lru_cache(maxsize=1)
def builtin_functions() -> dict[str, ParametricFunction]:
    # imported by name, not with an import statement: plugins use the public API (``paramlod``),
    # which is only complete once this room has been imported
    pkg = importlib.import_module(BUILTIN_PACKAGE)
    found: dict[str, ParametricFunction] = {}
    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        with built_in_definitions():
            module = importlib.import_module(f"{pkg.__name__}.{info.name}")
        # built-in plugins may not import this room (tests/test_layers.py): they declare their
        # builders as data, registered here under "module:name"
        for key, fn in getattr(module, "BUILDERS", {}).items():
            register_builder(f"{module.__name__}:{key}", fn)
        for key, obj in vars(module).items():
            if isinstance(obj, ParametricFunction) and not key.startswith("_"):
                if obj.name in found and found[obj.name] is not obj:
                    raise FunctionError(
                        f"two built-in functions are named '{obj.name}': "
                        f"{found[obj.name].where} and {obj.where}")
                obj.origin = obj.origin or "built-in"
                found[obj.name] = obj
    return found


def add_plugin_path(folder) -> list[ParametricFunction]:
    """Load a folder of plugin files now (validated and compile-checked) and register its functions.

    Returns the functions found. Raises FunctionError for a broken plugin or a name that is taken.
    """
    path = Path(folder).expanduser().resolve()
    added = path not in _plugin_paths
    if added:
        _plugin_paths.append(path)  # first, so that its parts can name its own functions
    try:
        funcs = _load_folder(path)
        all_functions()  # detect name clashes now, not at the first lookup
    except BaseException:
        if added:
            _plugin_paths.remove(path)
        _folder_cache.pop(path, None)
        raise
    return funcs


def plugin_paths() -> list[Path]:
    """Plugin folders in effect: those added by ``add_plugin_path``, then ``PARAMLOD_FUNCTIONS_PATH``."""
    out = list(_plugin_paths)
    for item in os.environ.get(ENV_VAR, "").split(":"):
        if item.strip():
            p = Path(item.strip()).expanduser().resolve()
            if p not in out:
                out.append(p)
    return out


def refresh() -> None:
    """Forget loaded plugin folders and entry points (they load again on the next lookup)."""
    _plugin_paths.clear()
    _folder_cache.clear()
    _entry_point_cache.clear()


def _load_folder(path: Path) -> list[ParametricFunction]:
    if path not in _folder_cache:
        skip = {id(f) for f in builtin_functions().values()}
        # two phases: register first, then validate, so that parts can name functions of the same
        # folder (validation expands parts through the registry)
        _folder_cache[path] = load_plugin_folder(path, skip=skip, check=False)
        try:
            validate(_folder_cache[path])
        except BaseException:
            del _folder_cache[path]
            raise
    return _folder_cache[path]


def _entry_point_functions() -> list[ParametricFunction]:
    key = tuple(sys.path)  # installing or adding a distribution changes what entry points exist
    if key not in _entry_point_cache:
        skip = {id(f) for f in builtin_functions().values()}
        _entry_point_cache.clear()
        _entry_point_cache[key] = load_entry_points(skip=skip, check=False)
        try:
            validate(_entry_point_cache[key])
        except BaseException:
            del _entry_point_cache[key]
            raise
    return _entry_point_cache[key]


def _describe_source(f: ParametricFunction) -> str:
    return f"{f.origin or 'unknown origin'} ({f.where})"


def all_functions() -> dict[str, ParametricFunction]:
    """Every known function by name: built-ins, entry points, plugin folders."""
    merged: dict[str, ParametricFunction] = dict(builtin_functions())
    sources = [_entry_point_functions()] + [_load_folder(p) for p in plugin_paths()]
    for funcs in sources:
        for f in funcs:
            other = merged.get(f.name)
            if other is not None and other is not f:
                raise FunctionError(
                    f"two functions are named '{f.name}': {_describe_source(other)} and "
                    f"{_describe_source(f)}; rename one of them (name='...' in @parametric)")
            merged[f.name] = f
    return merged


def register_builder(name: str, fn) -> None:
    """Make ``fn`` (a callable returning instance arrays: count, transforms, ...) nameable from scene
    files as ``instances = { builder = name, args = {...} }``. A name registered twice with another
    callable is an error."""
    if not isinstance(name, str) or not name.strip():
        raise FunctionError(f"a builder name is a non-empty string, got {name!r}")
    if not callable(fn):
        raise FunctionError(f"builder {name!r}: expected a callable, got {fn!r}")
    other = _builders.get(name)
    if other is not None and other is not fn:
        raise FunctionError(f"two builders are named {name!r}: {other!r} and {fn!r}")
    _builders[name] = fn


def builders() -> dict[str, object]:
    """Every registered instance builder by name (built-ins and those of loaded plugins)."""
    all_functions()   # loading the functions runs their modules, which register their builders
    return dict(_builders)


def get_builder(name: str):
    """The registered builder ``name``; FunctionError (listing the registered ones) otherwise."""
    known = builders()
    if name in known:
        return known[name]
    close = difflib.get_close_matches(str(name), known, n=3)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    raise FunctionError(f"builder {name!r} is not registered (registered: {', '.join(sorted(known)) or 'none'})"
                        f"{hint}; a scene file names only registered builders, or pass --trust-scene "
                        "to let it import and run any module:function")


def get_function(fn_or_name) -> ParametricFunction:
    if isinstance(fn_or_name, ParametricFunction):
        return fn_or_name
    if not isinstance(fn_or_name, str):
        raise FunctionError(f"expected a function name or a @parametric function, got {fn_or_name!r}")
    funcs = all_functions()
    try:
        return funcs[fn_or_name]
    except KeyError:
        close = difflib.get_close_matches(fn_or_name, funcs, n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise FunctionError(
            f"unknown function '{fn_or_name}' (known: {', '.join(sorted(funcs))}){hint}") from None


def _default(p):
    return p.default.tolist() if p.is_array else float(p.default)


def describe_functions() -> list[dict]:
    """One dict per known function, sorted by name, for ``paramlod functions``:
    name, summary, u and v domains, the periodic axes, parameters with defaults (array parameters:
    their size and default list), kind (sympy or snippet), number of parts, origin and source file."""
    out = []
    for name, f in sorted(all_functions().items()):
        out.append({
            "name": name,
            "summary": f.summary,
            "u": list(f.u_range),
            "v": list(f.v_range),
            "periodic": "".join(f.periodic),
            "params": [{"name": p.name, "default": _default(p), "size": p.size} for p in f.params],
            "kind": "snippet" if f.is_snippet else "sympy",
            "parts": len(f.parts),
            "origin": f.origin or "unknown",
            "source": f.where,
        })
    return out
