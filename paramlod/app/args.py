"""Argument types and options shared by every command (``paramlod render | bench | gallery | glyphs |
surfels``), so that a size, a vector or an output list means the same everywhere and a bad value is
refused by argparse with the command's usage line (exit status 2)."""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import threading
import time
import warnings
from contextlib import contextmanager
from pathlib import Path

from paramlod.device.programs import compiling_now
from paramlod.errors import ParamlodError

MAX_SIDE = 16384   # the largest image side any command renders (scene files share the limit)


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, like every other error of paramlod
    (``paramlod: error: argument --size: ...``, exit status 2), not the usage block. Subparsers
    made with ``add_parser`` share the class."""

    def error(self, message):
        self.exit(2, f"paramlod: error: {message} (see {self.prog} --help)\n")


def _int_at_least(lo: int):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            v = lo - 1
        if v < lo:
            raise argparse.ArgumentTypeError(f"must be an integer >= {lo}, got {text!r}")
        return v
    return parse


positive_int = _int_at_least(1)        # frame counts, repeats, workers
non_negative_int = _int_at_least(0)    # warm-up frames


def positive_float(text: str) -> float:
    """A finite number > 0 (distances, scales)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return v


def check_folder(folder, flag: str, create: bool = False) -> Path:
    """``folder`` exists (or, with ``create``, can be made) and a file can be created in it: probed
    with a real temporary file, so read-only file systems, permissions and /proc are all caught
    before any work. Raises ParamlodError naming ``flag``."""
    folder = Path(folder) if str(folder) else Path(".")
    if create and not folder.exists():
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ParamlodError(f"{flag}: cannot create folder {folder}: {exc.strerror or exc}") from None
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "does not exist"
        raise ParamlodError(f"{flag}: folder {folder} {what}")
    try:
        with tempfile.TemporaryFile(dir=folder, prefix=".paramlod-probe-"):
            pass
    except OSError as exc:
        raise ParamlodError(f"{flag}: folder {folder} is not writable ({exc.strerror or exc})") from None
    return folder


def check_outputs(paths, flag: str = "-o/--output", suffixes=(".png", ".exr")) -> list[Path]:
    """Every output path, before any work: a known suffix, no path twice, not an existing folder,
    and a writable folder (``check_folder``). Raises ParamlodError naming ``flag`` and the path."""
    out, seen = [], set()
    for p in paths:
        path = Path(p)
        if suffixes and path.suffix.lower() not in suffixes:
            raise ParamlodError(f"{flag} {p}: unknown file type {path.suffix or '(none)'!r} "
                                f"(use {' or '.join(suffixes)})")
        key = os.path.realpath(path)
        if key in seen:
            raise ParamlodError(f"{flag} {p}: given twice")
        seen.add(key)
        if path.is_dir():
            raise ParamlodError(f"{flag} {p}: is a folder")
        check_folder(path.parent, f"{flag} {p}")
        out.append(path)
    return out


def write_all_or_none(items) -> None:
    """``items``: (path, write(path)) pairs. Writes each (each atomically); when one fails, the
    outputs this call has already written are removed again, so a command leaves all or none."""
    done = []
    try:
        for path, write in items:
            existed = Path(path).exists()
            write(path)
            if not existed:
                done.append(Path(path))
    except BaseException:
        for path in done:
            path.unlink(missing_ok=True)
        raise


SPINNER = "|/-\\"
PROGRESS_ENV = "PARAMLOD_PROGRESS"   # "1": show progress even when stderr is not a terminal; "0": never


@contextmanager
def progress(stage: str, delay: float = 2.0, stream=None):
    """A spinner with ``stage`` and the seconds spent, on stderr, for a step that takes longer than
    ``delay`` seconds (quick steps print nothing); on a terminal only, unless PARAMLOD_PROGRESS=1.
    While an OpenCL compile runs (a first run), the line says so. The line is erased when the step
    ends, so the command's own output stays as it was."""
    stream = stream or sys.stderr
    mode = os.environ.get(PROGRESS_ENV, "")
    show = mode == "1" or (mode != "0" and getattr(stream, "isatty", lambda: False)())
    if not show:
        yield
        return
    stop = threading.Event()
    start = time.monotonic()
    widths = [0]   # the widths of the lines the spinner drew

    def spin():
        # quiet for ``delay`` seconds, or half a second once a compile is what the step waits for
        while time.monotonic() - start < (min(delay, 0.5) if compiling_now() else delay):
            if stop.wait(0.05):
                return
        for k in range(1 << 62):
            what = compiling_now()
            note = f" (compiling OpenCL: {what}; the driver caches it for later runs)" if what else ""
            line = f"\r{SPINNER[k % 4]} {stage}{note} ... {time.monotonic() - start:.0f} s "
            stream.write(line + " " * max(0, widths[-1] - len(line)))   # blank what a longer line left
            widths.append(len(line))
            stream.flush()
            if stop.wait(0.25):
                return

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        if len(widths) > 1:
            done = f"\r{stage}: {time.monotonic() - start:.1f} s"
            stream.write(done + " " * max(12, widths[-1] - len(done)) + "\n")
            stream.flush()


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


def format_warning(message) -> str:
    """One line for a warning: ``paramlod: warning: <message>``; the message's own line breaks and
    runs of spaces become single spaces, and no source path or code line is shown (they name
    paramlod's files, not the user's input)."""
    return f"paramlod: warning: {' '.join(str(message).split())}\n"


def install_warning_format(stream=None):
    """Show every Python warning on the command line as ``format_warning``'s one line (on ``stream``,
    default stderr at the time of the warning), instead of Python's ``path:line: Category: message``
    and the source line. Which warnings are shown (once per place, by default) stays Python's
    filters' choice. Returns the previous ``warnings.showwarning``, to put back if needed."""

    def show(message, category, filename, lineno, file=None, line=None):
        out = file or stream or sys.stderr
        try:
            out.write(format_warning(message))
            out.flush()
        except (OSError, ValueError, AttributeError):   # a closed or missing stderr: drop it, as Python does
            pass

    previous = warnings.showwarning
    warnings.showwarning = show
    return previous


def run_reporting_errors(call) -> int:
    """``call()``'s exit status; a ParamlodError is printed as one line, without a traceback (status
    2), and Ctrl-C ends quietly (status 130). Every command's ``main`` goes through here."""
    try:
        return call()
    except ParamlodError as exc:
        print(f"paramlod: error: {exc}", file=sys.stderr)
        return 2
    except RecursionError:   # a plugin's expression nested past Python's stack: one line, not 2,000
        print("paramlod: error: an expression is nested too deeply to handle (Python's recursion limit); "
              "name intermediate results with let(...)", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("paramlod: interrupted", file=sys.stderr)
        return 130
