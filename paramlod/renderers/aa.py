"""Anti-aliasing modes, one grammar for every renderer: ``noAA``; ``2xMS``/``4xMS``/``8xMS`` (aliases
``msaa2`` ...); ``4xSS``/``9xSS``/``16xSS`` (2x2, 3x3, 4x4 supersampling; aliases ``ssaa2x2`` ...);
and combinations such as ``4xSS+8xMS`` (32 depth samples per pixel). The tess variant takes a mode
whole; the points variant takes its supersampling (multisampling is an error there).

``hybrid`` (thesis section 5.5.7): the LOD stage's spot check sends each patch with sub-pixel
detail to a finer tier, and the tiers are drawn coarse to fine, each finer target starting from a
per-sample copy of the coarser one: for tess noAA -> 8xMS -> 4xSS+8xMS (``TESS_TIERS``), for
points 1x -> 4xSS -> 16xSS key buffers (``POINT_TIERS``)."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from paramlod.errors import SceneError

_MS_ALIASES = {f"msaa{n}": n for n in (2, 4, 8)}
_SS_ALIASES = {f"ssaa{n}x{n}": n for n in (2, 3, 4)}


@dataclass(frozen=True)
class AAMode:
    """``ss`` x ``ss`` supersampling (1 = none) combined with ``msaa`` multisamples (1 = none)."""

    ss: int = 1
    msaa: int = 1
    hybrid: bool = False   # the tiers of hybrid_tiers, chosen per patch (ss, msaa unused)

    @property
    def samples_per_pixel(self) -> int:
        return self.ss * self.ss * self.msaa

    def divisor(self, msaa_lod: bool = False) -> float:
        """LOD threshold divisor: ``ss``, so the LOD stage measures patches in the supersampled
        target's pixels (the thesis's 4xSS+8xMS figures: 4x the patches of noAA "due to 4xSS");
        with ``msaa_lod`` also sqrt(msaa), the hybrid scheme's guideline (sqrt(32) for 4xSS+8xMS)."""
        return self.ss * (math.sqrt(self.msaa) if msaa_lod else 1.0)

    @property
    def name(self) -> str:
        if self.hybrid:
            return "hybrid"
        parts = []
        if self.ss > 1:
            parts.append(f"{self.ss * self.ss}xSS")
        if self.msaa > 1:
            parts.append(f"{self.msaa}xMS")
        return "+".join(parts) or "noAA"


def parse_aa(mode) -> AAMode:
    """``"noAA"``, ``"8xMS"``, ``"4xSS"``, ``"4xSS+8xMS"``, ``"msaa4"``, ``"ssaa3x3"`` ... -> AAMode."""
    if isinstance(mode, AAMode):
        return mode
    if not isinstance(mode, str) or not mode.strip():
        raise SceneError(f"anti-aliasing mode must be a string such as 'noAA', '8xMS', '4xSS' or "
                         f"'4xSS+8xMS', got {mode!r}")
    text = mode.strip()
    if text.lower() in ("noaa", "none", "off"):
        return AAMode()
    if text.lower() == "hybrid":
        return AAMode(hybrid=True)
    ss, ms = 1, 1
    for part in (p.strip().lower() for p in text.split("+")):
        m_ms = re.fullmatch(r"(\d+)x?ms(?:aa)?", part)
        m_ss = re.fullmatch(r"(\d+)x?ss(?:aa)?", part)
        if part in _MS_ALIASES or m_ms:
            n = _MS_ALIASES.get(part) or int(m_ms.group(1))
            if n not in (2, 4, 8) or ms != 1:
                raise SceneError(f"anti-aliasing mode {mode!r}: multisampling must be given once, as 2xMS, "
                                 "4xMS or 8xMS")
            ms = n
        elif part in _SS_ALIASES or m_ss:
            if part in _SS_ALIASES:
                n = _SS_ALIASES[part]
            else:
                total = int(m_ss.group(1))
                n = math.isqrt(total)
                if n * n != total or n not in (2, 3, 4):
                    raise SceneError(f"anti-aliasing mode {mode!r}: supersampling must be 4xSS, 9xSS or 16xSS "
                                     "(2x2, 3x3, 4x4 samples per pixel)")
            if ss != 1:
                raise SceneError(f"anti-aliasing mode {mode!r}: supersampling must be given once")
            ss = n
        else:
            raise SceneError(f"unknown anti-aliasing mode {mode!r}: use noAA, 2xMS, 4xMS, 8xMS, 4xSS, 9xSS, "
                             "16xSS or a combination such as 4xSS+8xMS")
    return AAMode(ss, ms)


