"""OpenCL C and GLSL sources (package data) in folders by room (common, lod, points, tess, surfels,
bench), loaded with importlib.resources.

``source("points/points.cl")`` returns a file's text with each ``#include "folder/file"`` line
replaced by that file (once per source, so a shared header may be included from several files).
"""
import re
from importlib.resources import files

_INCLUDE = re.compile(r'^[ \t]*#include[ \t]+"([^"]+)"[ \t]*$', re.M)


def source(name: str, _seen: set | None = None) -> str:
    """The text of kernel file ``name`` (for example ``"lod/lod.cl"``), includes resolved."""
    seen = set() if _seen is None else _seen
    seen.add(name)
    text = files(__name__).joinpath(name).read_text(encoding="utf-8")

    def include(m):
        inc = m.group(1)
        return "" if inc in seen else source(inc, seen)

    return _INCLUDE.sub(include, text)
