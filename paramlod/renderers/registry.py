"""What draws what: object kinds and renderers declare themselves here (as pygfx picks a render
function by object and material type), and the frame plan looks them up.

An object kind ("parametric", "surfels", "mesh") names the Scene attribute that holds its objects
and the variant that draws them by default (or with a frame variant of another kind). A renderer names its variant, the kind it draws, the
``RenderSettings`` field that holds its settings, its target ("keys": the shared 64-bit key
buffers, OpenCL; "gl": its own OpenGL targets resolved into a host Frame), and a factory that
makes its per-scene state from the functions of the objects it draws.

Every renderer follows one protocol, driven by ``paramlod.pipeline``:
``prepare(scene, camera, settings)`` (uploads; ``camera`` is the one its target is drawn with),
``enqueue(target, settings)`` (its work, without waiting; a "gl" renderer is given the camera and
returns its Frame), ``collect()`` (enqueue the copies of its counters), then, after the driver's
one wait, ``grow(settings)`` (True if a buffer grew and the frame must be drawn again) and
``stats()`` (its counters and device times). A "keys" renderer whose state class sets
``tiered = True`` draws hybrid anti-aliasing's tiers (``aa = "hybrid"``): the driver calls
``enqueue(target, settings, tier=k)`` once per tier, coarsest first, each with that tier's key
buffers; other key renderers of a hybrid pass draw once, into tier 0.

Multi-view frames (``paramlod.render_views``): a renderer registered with ``multiview=True`` is
given a ``paramlod.core.views.Views`` as its camera (N cameras of one size); a "keys" renderer
draws view v into layer v of the layered key buffers (``KeyBuffer.layers``), a "gl" renderer
returns one Frame per view. ``stats()`` may add ``"views"``: one dict of counters per view.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from paramlod.errors import SceneError


@dataclass(frozen=True)
class ObjectKind:
    name: str
    default_variant: str   # the variant that draws an object of this kind when none is asked for
    scene_field: str       # the Scene attribute holding its objects, and Scene.subscene's keyword
    # frame variant of another kind -> the variant of this kind that goes with it ({"tess": "meshlets-gl"})
    follows: dict = field(default_factory=dict)

    def objects(self, scene) -> list:
        return getattr(scene, self.scene_field)

    def variant_for(self, frame_variant: str | None) -> str:
        """The variant that draws an object of this kind that has none, in a frame of ``frame_variant``."""
        spec = RENDERERS.get(frame_variant) if isinstance(frame_variant, str) else None
        if spec is not None and spec.kind == self.name:
            return frame_variant
        return self.follows.get(frame_variant, self.default_variant)


@dataclass(frozen=True)
class RendererSpec:
    variant: str
    kind: str
    factory: Callable      # (functions, record=False) -> renderer state for one scene
    settings: str          # field of RenderSettings with this renderer's settings
    target: str            # "keys" or "gl"
    settings_type: type = object   # the class of those settings
    description: str = ""
    takes_aa: str = "ss"   # the part of an AA mode it takes: "ss" (supersampling only) or "all"
    multiview: bool = False   # draws several views from one LOD pass (render_views)


KINDS: dict[str, ObjectKind] = {}
RENDERERS: dict[str, RendererSpec] = {}


def register_kind(kind: ObjectKind) -> ObjectKind:
    KINDS[kind.name] = kind
    return kind


def register_renderer(spec: RendererSpec) -> RendererSpec:
    RENDERERS[spec.variant] = spec
    return spec


def variants(kind: str | None = None) -> tuple[str, ...]:
    """The registered variants (of one object kind)."""
    return tuple(v for v, s in RENDERERS.items() if kind is None or s.kind == kind)


def renderer(variant: str, kind: str | None = None) -> RendererSpec:
    """The renderer of ``variant`` (for objects of ``kind``), or a SceneError naming the choices."""
    spec = RENDERERS.get(variant) if isinstance(variant, str) else None
    if spec is None or (kind is not None and spec.kind != kind):
        choices = ", ".join(variants(kind)) or "none"
        what = f" for {kind} objects" if kind else ""
        raise SceneError(f"unknown variant {variant!r}{what} (available: {choices})")
    return spec


def settings_factory(variant: str):
    """A default_factory for the settings of ``variant``'s renderer (RenderSettings' fields)."""
    return lambda: renderer(variant).settings_type()
