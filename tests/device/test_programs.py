"""paramlod.device.programs: what a successful build's compiler log shows the user."""
import warnings

import pyopencl as cl

from paramlod.device import programs

NVIDIA = ("(): Warning: Function {} is a kernel, so overriding noinline attribute. The function may be "
          "inlined when called.\n")


def test_nvidias_note_on_every_kernel_is_dropped_and_the_rest_kept():
    log = NVIDIA.format("lod_step") + NVIDIA.format("points_direct")
    assert programs.compiler_notes(log) == ""
    real = "<source>:12:5: warning: unused variable 'x'"
    assert programs.compiler_notes(NVIDIA.format("resolve") + real + "\n") == real


def test_a_compiler_warning_is_shown_once_with_its_text():
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        programs.build([], generated="#warning paramlod-test-note\n__kernel void k(__global int *a) { a[0] = 1; }")
    notes = [w for w in seen if issubclass(w.category, cl.CompilerWarning)]
    # ours, with the compiler's words, and not pyopencl's "non-empty compiler output" beside it
    assert len(notes) == 1 and "paramlod-test-note" in str(notes[0].message), [str(w.message) for w in seen]
    assert "generated code" in str(notes[0].message)
