"""The heads-up display: lines of text drawn with Pillow's built-in font into an RGBA image, which
the window blends over the frame (no GUI toolkit needed). ``lines`` is pure and tested; ``image``
is redrawn only when the text changes."""
from __future__ import annotations

import numpy as np

from paramlod.core.frame import FrameStats

ERROR_COLOUR = (255, 110, 90, 255)
TEXT_COLOUR = (235, 235, 235, 255)
HELP = ("WASD/QE fly, mouse look (drag), wheel speed, Tab orbit, F frame, R reset, V variant, B AA, "
        "[ ] LOD threshold, C debug colours, Space pause, , . time, P screenshot, H HUD, Esc quit")


def frame_counts(stats: FrameStats) -> str:
    """What the LOD stages produced: render patches of parametric objects and clusters of meshes."""
    parts = []
    patches = int(stats.get("render_patches", 0))
    clusters = sum(int(p.get("clusters_drawn", 0)) for p in stats.get("passes") or [stats]) \
        or int(stats.get("clusters_drawn", 0))
    if patches or not clusters:
        parts.append(f"{patches:,} patches")
    if clusters:
        parts.append(f"{clusters:,} clusters")
    samples = int(stats.get("samples", 0))
    if samples:
        parts.append(f"{samples:,} samples")
    return ", ".join(parts)


def lines(state: dict, stats: FrameStats | None, timings: dict, error: str | None) -> list[tuple[str, tuple]]:
    """The HUD's lines and their colours. ``state``: variant, aa, threshold, debug, mode, time,
    paused, source; ``timings``: fps and the frame's ms split into lod, render and present."""
    out = []
    fps = timings.get("fps", 0.0)
    out.append((f"{fps:5.1f} FPS  frame {timings.get('frame', 0.0):6.2f} ms = LOD {timings.get('lod', 0.0):.2f} + "
                f"render {timings.get('render', 0.0):.2f} + present {timings.get('present', 0.0):.2f}", TEXT_COLOUR))
    if stats is not None:
        w, h = stats.get("size", [0, 0])
        out.append((f"{frame_counts(stats)}  {w}x{h} on {stats.get('device') or '?'}", TEXT_COLOUR))
    out.append((f"{state['variant']}  AA {state['aa']}  threshold {state['threshold']:.3g} px  "
                f"colour {state['debug']}  {state['mode']}", TEXT_COLOUR))
    out.append((f"t = {state['time']:.2f}{' (paused)' if state['paused'] else ''}  {state['source']}", TEXT_COLOUR))
    for note in state.get("notes", []):
        out.append((note, TEXT_COLOUR))
    if error:
        for line in error.splitlines()[:12]:
            out.append((line, ERROR_COLOUR))
    return out


def image(text_lines, width: int, wrap: int | None = None) -> np.ndarray:
    """(h, w, 4) uint8 RGBA, rows top first: the lines over a translucent dark box, long lines
    wrapped to the window's width."""
    from PIL import Image, ImageDraw, ImageFont

    font = ImageFont.load_default()
    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    char_w = max(1, int(probe.textlength("M", font=font)))
    wrap = wrap or max(20, (width - 12) // char_w)
    rows = []
    for text, colour in text_lines:
        text = text or " "
        while text:
            rows.append((text[:wrap], colour))
            text = text[wrap:]
    line_h = 14
    h = 8 + line_h * len(rows)
    w = min(width, 12 + max(int(probe.textlength(t, font=font)) for t, _ in rows))
    img = Image.new("RGBA", (max(w, 1), h), (0, 0, 0, 150))
    draw = ImageDraw.Draw(img)
    for k, (text, colour) in enumerate(rows):
        draw.text((6, 4 + k * line_h), text, fill=colour, font=font)
    return np.asarray(img)
