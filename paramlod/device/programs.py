"""Building OpenCL programs from kernels/ (plus generated source given as text), with a
per-process cache and compiler errors that show the offending lines. Programs that include the
generated code of parametric functions are built through ``paramlod.function.programs``.

Across processes the OpenCL driver keeps the compiled programs: PoCL in its kernel cache
(``~/.cache/pocl/kcache``, keyed by source, options and device: ``paramlod render scenes/demo.toml``
took 5.3 s with an empty cache and 2.4 s with it on a 2-core Xeon), NVIDIA in its compute cache.
``compiling_now()`` names the program being compiled, so a command's progress line can say why a
first frame waits."""
from __future__ import annotations

import re
import warnings

import numpy as np
import pyopencl as cl

from paramlod import kernels
from paramlod.core.layouts import cl_prelude
from paramlod.device.context import cl_device
from paramlod.errors import FunctionError

# the programs being compiled now, by any thread (a progress line is drawn by another thread)
_compiling: list[str] = []


def compiling_now() -> str | None:
    """What an OpenCL compile in progress is building (its kernel files), or None."""
    return _compiling[-1] if _compiling else None


CL_LINE = r":(\d+):\d+:"              # clang-style 'file:LINE:COL:'
GLSL_LINE = r"\b0[:(](\d+)[(:)]"        # Mesa '0:LINE(COL)', NVIDIA '0(LINE)'


def context_lines(src: str, log: str, pattern: str = CL_LINE, around: int = 3) -> str:
    """The generated lines (up to three places) that a compiler ``log`` complains about."""
    lines = src.splitlines()
    shown, seen = [], set()
    for m in re.finditer(pattern, log):
        ln = int(m.group(1))
        if ln in seen or not 1 <= ln <= len(lines):
            continue
        seen.add(ln)
        lo, hi = max(1, ln - around), min(len(lines), ln + around)
        shown.append("\n".join(f"{'>' if i == ln else ' '}{i:5d} | {lines[i - 1]}" for i in range(lo, hi + 1)))
        if len(shown) >= 3:
            break
    return "\n...\n".join(shown)


# NVIDIA's compiler says of every kernel that it ignores a noinline attribute (a kernel may be
# inlined): nothing anyone can act on, so it is not shown
_NVIDIA_KERNEL_NOTE = re.compile(r"\(\):\s*Warning: Function \w+ is a kernel, so overriding noinline attribute\."
                                 r"\s*The function may be inlined when called\.")
# the kernels pyopencl generates for itself (scans, array fills) pass the same notes on as
# warnings; they are about pyopencl's code, not a user's
warnings.filterwarnings("ignore", category=cl.CompilerWarning, module=r"pyopencl(\.|$)")


def compiler_notes(log: str) -> str:
    """What a successful build's ``log`` says that is worth showing ('' if nothing)."""
    return _NVIDIA_KERNEL_NOTE.sub("", log).strip()


def define_options(defines: dict) -> tuple[str, ...]:
    """``-D`` compiler options for ``defines``: a numpy float32 value becomes a float literal
    (``2.0f``, the same float: the constant a numpy twin reads), anything else its text."""
    def text(v):
        return np.format_float_positional(v, trim="0") + "f" if isinstance(v, np.float32) else v
    return tuple(f"-D{k}={text(v)}" for k, v in sorted(defines.items()))


