"""``paramlod view``: a window (moderngl-window) that draws the frame pipeline every frame.

Per frame: reload what changed on disk -> move the camera by the held keys -> ``render`` (the one
driver; its per-scene state keeps frames after the first warm) -> the frame's 8-bit image, the
only copy to the host (3 bytes a pixel; OpenCL and the window's OpenGL context share nothing) ->
a texture of the window's context -> a full-screen triangle strip, the HUD blended over it ->
swap (at the display's rate, vsync). The window's context is not paramlod's: the tess and
meshlets-gl renderers draw into paramlod's own EGL context (paramlod.device.context), which is
made current around the render and the window's again afterwards.

Events come through moderngl-window's callbacks (key_event_func, mouse_drag_event_func, ...),
the same in a real window, the headless backend (EGL) and the scripted mode, so the tests drive
exactly what a user drives.
"""
from __future__ import annotations

import copy
import os
import time
from pathlib import Path

import numpy as np

from paramlod.app.args import check_folder
from paramlod.app.dist import write_video
from paramlod.device.context import gl_context
from paramlod.errors import DeviceError, ParamlodError, SceneError
from paramlod.pipeline.driver import render
from paramlod.renderers.registry import variants
from paramlod.scene.framing import scene_box
from paramlod.viewer import hud
from paramlod.viewer.controls import Controls
from paramlod.viewer.reload import POLL_SECONDS, Source, Watcher, cli_message
from paramlod.viewer.script import Recorder, Script, load_script

AA_MODES = ("noAA", "4xSS", "9xSS", "8xMS", "4xSS+8xMS")
THRESHOLD_STEP = 1.25
HUD_SECONDS = 0.25         # how often the HUD's timings are redrawn
TIME_STEP = 0.1            # seconds of scene time per , or . press
INSTALL = "pip install paramlod[viewer]"
NO_DISPLAY = ("no display to open a window on (DISPLAY is not set); without one use the headless modes: "
              "`paramlod view SOURCE --script FILE --record DIR` (EGL, no window), `paramlod render SCENE.toml`, "
              "or pl.show(scene) in Jupyter")

_VERTEX = """
#version 330
out vec2 uv;
void main() {
    vec2 p = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
    uv = vec2(p.x, 1.0 - p.y);          // images are stored top row first
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""
_FRAGMENT = """
#version 330
uniform sampler2D image;
in vec2 uv;
out vec4 colour;
void main() { colour = texture(image, uv); }
"""


def _import_mglw():
    try:
        import moderngl_window
    except ImportError:
        raise ParamlodError(f"the viewer needs moderngl-window: {INSTALL}") from None
    return moderngl_window


def _named_keys():
    """Key codes for the headless backend, which has none of its own: each key is its name."""
    from moderngl_window.context.base import BaseKeys

    names = {k: k for k in dir(BaseKeys) if k.isupper() and not k.startswith("ACTION")}
    return type("NamedKeys", (BaseKeys,), {**names, "ACTION_PRESS": "ACTION_PRESS",
                                           "ACTION_RELEASE": "ACTION_RELEASE"})


def open_window(size, headless: bool = False, vsync: bool = True, title: str = "paramlod"):
    """A moderngl-window window: pyglet on a display, or the headless backend (EGL). Raises
    ParamlodError with the alternatives when there is no display or no EGL."""
    mglw = _import_mglw()
    if headless:
        cls = mglw.get_local_window_cls("headless")
        try:
            win = cls(title=title, size=tuple(size), vsync=False, gl_version=(3, 3), backend="egl")
        except Exception as exc:   # glcontext raises plain Exceptions for a missing EGL
            raise ParamlodError(f"no headless OpenGL (EGL) context: {exc}; install Mesa's EGL (Debian: libegl1 "
                                "libegl-mesa0) or an NVIDIA driver, or use `paramlod render` (OpenCL only)") from None
        win.keys = _named_keys()
        return win
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ParamlodError(NO_DISPLAY)
    try:   # importing pyglet's window already connects to the display
        cls = mglw.get_local_window_cls("pyglet")
        return cls(title=title, size=tuple(size), vsync=vsync, gl_version=(3, 3), resizable=True)
    except Exception as exc:   # pyglet: no such display, no GLX
        raise ParamlodError(f"cannot open a window on display {os.environ.get('DISPLAY', '')!r}: "
                            f"{type(exc).__name__}: {exc}; {NO_DISPLAY.split('; ', 1)[1]}") from None


def object_colours(ids: np.ndarray, rgb8: np.ndarray) -> np.ndarray:
    """A colour per object id (golden-ratio hues), shaded by the frame's brightness; background kept."""
    h = (ids.astype(np.float64) * 0.618033988749895) % 1.0
    k = np.stack([(5 + h * 6) % 6, (3 + h * 6) % 6, (1 + h * 6) % 6], axis=-1)
    hue = 1 - np.clip(np.minimum(k, 4 - k), 0, 1) * 0.75
    lum = rgb8.astype(np.float64).mean(axis=-1, keepdims=True) / 255.0
    out = np.where(ids[..., None] > 0, hue * (0.3 + 0.7 * lum) * 255, rgb8)
    return out.astype(np.uint8)


