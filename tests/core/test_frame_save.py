"""Frame.save: a failed EXR write is a clean error like a failed PNG write, and leaves no file."""
from __future__ import annotations

import numpy as np
import OpenEXR
import pytest

from paramlod.core.frame import Frame
from paramlod.errors import ParamlodError


def small_frame() -> Frame:
    h, w = 4, 6
    return Frame(color=np.zeros((h, w, 4), np.float32), depth=np.full((h, w), np.inf, np.float32),
                 normal=np.zeros((h, w, 3), np.float32), object_id=np.zeros((h, w), np.uint32))


def test_a_full_disk_during_an_exr_write_is_a_clean_error(tmp_path, monkeypatch):
    class FullDisk:   # what OpenEXR raises when the disk fills up mid-write
        def __init__(self, header, channels):
            pass

        def write(self, name):
            raise RuntimeError(f'Failed to write pixel data to image file "{name}". No space left on device.')

    monkeypatch.setattr(OpenEXR, "File", FullDisk)
    out = tmp_path / "f.exr"
    with pytest.raises(ParamlodError) as e:
        small_frame().save(out)
    assert str(e.value) == f"cannot write {out}: No space left on device"
    assert list(tmp_path.iterdir()) == []   # no partial or temporary file left
