"""State by lifetime. Per scene (``SceneState``): the plan, each group's subscene and renderer
state (compiled programs, uploads, LOD buffers), kept while the scene lives and reused across its
versions when a group draws the same functions. Per view: the key buffers of each (size,
subsamples, layers) and their downsamples (a multi-view frame's keys have a layer per view). Per
frame: FrameStats (built by the driver)."""
from __future__ import annotations

from paramlod.device.context import cl_device
from paramlod.errors import SceneError
from paramlod.pipeline.plan import plan
from paramlod.renderers.registry import KINDS
from paramlod.renderers.targets import Downsample, KeyBuffer, Upsample

MAX_SIDE = 16384   # subsamples per side of a supersampled key buffer


class SceneState:
    def __init__(self):
        self._plan_key = None
        self.passes = []
        self.subscenes: dict = {}      # Group -> its subscene
        self._by_group: dict = {}      # Group -> its renderer state, for the current plan
        self._renderers: dict = {}     # (variant, aa, functions) -> renderer state
        # (w, h, tag, layers) -> KeyBuffer; tag: the frame's keys' ss, or -factor for the keys of
        # a supersampled target (a hybrid pass has one per tier)
        self._keys: dict = {}
        self._downsample: dict = {}    # ss -> Downsample
        self._upsample: dict = {}      # ratio -> Upsample

    def update(self, scene, variant, settings):
        """Plan the scene again when it, the frame's variant or the default AA changed."""
        key = (scene._version, variant, settings.points.supersample, settings.points.hybrid, settings.tess.aa)
        if key != self._plan_key:
            self.passes = plan(scene, variant, settings)
            self.subscenes = {g: scene.subscene(**{KINDS[g.spec.kind].scene_field: g.objects})
                              for p in self.passes for g in p.groups}
            self._by_group = {}
            self._plan_key = key
        for sub in self.subscenes.values():
            sub.time = scene.time
        return self.passes

    def renderer(self, group):
        """The renderer state that draws ``group``: made on first use and kept for the plan; a new
        plan reuses the state of a group of the same variant, AA mode and functions (programs, LOD
        buffers, uploads)."""
        state = self._by_group.get(group)
        if state is None:
            functions = tuple(self.subscenes[group].functions())
            key = (group.spec.variant, group.aa, functions)
            state = self._renderers.get(key)
            if state is None:
                state = self._renderers[key] = group.spec.factory(list(functions))
            self._by_group[group] = state
        return state

    def renderer_states(self) -> list:
        """The renderer states made so far (for memory figures)."""
        return list(self._renderers.values())

    def keys(self, size, ss: int = 1, layers: int = 1) -> KeyBuffer:
        """The frame-sized key buffers of a pass with ``ss`` subsamples per pixel side (``layers``:
        one per view)."""
        return self._buffer(size[0], size[1], ss, layers)

    def subsample_keys(self, size, ss: int, layers: int = 1) -> KeyBuffer:
        """The key buffers ``ss`` times the frame's size that a supersampled pass draws into."""
        w, h = size[0] * ss, size[1] * ss
        if max(w, h) > MAX_SIDE:
            raise SceneError(f"points supersample {ss} at {size[0]}x{size[1]} needs {w}x{h} subsamples, more "
                             f"than {MAX_SIDE} a side; use a smaller factor or frame")
        return self._buffer(w, h, -ss, layers)

    def downsample(self, ss: int) -> Downsample:
        if ss not in self._downsample:
            self._downsample[ss] = Downsample(ss)
        return self._downsample[ss]

    def upsample(self, ratio: int) -> Upsample:
        if ratio not in self._upsample:
            self._upsample[ratio] = Upsample(ratio)
        return self._upsample[ratio]

    def _buffer(self, w, h, tag, layers) -> KeyBuffer:
        key = (w, h, tag, layers)
        buf = self._keys.get(key)
        if buf is None:
            # free buffers of other sizes first (a resized view keeps only its own)
            for k in [k for k in self._keys if k[2] == tag and k != key]:
                self._keys.pop(k)
            limit = cl_device().device.max_mem_alloc_size
            if w * h * layers * 8 > limit:
                views = f" x {layers} views" if layers > 1 else ""
                raise SceneError(f"key buffers of {w}x{h} keys{views} need {w * h * layers * 8 / 2**20:.0f} MiB each, "
                                 f"more than this device allocates at once ({limit / 2**20:.0f} MiB); use fewer views, "
                                 "a smaller frame or less supersampling")
            buf = self._keys[key] = KeyBuffer(w, h, max(tag, 1), layers)
        return buf