class Viewer:
    """The viewer's state and frame loop. ``window``: a moderngl-window window (``open_window``);
    ``source``: a reload.Source (loaded now: a source that fails to load raises its message)."""

    def __init__(self, source: Source, window, hud_on: bool = True, screenshots="out/screenshots", loaded=None):
        self.source, self.window = source, window
        self.loaded = loaded or source.load()
        self.watcher = Watcher(self.loaded.watched)
        self.error: str | None = None
        self.hud_on = hud_on
        self.screenshots = Path(screenshots)
        self.notes: list[str] = []
        self.time, self.paused = 0.0, True
        self.quit = False
        self.image: np.ndarray | None = None      # the last good image shown (rgb8)
        self.frame = None                         # the last good Frame
        self.timings = {"fps": 0.0}
        self._fps_t, self._fps_n, self._last_poll = time.perf_counter(), 0, 0.0
        self._tex = self._hud_tex = None
        self._hud_key, self._hud_t, self._hud_timings, self._hud_stats = None, 0.0, {}, None
        self._pbo = None
        self._adopt(self.loaded, first=True)
        self._gl_setup()
        self._connect()

    # --- the source --------------------------------------------------------------------------
    def _adopt(self, loaded, first: bool = False) -> None:
        """Draw ``loaded`` from now on; the camera and the user's choices are kept on a reload."""
        self.loaded = loaded
        self.base_settings = loaded.settings
        if first:
            lo, hi = loaded.box if loaded.box is not None else scene_box(loaded.scene)
            self.controls = Controls.for_box(loaded.camera, lo, hi, loaded.up)
            self.variant = loaded.variant
            self.aa = self._aa_label(loaded.settings)
            self.threshold_scale = 1.0
            self.debug = "material"
            self.forced_variant = False
            if loaded.animation:   # an animated scene plays from its start; others stay still (no re-uploads)
                self.time, self.paused = float(loaded.animation["t0"]), False
        elif self.forced_variant:   # V chose the variant of every object: the reloaded scene's too
            self._clear_object_variants()
        self.watcher.watch(loaded.watched)
        self._settings()

    @staticmethod
    def _aa_label(settings) -> str:
        return str(settings.tess.aa or "noAA")

    def _kinds(self) -> tuple[bool, bool]:
        s = self.loaded.scene
        return bool(s.objects or s.surfels), bool(s.meshes)

    def _settings(self) -> None:
        """The frame's settings: the source's, with the AA mode, threshold and colouring chosen here."""
        st = copy.deepcopy(self.base_settings)
        if self.aa != self._aa_label(self.base_settings):
            try:
                st.apply_aa(self.aa, points_only=self.variant == "points", variant=self.variant)
            except ParamlodError:   # a reloaded scene whose settings the chosen mode does not fit: its own
                st, self.aa = copy.deepcopy(self.base_settings), self._aa_label(self.base_settings)
        st.lod.threshold = tuple(t * self.threshold_scale for t in st.lod.threshold)
        st.mesh.threshold_px = st.mesh.threshold_px * self.threshold_scale
        st.mesh.color_by = self.debug if self.debug in ("cluster", "level") else st.mesh.color_by
        if self.variant == "points" and self.debug in ("patch", "level"):   # the direct points draw these
            st.points.color_by = self.debug
        self.settings = st

    def reload(self, changed=()) -> bool:
        """Load the source again; on failure keep the last good one and show the CLI's message."""
        folders = any(p != self.source.path for p in changed) and self.source.kind != "plugin"
        try:
            loaded = self.source.load(folders_changed=folders)
        except (ParamlodError, RecursionError) as exc:
            self.error = cli_message(exc)
            # keep watching what was watched, and the source itself (its plugins may be what broke)
            self.watcher.watch([*self.watcher.seen])
            return False
        self.error = None
        self._adopt(loaded)
        return True

    def poll(self, force: bool = False) -> None:
        now = time.perf_counter()
        if force or now - self._last_poll >= POLL_SECONDS:
            self._last_poll = now
            changed = self.watcher.changed()
            if changed:
                self.reload(changed)

    # --- events (the window's callbacks and the script call these) --------------------------
    def _connect(self) -> None:
        w = self.window
        names = [k for k in dir(w.keys) if k.isupper() and not k.startswith("ACTION")]
        self.key_names = {getattr(w.keys, k): k for k in names if getattr(w.keys, k) != "undefined"}
        w.key_event_func = self._key_event
        w.mouse_drag_event_func = lambda x, y, dx, dy: self.controls.mouse_look(dx, dy)
        w.mouse_scroll_event_func = lambda x_offset, y_offset: self.controls.wheel(y_offset)
        w.close_func = self._close
        w.resize_func = lambda width, height: None   # the next frame renders at the new size

    def _close(self) -> None:
        self.quit = True

    def _key_event(self, key, action, modifiers) -> None:
        name = self.key_names.get(key)
        if name is not None:
            self.on_key(name, action == self.window.keys.ACTION_PRESS)

    def on_key(self, name: str, pressed: bool) -> None:
        action = self.controls.key(name, pressed)
        if action is None or self.controls.camera_action(action):
            return
        if action == "variant":
            self._next_variant()
        elif action == "aa":
            self._next_aa()
        elif action in ("coarser", "finer"):
            self.threshold_scale *= THRESHOLD_STEP if action == "coarser" else 1 / THRESHOLD_STEP
            self._settings()
        elif action == "debug":
            self._next_debug()
        elif action == "pause":
            self.paused = not self.paused
        elif action in ("time_back", "time_forward"):
            self.time += TIME_STEP if action == "time_forward" else -TIME_STEP
        elif action == "screenshot":
            self.screenshot()
        elif action == "next_function":
            if self.source.kind == "plugin":
                self.source.function_index += 1
                self.reload()
        elif action == "hud":
            self.hud_on = not self.hud_on
        elif action == "quit":
            self.quit = True

    def _next_variant(self) -> None:
        parametric, meshes = self._kinds()
        choices = list(variants("parametric" if parametric else "mesh"))
        k = choices.index(self.variant) if self.variant in choices else -1
        self.variant = choices[(k + 1) % len(choices)]
        self.forced_variant = True
        self._clear_object_variants()
        self._fit_aa()

    def _clear_object_variants(self) -> None:
        """The frame's variant draws every object (as ``paramlod render --variant`` does)."""
        scene = self.loaded.scene
        if any(o.variant or o.aa for o in [*scene.objects, *scene.meshes]):
            for o in [*scene.objects, *scene.meshes]:
                o.variant = o.aa = None
            scene.touch()

    def _next_aa(self) -> None:
        k = AA_MODES.index(self.aa) if self.aa in AA_MODES else -1
        for step in range(1, len(AA_MODES) + 1):
            if self._try_aa(AA_MODES[(k + step) % len(AA_MODES)]):
                return

    def _try_aa(self, mode: str) -> bool:
        try:
            copy.deepcopy(self.base_settings).apply_aa(mode, points_only=self.variant == "points", variant=self.variant)
        except SceneError:
            return False
        self.aa = mode
        self._settings()
        return True

    def _fit_aa(self) -> None:
        """Keep the AA mode when the new variant can draw it, else the first one it can."""
        if not self._try_aa(self.aa):
            for mode in AA_MODES:
                if self._try_aa(mode):
                    break

    def _next_debug(self) -> None:
        parametric, meshes = self._kinds()
        direct = parametric and self.variant == "points"   # per patch and per LOD step: the direct points
        modes = (["material", "object"] + (["patch"] if direct else []) + (["cluster"] if meshes else [])
                 + (["level"] if meshes or direct else []))
        self.debug = modes[(modes.index(self.debug) + 1) % len(modes)] if self.debug in modes else "material"
        self._settings()

    def screenshot(self) -> list[Path]:
        """The last frame as PNG and EXR (colour, depth, normal, object id) in the screenshot folder."""
        if self.frame is None:
            return []
        folder = check_folder(self.screenshots, "screenshot folder", create=True)
        k = 0
        while (folder / f"view_{k:04d}.png").exists() or (folder / f"view_{k:04d}.exr").exists():
            k += 1
        out = [self.frame.save(folder / f"view_{k:04d}.png"), self.frame.save(folder / f"view_{k:04d}.exr")]
        self.notes = [f"saved {out[0]} and {out[1].name}"]
        return out

    # --- one frame -----------------------------------------------------------------------------
    def render_size(self) -> tuple[int, int]:
        w, h = self.window.buffer_size
        return max(1, int(w)), max(1, int(h))

    def state(self) -> dict:
        parametric, meshes = self._kinds()
        th = self.settings.lod.threshold[0] if parametric else self.settings.mesh.threshold_px
        return {"variant": self.variant, "aa": self.aa, "threshold": th, "debug": self.debug,
                "mode": self.controls.mode, "time": self.time, "paused": self.paused,
                "source": self.loaded.label, "notes": self.notes}

    def draw_frame(self, dt: float, camera=None) -> None:
        """One frame: reload, move, render, present. ``camera``: draw this one instead of the
        controls' (the bench compares the same frames)."""
        t0 = time.perf_counter()
        self.poll()
        self.controls.step(dt)
        if not self.paused:
            anim = self.loaded.animation
            span = anim["t1"] - anim["t0"] if anim else 0.0
            self.time += -dt if span < 0 else dt   # t1 < t0 plays the animation backwards
            if span and (self.time - anim["t0"]) / span > 1:   # past t1: loop [t0, t1]
                self.time = anim["t0"] + (self.time - anim["t0"]) % span
        camera = camera or self.controls.camera(self.render_size())
        t1 = time.perf_counter()
        lod_ms = 0.0
        try:
            frame = self._render(camera)
            img = frame.rgb8()
            if self.debug == "object":
                img = object_colours(frame.object_id, img)
            self.frame, self.image = frame, img
            lod_ms = float(frame.stats["ms"].get("lod", 0.0))
            if self.error and self.error.startswith("render: "):
                self.error = None
        except (ParamlodError, RecursionError) as exc:   # e.g. a capacity the scene outgrew: shown, not fatal
            self.error = "render: " + cli_message(exc)
        t2 = time.perf_counter()
        self.present()
        t3 = time.perf_counter()
        render_ms = (t2 - t1) * 1e3
        self.timings.update(frame=(t3 - t0) * 1e3, lod=lod_ms, render=max(render_ms - lod_ms, 0.0),
                            present=(t3 - t2) * 1e3, render_total=render_ms)
        self._fps_n += 1
        if t3 - self._fps_t >= 0.5:
            self.timings["fps"] = self._fps_n / (t3 - self._fps_t)
            self._fps_t, self._fps_n = t3, 0

    def _render(self, camera):
        """``render`` with paramlod's own GL context current (its GL renderers assume it)."""
        self._paramlod_current()
        return render(self.loaded.scene, camera, self.variant, self.settings, time=self.time)

    @staticmethod
    def _paramlod_current() -> None:
        """paramlod's EGL context current: outside ``present`` it is, so that any render in this
        process (a test's, the bench's) finds the context its renderers were made in."""
        try:
            gl_context().__enter__()
        except DeviceError:
            pass   # no EGL: the OpenCL variants still draw; a GL variant reports it when asked for

    def _window_current(self) -> None:
        native = getattr(self.window, "_window", None)   # pyglet's window: GLX
        if native is not None and hasattr(native, "switch_to"):
            native.switch_to()
        else:   # the headless backend's EGL context
            self.window.ctx.__enter__()

    def finish(self) -> None:
        """Wait for the window's GL work (the bench counts it)."""
        self._window_current()
        self.window.ctx.finish()
        self._paramlod_current()

    # --- presenting ------------------------------------------------------------------------------
    def _gl_setup(self) -> None:
        self._window_current()
        ctx = self.window.ctx
        self.prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self.vao = ctx.vertex_array(self.prog, [])
        self._paramlod_current()

    def _texture(self, tex, size, components=3):
        if tex is None or tex.size != tuple(size) or tex.components != components:
            if tex is not None:
                tex.release()
            tex = self.window.ctx.texture(tuple(size), components)
            tex.filter = (self.window.ctx.NEAREST, self.window.ctx.NEAREST)
        return tex

    def present(self) -> None:
        import moderngl

        w = self.window
        ctx = w.ctx
        self._window_current()
        w.use()
        bw, bh = self.render_size()
        ctx.viewport = (0, 0, bw, bh)
        bg = self.loaded.scene.background
        ctx.clear(*bg, 1.0)
        if self.image is not None:
            h, wd = self.image.shape[:2]
            self._tex = self._texture(self._tex, (wd, h))
            # through a pixel buffer: the driver copies from it on the GPU's side (H200: 1.2 ms
            # against 2-3 ms for a direct write of a 1920x1080 RGB image)
            data = np.ascontiguousarray(self.image)
            if self._pbo is None or self._pbo.size != data.nbytes:
                if self._pbo is not None:
                    self._pbo.release()
                self._pbo = ctx.buffer(reserve=data.nbytes)
            self._pbo.write(data)
            self._tex.write(self._pbo)
            self._tex.use(0)
            self.vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        if self.hud_on or self.error:
            now = time.perf_counter()
            # numbers that change every frame (timings, counts) are shown 4 times a second: drawing the
            # text with Pillow takes about 8 ms at 1920 px (H200 host), more than the frame
            if now - self._hud_t >= HUD_SECONDS or self._hud_stats is None:
                self._hud_t, self._hud_timings = now, dict(self.timings)
                self._hud_stats = self.frame.stats if self.frame is not None else None
            text = hud.lines(self.state(), self._hud_stats, self._hud_timings,
                             self.error) if self.hud_on else [(line, hud.ERROR_COLOUR) for line in self.error.splitlines()]
            key = (tuple(t for t, _ in text), bw)
            if key != self._hud_key:   # Pillow draws the text only when it changed
                img = hud.image(text, bw)
                self._hud_tex = self._texture(self._hud_tex, (img.shape[1], img.shape[0]), 4)
                self._hud_tex.write(np.ascontiguousarray(img))
                self._hud_key, self._hud_size = key, (img.shape[1], img.shape[0])
            hw, hh = self._hud_size
            ctx.viewport = (0, max(bh - hh, 0), hw, hh)
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
            self._hud_tex.use(0)
            self.vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
            ctx.disable(moderngl.BLEND)
            ctx.viewport = (0, 0, bw, bh)
        w.swap_buffers()
        self._paramlod_current()

    def window_image(self) -> np.ndarray:
        """What the window shows now, (h, w, 3) uint8 top row first (for tests and the bench)."""
        self._window_current()
        fbo = self.window.fbo
        w, h = fbo.size
        data = fbo.read(components=3)
        self._paramlod_current()
        return np.frombuffer(data, np.uint8).reshape(h, w, 3)[::-1]

    # --- loops -----------------------------------------------------------------------------------
    def run(self, frames: int | None = None, recorder: Recorder | None = None) -> int:
        """Until the window closes (or ``frames`` frames), at the display's rate."""
        last = time.perf_counter()
        n = 0
        while not (self.quit or self.window.is_closing) and (frames is None or n < frames):
            now = time.perf_counter()
            self.draw_frame(min(now - last, 0.25))   # a stall (a reload, a first compile) is no leap
            last = now
            if recorder is not None and self.image is not None:
                recorder.write(self.image)
            n += 1
        return n

    def run_script(self, script: Script, frames: int | None = None, recorder: Recorder | None = None,
                   video=None) -> int:
        """The script's frames at its fixed time step: events first, then its camera, then the frame."""
        n = frames or script.frames
        dt = 1.0 / script.fps
        for i in range(n):
            if self.quit or self.window.is_closing:
                break
            for e in script.events_at(i):
                if e.kind == "key":
                    self.on_key(e.key, e.pressed)
                elif e.kind == "drag":
                    self.window.mouse_drag_event_func(0, 0, *e.value)
                else:
                    self.window.mouse_scroll_event_func(0.0, e.value[0])
            pose = script.camera_at(i)
            if pose is not None:
                eye, target = pose
                self.controls.set_view(eye, target - eye)
            self.poll(force=True)
            self.draw_frame(dt)
            if recorder is not None and self.image is not None:
                recorder.write(self.image)
        if video is not None and recorder is not None and recorder.paths:
            write_video(video, recorder.paths, script.fps)
        return n

    def close(self) -> None:
        """Destroy the window; paramlod's context stays current for the rest of the process."""
        self._window_current()
        self.window.destroy()
        self._paramlod_current()


