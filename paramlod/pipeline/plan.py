"""The plan of a frame: a scene's objects grouped by (kind, variant, AA mode), each group drawn
by its registered renderer, and the groups placed in passes (targets), coarsest first.

A "keys" pass is one set of 64-bit key buffers (``ss`` x ``ss`` subsamples per pixel) that every
key renderer of the pass draws into; a "gl" pass is one renderer's own OpenGL targets. Surfels
join the pass of the direct point variant (else one of ``settings.points.supersample``).

A hybrid keys pass (``aa = "hybrid"``) has ``tiers``: the subsamples per pixel side of each tier's
key buffers (POINT_TIERS: 1, 2, 4), drawn coarsest first, each finer one starting from a copy of
the coarser; its renderers draw each patch in the tier the LOD stage gave it, the others (surfels,
meshes) in tier 0."""
from __future__ import annotations

from dataclasses import dataclass

from paramlod.errors import SceneError
from paramlod.renderers.aa import POINT_TIERS, parse_aa, supersampling_only
from paramlod.renderers.registry import KINDS, RENDERERS, RendererSpec, renderer


@dataclass(frozen=True, eq=False)
class Group:
    spec: RendererSpec
    aa: str | None       # the objects' own AA mode (None: the frame's settings)
    objects: tuple       # the scene's objects this group draws, in scene order


@dataclass
class Pass:
    target: str          # "keys" or "gl"
    ss: int              # subsamples per pixel side of a keys pass (its finest tier's); 1 for gl
    groups: list
    tiers: tuple = ()    # a hybrid keys pass: each tier's subsamples per pixel side, coarsest first


def check_variant(variant) -> None:
    if variant is not None:
        renderer(variant)   # a SceneError naming the registered variants


def multiview_variants() -> tuple[str, ...]:
    """The variants that draw several views from one LOD pass (render_views)."""
    return tuple(v for v, s in RENDERERS.items() if s.multiview)


def plan(scene, variant, settings) -> list[Pass]:
    """The passes that draw ``scene``; ``variant``: the frame's variant for objects without one
    (None: each kind's default; the driver has checked it)."""
    groups: dict[tuple, list] = {}
    for kind in KINDS.values():
        for obj in kind.objects(scene):
            v = getattr(obj, "variant", None) or kind.variant_for(variant)
            spec = renderer(v, kind.name)
            groups.setdefault((spec.variant, getattr(obj, "aa", None)), []).append(obj)
    keys: dict[tuple, list] = {}   # (ss, hybrid) -> the groups of that keys pass
    passes = []
    surfels = []
    for (v, aa), objs in groups.items():
        spec = renderer(v)
        group = Group(spec, aa, tuple(objs))
        if spec.target == "gl":
            passes.append(Pass("gl", 1, [group]))
            continue
        if spec.kind == "surfels":
            surfels.append(group)
            continue
        keys.setdefault(_key_ss(group, settings), []).append(group)
    if surfels:
        direct = [k for k, gs in keys.items() if any(g.spec.variant == "points" for g in gs)]
        keys.setdefault(direct[0] if direct else (settings.points.supersample, False), []).extend(surfels)
    tiers = tuple(t.ss for t in POINT_TIERS)
    passes += [Pass("keys", ss, gs, tiers if hybrid else ()) for (ss, hybrid), gs in keys.items()]
    return sorted(passes, key=lambda p: (p.target == "gl", p.ss, bool(p.tiers)))


def _key_ss(group: Group, settings) -> tuple[int, bool]:
    """(subsamples per pixel side, hybrid) of the keys pass that draws ``group``."""
    if group.spec.variant == "points-ssaa":
        if group.aa:
            raise SceneError(f"points-ssaa takes no per-object aa ({group.aa!r}): its subsamples are "
                             "settings.ssaa.ss ([ssaa] ss in a scene file)")
        return 1, False
    if group.aa is None:
        hybrid, ss = settings.points.hybrid, settings.points.supersample
    else:
        hybrid, ss = parse_aa(group.aa).hybrid, supersampling_only(group.aa)
    if hybrid:   # a renderer without tiers draws into the hybrid pass's tier 0
        return POINT_TIERS[-1].ss, True
    return ss, False
