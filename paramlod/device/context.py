"""The one OpenCL context and queue of the process, and the lazily created headless GL context.

OpenCL: by default the first GPU with ``cl_khr_int64_extended_atomics`` (64-bit atom_min), else the
PoCL CPU device. ``PARAMLOD_CL_DEVICE=<substring>`` (or ``--cl-device``) picks by platform or device
name. Only this module creates contexts.
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field

from paramlod.device import pocl_cpu
from paramlod.errors import DeviceError

REQUIRED_EXTENSION = "cl_khr_int64_extended_atomics"
INSTALL_HINT = ("install a CPU OpenCL driver with `pip install 'pyopencl[pocl]'`, or make your GPU "
                "driver visible to the ICD loader (OCL_ICD_VENDORS pointing at a folder of .icd files)")


@dataclass
class CLDevice:
    context: object
    queue: object
    device: object
    # objects that live as long as the context (built programs, uploaded tables), by owner's key
    cache: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        return f"{self.device.name.strip()} ({self.device.platform.name.strip()})"

    @property
    def is_gpu(self) -> bool:
        import pyopencl as cl

        return bool(self.device.type & cl.device_type.GPU)

    def copy_of(self, a, writable: bool = False):
        """A device buffer holding a copy of the host array ``a``, made with it: no transfer is
        queued, so nothing waits for one (on PoCL each blocking transfer waits for its threads)."""
        import pyopencl as cl

        flags = cl.mem_flags.READ_WRITE if writable else cl.mem_flags.READ_ONLY
        return cl.Buffer(self.context, flags | cl.mem_flags.COPY_HOST_PTR, hostbuf=a)


_cl: CLDevice | None = None
_cl_override: str | None = None
_gl = None
_gl_cache: dict = {}   # objects that live as long as the GL context (compiled shader programs)


def list_devices() -> list:
    """Every OpenCL device of every platform (no context is made)."""
    import pyopencl as cl

    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return []  # PLATFORM_NOT_FOUND_KHR: no ICD found at all
    out = []
    for p in platforms:
        try:
            out.extend(p.get_devices())
        except cl.Error:
            continue
    return out


def _describe(devs) -> str:
    if not devs:
        return "no OpenCL devices were found"
    lines = []
    for d in devs:
        has = REQUIRED_EXTENSION in d.extensions
        lines.append(f"  - {d.name.strip()} ({d.platform.name.strip()}): "
                     f"{'has' if has else 'lacks'} {REQUIRED_EXTENSION}")
    return "OpenCL devices found:\n" + "\n".join(lines)


def set_cl_device(selector: str | None) -> None:
    """Choose the device by name substring before the first use (what ``--cl-device`` does)."""
    global _cl_override, _cl
    _cl_override = selector
    _cl = None


def choose_device(devs, selector: str | None):
    import pyopencl as cl

    usable = [d for d in devs if REQUIRED_EXTENSION in d.extensions]
    if selector:
        sel = selector.lower()
        named = [d for d in devs if sel in d.name.lower() or sel in d.platform.name.lower()]
        if not named:
            raise DeviceError(f"no OpenCL device matches '{selector}' (PARAMLOD_CL_DEVICE/--cl-device).\n{_describe(devs)}")
        ok = [d for d in named if REQUIRED_EXTENSION in d.extensions]
        if not ok:
            raise DeviceError(f"OpenCL device '{named[0].name.strip()}' lacks {REQUIRED_EXTENSION}, "
                              f"which the renderers need for 64-bit atom_min.\n{_describe(devs)}")
        return ok[0]
    for d in usable:
        if d.type & cl.device_type.GPU:
            return d
    if usable:
        return usable[0]
    raise DeviceError(f"no usable OpenCL device: the renderers need {REQUIRED_EXTENSION}.\n"
                      f"{_describe(devs)}\nTo fix: {INSTALL_HINT}.")


def cl_device() -> CLDevice:
    """The process's OpenCL context and in-order queue (created on first use)."""
    global _cl
    if _cl is None:
        import pyopencl as cl

        selector = _cl_override or os.environ.get("PARAMLOD_CL_DEVICE") or None
        dev = choose_device(list_devices(), selector)
        if pocl_cpu.needs_cpu_name(dev):
            pocl_cpu.name_cpu(dev)
        ctx = cl.Context([dev])
        _cl = CLDevice(ctx, cl.CommandQueue(ctx, properties=cl.command_queue_properties.PROFILING_ENABLE), dev)
    return _cl


def gl_context():
    """A headless OpenGL 4.5 core context through EGL, created on first use."""
    global _gl
    if _gl is None:
        import moderngl

        try:
            ctx = moderngl.create_context(standalone=True, backend="egl", require=450)
        except Exception as exc:  # moderngl raises plain Exception subclasses for missing EGL/GL
            raise DeviceError(
                f"could not create a headless OpenGL 4.5 context through EGL: {exc}. "
                "Install Mesa's EGL (Debian: libegl1 libegl-mesa0) or an NVIDIA driver.") from exc
        _gl = ctx
    return _gl


def gl_cache(ctx) -> dict:
    """The cache of objects that live as long as GL context ``ctx`` (this module's context)."""
    if ctx is not _gl:
        raise DeviceError("gl_cache: not the context of paramlod.device.context.gl_context()")
    return _gl_cache


def cl_info() -> dict:
    d = cl_device().device
    return {
        "device": d.name.strip(),
        "platform": d.platform.name.strip(),
        "version": d.version.strip(),
        "type": "GPU" if cl_device().is_gpu else "CPU",
        "compute_units": d.max_compute_units,
        "global_memory_mib": d.global_mem_size // 2**20,
        "max_work_group_size": d.max_work_group_size,
        "local_memory_kib": d.local_mem_size // 1024,
        "int64_atomics": REQUIRED_EXTENSION in d.extensions,
    }


GL_MAX_TESS_GEN_LEVEL = 0x8E7E


def _gl_integer(name: int) -> int | None:
    """glGetIntegerv of a limit that moderngl's info dict lacks (the context is current)."""
    import ctypes

    for lib in ("libOpenGL.so.0", "libGL.so.1"):
        try:
            gl = ctypes.CDLL(lib)
            break
        except OSError:
            continue
    else:
        return None
    value = ctypes.c_int(0)
    gl.glGetIntegerv(ctypes.c_uint(name), ctypes.byref(value))
    return value.value or None


def gl_info() -> dict:
    ctx = gl_context()
    return {
        "renderer": ctx.info["GL_RENDERER"],
        "vendor": ctx.info["GL_VENDOR"],
        "version": ctx.info["GL_VERSION"],
        "max_tess_gen_level": _gl_integer(GL_MAX_TESS_GEN_LEVEL),
        "max_samples": ctx.info.get("GL_MAX_SAMPLES"),
    }


def all_cl_devices_summary() -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _describe(list_devices())