def view(spec, size=None, variant=None, aa=None, script=None, record=None, frames=None, video=None,
         headless: bool | None = None, vsync: bool = True, overwrite: bool = False) -> int:
    """``paramlod view``: load ``spec`` (errors as the CLI gives them), open the window, run."""

    scr = load_script(script) if script else None
    if video is not None:
        if Path(video).suffix.lower() not in (".gif", ".mp4"):
            raise ParamlodError(f"--video {video}: unknown type {Path(video).suffix or '(none)'!r} (use .gif or .mp4)")
        if record is None:
            raise ParamlodError("--video is made from the recorded frames; add --record DIR")
    recorder = Recorder(record, overwrite) if record else None
    source = Source(spec, size, variant, aa)
    if headless is None:   # recording or a script with a frame count needs no display
        headless = not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) and (
            record is not None or frames is not None or scr is not None)
    loaded_first = source.load()          # the load error before any window appears
    w, h = size or tuple(loaded_first.camera.size)
    window = open_window((w, h), headless=headless, vsync=vsync and scr is None,
                         title=f"paramlod view {Path(str(spec)).name}")
    viewer = None
    try:
        viewer = Viewer(source, window, loaded=loaded_first)
        if scr is not None:
            n = viewer.run_script(scr, frames, recorder, video)
        else:
            n = viewer.run(frames, recorder)
            if video is not None and recorder is not None and recorder.paths:
                write_video(video, recorder.paths, 30.0)
    finally:
        if viewer is not None:
            viewer.close()
        else:
            window.destroy()
    if recorder is not None:
        print(f"{n} frames, {len(recorder.paths)} written to {recorder.folder}" + (f", video {video}" if video else ""))
    return 0