def lod_divisor(mode, max_samples: int | None = None, msaa_lod: bool = False) -> float:
    """Threshold divisor of an AA mode (``AAMode.divisor``): 2 for 4xSS and 4xSS+8xMS, 1 for 8xMS;
    with ``msaa_lod`` sqrt(samples per pixel): sqrt(8) for 8xMS, sqrt(32) for 4xSS+8xMS. With
    ``max_samples`` the multisample count is first capped to what the device supports."""
    aa = parse_aa(mode)
    if max_samples is not None and aa.msaa > 1:
        aa = AAMode(aa.ss, cap_samples(aa.msaa, max_samples))
    return aa.divisor(msaa_lod)


# the hybrid tiers, coarsest first: the thesis's three for tess, supersampled key buffers for points
TESS_TIERS = (AAMode(), AAMode(1, 8), AAMode(2, 8))
POINT_TIERS = (AAMode(), AAMode(2), AAMode(4))


def hybrid_tiers(variant: str, max_samples: int | None = None) -> tuple[AAMode, ...]:
    """The tiers of ``aa = "hybrid"`` for ``variant`` ("tess": multisampling capped to
    ``max_samples``; the point variants: supersampling only)."""
    if variant != "tess":
        return POINT_TIERS
    if max_samples is None:
        return TESS_TIERS
    return tuple(AAMode(t.ss, cap_samples(t.msaa, max_samples)) for t in TESS_TIERS)


def tier_divisors(tiers, msaa_lod: bool = False) -> tuple[tuple[float, float], ...]:
    """Tiers 1 and 2's (LOD threshold divisor, spot-check scale): the divisor as the uniform mode of
    the tier would divide (``AAMode.divisor``: its supersampling, with ``msaa_lod`` also sqrt(msaa);
    2 and 4 for points), the scale its samples per pixel side, sqrt of its samples per pixel (the
    thesis's guideline; sqrt(8) and sqrt(32) for tess): the spot check looks for detail smaller than
    the tier's samples can show."""
    return tuple((t.divisor(msaa_lod), t.divisor(msaa_lod=True)) for t in tiers[1:])


def cap_samples(requested: int, max_samples: int) -> int:
    n = requested
    while n > 1 and n > max_samples:
        n //= 2
    return max(n, 1)


def supersampling_only(mode) -> int:
    """The supersampling factor of ``mode`` for a renderer that cannot multisample (the points
    variant; "hybrid" is its tiers, POINT_TIERS); a SceneError names the mode if it multisamples."""
    aa = parse_aa(mode)
    if aa.msaa > 1:
        raise SceneError(f"anti-aliasing {mode!r}: the points variant supersamples only (4xSS, 9xSS, "
                         f"16xSS) or draws \"hybrid\"; multisampling is a mode of the tess variant")
    return aa.ss


# points-ssaa's local framebuffer holds 2x2 or 3x3 subsamples (SsaaSettings.ss)
LFB_MODES = {"4xSS": 2, "9xSS": 3}


def local_framebuffer_ss(mode) -> int:
    """The subsamples per pixel side the points-ssaa variant draws ``mode`` with (2 for 4xSS, 3 for
    9xSS); any other mode is a SceneError naming the modes it can do."""
    aa = parse_aa(mode)
    if aa.msaa == 1 and aa.ss in LFB_MODES.values():
        return aa.ss
    raise SceneError(f"anti-aliasing {aa.name if isinstance(mode, AAMode) else mode!r}: the points-ssaa variant "
                     f"draws {' or '.join(LFB_MODES)} only (2x2 or 3x3 subsamples in its local framebuffer); "
                     "use the points variant for noAA or 16xSS and the tess variant for multisampling")
