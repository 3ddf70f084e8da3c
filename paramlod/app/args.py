"""Argument types and options shared by every command (``paramlod render | bench | gallery | glyphs |
surfels``), so that a size, a vector or an output list means the same everywhere and a bad value is
refused by argparse with the command's usage line (exit status 2)."""
from __future__ import annotations

import argparse
import math
import sys

from paramlod.errors import ParamlodError

MAX_SIDE = 16384   # the largest image side any command renders (scene files share the limit)


def parse_size(text: str) -> tuple[int, int]:
    """``"960x540"`` -> (960, 540); each side 1..MAX_SIDE."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
        if not (0 < w <= MAX_SIDE and 0 < h <= MAX_SIDE):
            raise ValueError
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 960x540 (each side 1..{MAX_SIDE}), "
                                         f"got {text!r}") from None


def parse_vec3(text: str) -> tuple[float, float, float]:
    """``"1,0.5,2"`` -> (1.0, 0.5, 2.0); three finite numbers."""
    try:
        v = tuple(float(x) for x in text.split(","))
        if len(v) != 3 or not all(math.isfinite(x) for x in v):
            raise ValueError
        return v
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers like 1,0.5,2, got {text!r}") from None


def add_size(parser, default: str | None = None, what: str = "image size"):
    """``--size WxH`` parsed by ``parse_size``; None when not given and there is no default."""
    tail = f" (default {default})" if default else ", e.g. 1920x1080"
    return parser.add_argument("--size", type=parse_size, default=default, metavar="WxH",
                               help=f"{what} in pixels{tail}")


def add_output(parser, required: bool = True, default_help: str = ""):
    """``-o/--output FILE``, repeatable; the format follows the suffix (.png or .exr)."""
    return parser.add_argument("-o", "--output", action="append", required=required, metavar="FILE",
                               help="output .png or .exr (repeatable)" + (f"; {default_help}" if default_help else ""))


def add_stats(parser):
    """``--stats FILE``: the frame statistics as JSON."""
    return parser.add_argument("--stats", metavar="FILE", help="write the frame statistics as JSON to this file")


def run_reporting_errors(call) -> int:
    """``call()``'s exit status; a ParamlodError is printed as one line, without a traceback (status
    2), and Ctrl-C ends quietly (status 130). Every command's ``main`` goes through here."""
    try:
        return call()
    except ParamlodError as exc:
        print(f"paramlod: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("paramlod: interrupted", file=sys.stderr)
        return 130
