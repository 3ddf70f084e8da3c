"""Name a CPU that PoCL's LLVM does not know, so that PoCL can compile for it.

The PoCL that ``pip install 'pyopencl[pocl]'`` brings (3.0, a DISTRO build on LLVM 14) asks LLVM for
the host CPU's name and passes it to clang as ``-target-cpu``. LLVM 14 names AMD's family 19h
(Zen 3 and Zen 4) "znver3"; a newer CPU (Zen 5, family 1Ah) it names "generic", which clang
refuses: every build fails with "unknown target CPU 'generic'" (pocl/pocl#1049). PoCL 3.0 has no
setting for the name, so before the context is made we point the device's name at "znver3", the
newest AMD name LLVM 14 has. Every newer AMD CPU runs znver3's instructions; the built-in library
PoCL links is chosen from the CPU's features, not from this name.

The device record is PoCL's own C struct. The name is found there, not assumed at an offset: the
pointer to "generic" that follows the pointer to the target triple ("x86_64-..."), read through
/proc/self/mem, so that a word that is not a pointer reads as nothing instead of crashing.
"""
from __future__ import annotations

import ctypes
import struct

from paramlod.errors import DeviceError

LLVM_CPU = b"znver3"
_RECORD_BYTES = 4096     # PoCL 3.0's device record is about 1.6 kB; its name pointers lie in the first 1 kB
_names: list = []        # the C strings the patched devices point at (they must outlive the devices)


def needs_cpu_name(device) -> bool:
    """True for a PoCL CPU device that LLVM named "generic" (its version string ends so)."""
    import pyopencl as cl

    return bool(device.type & cl.device_type.CPU and "Portable Computing Language" in device.platform.name
                and device.version.strip().endswith("-generic"))


def _read(mem, addr: int, n: int) -> bytes | None:
    """``n`` bytes of this process at ``addr`` (``mem``: /proc/self/mem), or None where none are mapped."""
    if addr < 4096:
        return None
    try:
        mem.seek(addr)
        return mem.read(n)
    except (OSError, ValueError, OverflowError):
        return None


def name_cpu(device) -> None:
    """Point ``device``'s LLVM CPU name at LLVM_CPU (see the module's docstring)."""
    with open("/proc/self/mem", "rb", buffering=0) as mem:
        record = _read(mem, device.int_ptr, _RECORD_BYTES) or b""
        words = struct.unpack(f"<{len(record) // 8}Q", record[: len(record) // 8 * 8])
        slots = [i for i in range(1, len(words))
                 if _read(mem, words[i], 8) == b"generic\0" and _read(mem, words[i - 1], 7) == b"x86_64-"]
    if len(slots) != 1:
        raise DeviceError(
            f"PoCL cannot compile for this CPU: its LLVM names it 'generic' ({device.version.strip()}), and "
            f"paramlod could not set another name ({len(slots)} candidates in the device record). "
            "Use another OpenCL device (PARAMLOD_CL_DEVICE) or a PoCL built with a newer LLVM.")
    name = ctypes.create_string_buffer(LLVM_CPU)
    _names.append(name)
    ctypes.c_void_p.from_address(device.int_ptr + 8 * slots[0]).value = ctypes.addressof(name)