def build(files: list[str], defines: dict | None = None, options: tuple = (), generated: str = "",
          describe: str = "none"):
    """Compile the prelude (``paramlod.core.layouts.cl_prelude``: records, shading constants, sRGB
    table) + kernels/common/common.cl + ``generated`` + ``files`` (paths in kernels/);
    ``options`` are extra compiler options; ``describe`` names the generated code's sources in
    the error a failed compile raises. Every program gets ``PL_GPU`` (1 on a GPU, else 0) for
    code whose fastest form differs between the two (kernels/common/builtins.cl, keys.cl's srgb8)."""
    prelude = cl_prelude()
    for name in defines or {}:   # a -D the prelude defines again would be silently overridden
        if re.search(rf"^#define {name}\b", prelude, re.M) or name == "PL_GPU":
            raise ValueError(f"OpenCL define {name} is already a macro of the prelude (paramlod.core.layouts) "
                             "or of build()")
    src = "\n".join([prelude, kernels.source("common/common.cl"), generated,
                      *(kernels.source(f) for f in files)])
    dev = cl_device()
    defines = {**(defines or {}), "PL_GPU": int(dev.is_gpu)}
    opts = define_options(defines) + tuple(options)
    cache = dev.cache.setdefault("programs", {})
    key = (src, opts)
    prog = cache.get(key)
    if prog is None:
        what = ", ".join(files) or "generated code"
        _compiling.append(what)
        try:
            with warnings.catch_warnings():   # pyopencl's note says only "non-empty output"; ours says what
                warnings.simplefilter("ignore", cl.CompilerWarning)
                prog = cl.Program(dev.context, src).build(options=list(opts))
            notes = compiler_notes(prog.get_build_info(dev.device, cl.program_build_info.LOG) or "")
            if notes:
                warnings.warn(f"the OpenCL compiler's notes on {what}: {notes[-2000:]}", cl.CompilerWarning,
                              stacklevel=2)
        except cl.RuntimeError as exc:
            log = str(exc)
            raise FunctionError(
                f"the generated OpenCL code does not compile (functions: {describe}).\n"
                f"{context_lines(src, log)}\ncompiler said:\n{log[-2000:]}") from None
        finally:
            _compiling.remove(what)
        cache[key] = prog
    return prog


_timing: list | None = None   # (kernel, event) of the current measurement, when one is running


class TimedKernel:
    """A cl.Kernel whose launches can be timed (``start_timing`` / ``stop_timing``): the benchmark
    uses the kernels' durations to separate device time from host (Python) time, and to show
    where the device time goes."""

    def __init__(self, k):
        self.k = k

    def __call__(self, *args, **kw):
        evt = self.k(*args, **kw)
        if _timing is not None:
            _timing.append((self.k, evt))
        return evt

    def __getattr__(self, name):
        return getattr(self.k, name)


def launch(queue, k, global_size, local_size=None):
    """Enqueue a cl.Kernel whose arguments are already set (no per-launch argument conversion);
    recorded like TimedKernel launches while a measurement runs."""
    evt = cl.enqueue_nd_range_kernel(queue, k, global_size, local_size)
    if _timing is not None:
        _timing.append((k, evt))
    return evt


def start_timing() -> None:
    global _timing
    _timing = []


def stop_timing() -> dict[str, float]:
    """Milliseconds each recorded kernel ran on the device, by name, summed over its launches
    (waits for them; the names are read here, not at launch, which the measured frame pays)."""
    global _timing
    recorded, _timing = _timing or [], None
    out: dict[str, float] = {}
    for k, evt in recorded:
        name = k.function_name
        out[name] = out.get(name, 0.0) + events_ms([evt])
    return out


def events_ms(events) -> float:
    """Milliseconds the profiled ``events`` ran on the device, summed (waits for them)."""
    total = 0
    for e in events:
        e.wait()
        total += e.profile.end - e.profile.start
    return total * 1e-6


def kernel(name: str, files: list[str], defines: dict | None = None, options: tuple = (), generated: str = "",
           describe: str = "none"):
    """A kernel object from ``build(files, defines, options, generated)``, retrieved once and reused."""
    prog = build(files, defines, options, generated, describe)
    kernels_ = cl_device().cache.setdefault("kernels", {})
    key = (prog, name)
    k = kernels_.get(key)
    if k is None:
        k = kernels_[key] = TimedKernel(cl.Kernel(prog, name))
    return k


def set_uniform(prog, name: str, value) -> None:
    """Set a uniform of a moderngl program if the compiler kept it (unused ones are optimized
    away); numpy arrays are written as float32 bytes."""
    try:
        u = prog[name]
    except KeyError:
        return
    if isinstance(value, np.ndarray):
        u.write(np.ascontiguousarray(value, np.float32).tobytes())
    else:
        u.value = value


def check_block(prog, name: str, nbytes: int, source: str) -> None:
    """Check that uniform block ``name`` of a moderngl program (if the compiler kept it) takes
    ``nbytes``, the size of the records Python writes into it: the GLSL struct in ``source`` and
    its Python mirror must change together."""
    try:
        size = prog[name].size
    except KeyError:
        return
    if size != nbytes:
        raise RuntimeError(f"uniform block {name} of {source} takes {size} bytes, its records written from "
                           f"Python {nbytes}: change them together")
