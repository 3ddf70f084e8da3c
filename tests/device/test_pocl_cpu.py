"""A CPU that PoCL's LLVM 14 names "generic" (AMD Zen 5) gets the name "znver3", so that PoCL
compiles for it (paramlod/device/pocl_cpu.py). The search runs on a stand-in device record here, so
the test checks it on every machine; the device of this process must build programs either way."""
import ctypes
import types

import numpy as np
import pytest

from paramlod.device import pocl_cpu
from paramlod.device.context import cl_device
from paramlod.errors import DeviceError


def _record(*strings):
    """A stand-in device record: zero words, then pointers to ``strings`` from word 10 on."""
    keep = [ctypes.create_string_buffer(s) for s in strings]
    words = (ctypes.c_uint64 * 64)()
    for i, s in enumerate(keep):
        words[10 + i] = ctypes.addressof(s)
    words[5] = 12345               # a word that is no pointer: read as nothing, never dereferenced
    device = types.SimpleNamespace(int_ptr=ctypes.addressof(words), version="OpenCL 3.0 PoCL HSTR: x-generic")
    return device, words, keep


def test_the_generic_name_after_the_triple_becomes_znver3():
    device, words, keep = _record(b"pthread", b"x86_64-unknown-linux-gnu", b"generic", b"generic")
    pocl_cpu.name_cpu(device)
    assert ctypes.string_at(words[12]) == b"znver3"
    assert ctypes.string_at(words[13]) == b"generic"       # only the name that follows the triple
    assert ctypes.string_at(words[11]) == b"x86_64-unknown-linux-gnu"


def test_a_record_without_the_name_is_left_alone_with_a_clear_error():
    device, words, keep = _record(b"pthread", b"generic")
    before = list(words)
    with pytest.raises(DeviceError, match="names it 'generic'.*PARAMLOD_CL_DEVICE"):
        pocl_cpu.name_cpu(device)
    assert list(words) == before


def test_this_process_device_builds_and_runs_a_kernel():
    import pyopencl as cl

    dev = cl_device()
    assert not (pocl_cpu.needs_cpu_name(dev.device) and not pocl_cpu._names)
    prog = cl.Program(dev.context, "__kernel void twice(__global float* a) { a[get_global_id(0)] *= 2.0f; }").build()
    a = np.arange(8, dtype=np.float32)
    buf = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=a)
    prog.twice(dev.queue, a.shape, None, buf)
    out = np.empty_like(a)
    cl.enqueue_copy(dev.queue, out, buf)
    np.testing.assert_array_equal(out, 2 * a)
