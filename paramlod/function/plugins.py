"""Loading parametric-function plugins, and checking them on the OpenCL device at load time.

Sources (the registry in ``registry.py`` merges them and rejects duplicate names):

* a folder of ``.py`` files (``paramlod.function.registry.add_plugin_path(dir)``, ``--functions DIR``,
  ``PARAMLOD_FUNCTIONS_PATH``): every public ``@parametric`` function a file defines;
* the entry-point group ``paramlod.functions`` of installed distributions: an entry point names a
  module (all its public functions), a ParametricFunction, or a list of them.

Each loaded function is validated (derivatives, printable code, parts) and compiled once with
``check_compiles``, so a broken plugin fails when it is loaded, not in the middle of a render.
"""
from __future__ import annotations

import hashlib
import importlib.util
import sys
import warnings
from pathlib import Path
from types import ModuleType

import numpy as np

from paramlod.device.context import cl_device
from paramlod.errors import DeviceError, FunctionError
from paramlod.function.codegen_cl import check_printable, function_body
from paramlod.function.define import ParametricFunction, _failing_line
from paramlod.function.programs import build, kernel

ENTRY_POINT_GROUP = "paramlod.functions"


# --- collecting functions ----------------------------------------------------------------------
def functions_in(obj, skip: set[int] = frozenset()) -> list[ParametricFunction]:
    """The ParametricFunctions a module, a function or a list/tuple/dict of them provides.

    In a module: public names only (no leading underscore), each object once, and none whose id is
    in ``skip`` (the built-ins a plugin merely imported).
    """
    if isinstance(obj, ParametricFunction):
        found = [obj]
    elif isinstance(obj, ModuleType):
        found = [v for k, v in vars(obj).items() if not k.startswith("_") and isinstance(v, ParametricFunction)]
    elif isinstance(obj, dict):
        found = list(obj.values())
    elif isinstance(obj, (list, tuple)):
        found = list(obj)
    else:
        return []
    out, seen = [], set()
    for f in found:
        if isinstance(f, ParametricFunction) and id(f) not in seen and id(f) not in skip:
            seen.add(id(f))
            out.append(f)
    return out


def load_plugin_file(path: Path, skip: set[int] = frozenset()) -> list[ParametricFunction]:
    """Import one plugin file (under a private module name) and return its functions."""
    path = Path(path).resolve()
    digest = hashlib.sha1(str(path).encode()).hexdigest()[:10]
    modname = f"paramlod_plugin_{digest}_{path.stem}"
    spec = importlib.util.spec_from_file_location(modname, path)
    if spec is None or spec.loader is None:
        raise FunctionError(f"plugin file {path}: cannot be imported as a Python module")
    module = importlib.util.module_from_spec(spec)
    sys.modules[modname] = module
    try:
        spec.loader.exec_module(module)
    except FunctionError:
        sys.modules.pop(modname, None)
        raise  # already names the plugin, its file and the problem
    except SyntaxError as exc:
        sys.modules.pop(modname, None)
        raise FunctionError(f"plugin file {path}:{exc.lineno}: syntax error: {exc.msg}") from None
    except SystemExit as exc:   # would end paramlod without a word
        sys.modules.pop(modname, None)
        raise FunctionError(f"plugin file {path} called sys.exit({exc.code!r}) while being imported") from None
    except Exception as exc:
        sys.modules.pop(modname, None)
        line = _failing_line(exc, str(path))
        at = f":{line}" if line else ""
        raise FunctionError(f"plugin file {path}{at} failed to import: {type(exc).__name__}: {exc}") from None
    funcs = functions_in(module, skip)
    for f in funcs:
        f.origin = f"plugin folder {path.parent}"
    return funcs


def load_plugin_folder(folder, skip: set[int] = frozenset(), check: bool = True) -> list[ParametricFunction]:
    """All functions of the ``.py`` files in ``folder`` (sorted by file name; ``_*.py`` skipped)."""
    folder = Path(folder).expanduser()
    if not folder.is_dir():
        raise FunctionError(f"plugin folder {folder} does not exist or is not a folder")
    funcs: list[ParametricFunction] = []
    for path in sorted(folder.glob("*.py")):
        if path.name.startswith("_"):
            continue
        funcs.extend(load_plugin_file(path, skip))
    if check:
        validate(funcs)
    return funcs


def load_entry_points(skip: set[int] = frozenset(), check: bool = True) -> list[ParametricFunction]:
    """Functions from the ``paramlod.functions`` entry points of installed distributions."""
    from importlib.metadata import entry_points

    funcs: list[ParametricFunction] = []
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: (e.name, e.value)):
        dist = getattr(ep, "dist", None)
        label = f"entry point '{ep.name} = {ep.value}'" + (f" of {dist.name} {dist.version}" if dist else "")
        try:
            obj = ep.load()
        except FunctionError as exc:
            raise FunctionError(f"{label}: {exc}") from None
        except Exception as exc:
            raise FunctionError(f"{label} failed to load: {type(exc).__name__}: {exc}") from None
        if callable(obj) and not isinstance(obj, ParametricFunction) and not isinstance(obj, ModuleType):
            try:
                obj = obj()  # a factory returning functions
            except Exception as exc:
                raise FunctionError(f"{label}: calling it failed: {type(exc).__name__}: {exc}") from None
        found = functions_in(obj, skip)
        if not found:
            raise FunctionError(f"{label} provides no @parametric functions (it loaded {type(obj).__name__}); "
                                f"point it at a module, a function, or a list of functions")
        for f in found:
            f.origin = label
        funcs.extend(found)
    if check:
        validate(funcs)
    return funcs


# --- checks ------------------------------------------------------------------------------------
def validate(funcs: list[ParametricFunction], compile: bool = True) -> None:
    """Load-time checks: derivatives exist, every function prints as GPU code, parts sit where the
    frame is defined, and the generated OpenCL compiles (if a device is available)."""
    for f in funcs:
        check_printable(f)
        if not f.is_snippet:
            bindings, outputs = f.program("surface")  # raises now if sympy cannot differentiate
            function_body(f, outputs, bindings=bindings)  # the partials must print too
        if f.parts:
            f.expand_parts()
    if compile and funcs:
        try:
            check_compiles(funcs)
        except DeviceError as exc:
            warnings.warn(f"plugins were not compile-checked: {exc}", stacklevel=2)


def check_compiles(fn) -> None:
    """Compile one function (or a list) with the evaluation kernel on the current OpenCL device.

    Raises FunctionError naming the plugin, its file, and the generated lines around the
    compiler's complaint.
    """
    funcs = [fn] if isinstance(fn, ParametricFunction) else list(fn)
    try:
        build(["common/eval.cl"], funcs)
        return
    except FunctionError as exc:
        if len(funcs) == 1:
            f = funcs[0]
            raise FunctionError(f"plugin '{f.name}' ({f.where}): {exc}") from None
        first = exc
    for f in funcs:  # find the culprit
        check_compiles(f)
    raise first


def evaluate_cl(fn: ParametricFunction, u, v, block=None, functions=None, split: bool = False, **params):
    """Evaluate ``fn`` on the OpenCL device at float32 (u, v): (pos, du, dv, pos_only), each (..., 3);
    with ``split``, also (pos, du, dv) of the generated code's surface split and pos of its
    position split (codegen_cl.split_surface).

    The device-side twin of ``fn.surface``. ``functions`` (which must contain ``fn``) is the set the
    program is built for: pass the same list for several functions to compile once.
    """
    import pyopencl.array as cla

    funcs = [fn] if functions is None else list(functions)
    index = next((i for i, f in enumerate(funcs) if f is fn), None)
    if index is None:
        raise FunctionError(f"evaluate_cl: '{fn.name}' is not in the functions given")
    if block is None:
        block = fn.param_block(params)
    u = np.asarray(u, np.float32)
    v = np.asarray(v, np.float32)
    shape = np.broadcast_shapes(u.shape, v.shape)
    uv = np.stack([np.broadcast_to(u, shape).ravel(), np.broadcast_to(v, shape).ravel()], axis=1)
    n = uv.shape[0]
    q = cl_device().queue
    k = kernel("eval_samples", ["common/eval.cl"], funcs)   # built once per set of functions, then cached
    d_uv = cla.to_device(q, np.ascontiguousarray(uv, np.float32))
    d_p = cla.to_device(q, np.concatenate([fn.device_blocks(np.asarray(block, np.float32).reshape(-1)), np.zeros(1, np.float32)]))
    d_out = cla.empty(q, max(1, n) * 24, np.float32)
    k(q, (max(1, n),), None, np.uint32(index), d_uv.data, np.uint32(n), d_p.data, d_out.data)
    out = d_out.get()[:n * 24].reshape(shape + (8, 3)).astype(np.float64)
    values = tuple(out[..., i, :] for i in range(4))
    return values + (tuple(out[..., i, :] for i in range(4, 8)),) if split else values


def measure_throughput(fn: ParametricFunction, side: int = 512, repeats: int = 3, block=None) -> float:
    """Positions per second of ``fn`` on the OpenCL device (kernels/common/eval.cl, eval_throughput): the
    best of ``repeats`` timed launches over a side x side grid of its domain, after one warm-up.
    For ``paramlod bench``; never asserted in tests."""
    import time

    import pyopencl.array as cla

    q = cl_device().queue
    throughput = build(["common/eval.cl"], [fn]).eval_throughput
    if block is None:
        block = fn.param_block()
    d_p = cla.to_device(q, np.concatenate([fn.device_blocks(np.asarray(block, np.float32).reshape(-1)), np.zeros(1, np.float32)]))
    out = cla.empty(q, side * side, np.float32)
    (u0, u1), (v0, v1) = fn.u_range, fn.v_range
    args = (np.uint32(0), np.float32(u0), np.float32((u1 - u0) / (side - 1)), np.float32(v0),
            np.float32((v1 - v0) / (side - 1)), np.uint32(side), d_p.data, out.data)
    best = float("inf")
    for k in range(repeats + 1):
        q.finish()
        t0 = time.perf_counter()
        throughput(q, (side, side), None, *args)
        q.finish()
        if k:  # the first launch warms up
            best = min(best, time.perf_counter() - t0)
    return side * side / best
