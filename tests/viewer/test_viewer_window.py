"""The viewer's frame loop in moderngl-window's headless window (EGL), driven by real key and
mouse events through the window's callbacks: the same code path as in a window on a display."""
import time

import numpy as np
import pytest

import paramlod as pl
from paramlod.viewer import hud
from paramlod.viewer.app import Viewer, open_window
from paramlod.viewer.reload import POLL_SECONDS, Source, cli_message

SIZE = (64, 48)

PLUGIN = '''
from sympy import cos, pi, sin
from paramlod import parametric


@parametric(u=(0, pi), v=(0, 2 * pi), params={{"radius": 1.0}})
def live_blob(u, v, radius):
    """A blob whose shape the test edits."""
    return radius * sin(u) * cos(v) * {sx}, radius * sin(u) * sin(v), radius * cos(u)
'''


@pytest.fixture(scope="module")
def window():
    win = open_window(SIZE, headless=True)
    yield win
    win.destroy()


def press(win, key, pressed=True):
    """A key event as the window library delivers it: its key code, its action, modifiers."""
    win.key_event_func(getattr(win.keys, key), win.keys.ACTION_PRESS if pressed else win.keys.ACTION_RELEASE, None)


def tap(win, key):
    press(win, key)
    press(win, key, False)


def test_moving_forward_matches_a_camera_moved_the_same_way(window):
    v = Viewer(Source("sphere", SIZE), window, hud_on=False)
    v.draw_frame(0.0)
    first = v.image.copy()
    eye, forward, speed = v.controls.fly.eye.copy(), v.controls.fly.forward.copy(), v.controls.fly.speed
    press(window, "W")
    v.draw_frame(0.4)
    press(window, "W", False)
    moved = eye + forward * speed * 0.4
    cam = pl.Camera.look_at(moved, moved + forward, (0, 1, 0), v.loaded.camera.fov_y, SIZE,
                            near=v.controls.camera().near, far=v.controls.camera().far)
    expect = pl.render(v.loaded.scene, cam).rgb8()
    assert not np.array_equal(first, v.image)            # the view changed
    assert np.array_equal(v.image, expect)                # exactly as the moved camera renders it
    assert np.array_equal(v.window_image(), v.image)      # and that is what the window shows
    v.draw_frame(0.4)   # released: it stays
    assert np.array_equal(v.image, expect)


def test_mouse_drag_looks_and_the_wheel_changes_speed(window):
    v = Viewer(Source("sphere", SIZE), window, hud_on=False)
    f0, s0 = v.controls.fly.forward.copy(), v.controls.fly.speed
    window.mouse_drag_event_func(10, 10, 60, 0)
    window.mouse_scroll_event_func(0.0, 2.0)
    assert v.controls.fly.forward[0] > f0[0] + 0.1
    assert v.controls.fly.speed > s0
    tap(window, "TAB")
    assert v.controls.mode == "orbit"
    d0 = v.controls.orbit.distance
    window.mouse_scroll_event_func(0.0, 1.0)
    assert v.controls.orbit.distance < d0


def test_threshold_keys_change_the_patch_count(window):
    v = Viewer(Source("sphere", SIZE), window, hud_on=False)
    v.draw_frame(0.0)
    n0 = v.frame.stats["render_patches"]
    for _ in range(4):
        tap(window, "RIGHT_BRACKET")   # finer: a smaller threshold splits more
    v.draw_frame(0.0)
    finer = v.frame.stats["render_patches"]
    for _ in range(8):
        tap(window, "LEFT_BRACKET")
    v.draw_frame(0.0)
    coarser = v.frame.stats["render_patches"]
    assert finer > n0 >= coarser
    assert v.state()["threshold"] == pytest.approx(84.0 * 1.25 ** 4)


def test_variant_aa_debug_pause_and_hud_keys(window, tmp_path):
    v = Viewer(Source("sphere", SIZE), window, hud_on=True, screenshots=tmp_path / "shots")
    v.draw_frame(0.0)
    plain = v.image.copy()
    tap(window, "C")   # a colour per object
    v.draw_frame(0.0)
    assert v.debug == "object"
    ids = v.frame.object_id
    assert not np.array_equal(v.image[ids > 0], plain[ids > 0]) and np.array_equal(v.image[ids == 0], plain[ids == 0])
    for mode in ("patch", "level"):   # the direct points colour each render patch, then each LOD step
        tap(window, "C")
        v.draw_frame(0.0)
        assert v.debug == mode and v.settings.points.color_by == mode
        c = v.image[ids > 0].astype(float)
        hues = np.unique(np.round(c / (c.sum(axis=1, keepdims=True) + 1), 2), axis=0)
        assert len(hues) > 3, f"{mode}: one colour per patch / step expected, got {len(hues)} hues"
    tap(window, "C")
    assert v.debug == "material"
    tap(window, "B")   # the points variant supersamples: 4xSS
    v.draw_frame(0.0)
    assert v.aa == "4xSS" and v.frame.stats["supersample"] == 2
    tap(window, "V")
    v.draw_frame(0.0)
    assert v.variant == "points-ssaa" and v.frame.stats["variant"] == "points-ssaa"
    assert v.aa in ("4xSS", "9xSS")   # what the local framebuffer can draw
    tap(window, "SPACE")
    assert not v.paused
    v.draw_frame(0.5)
    assert v.time == pytest.approx(0.5)
    tap(window, "SPACE")
    tap(window, "COMMA")
    assert v.time == pytest.approx(0.4)
    text = " ".join(t for t, _ in hud.lines(v.state(), v.frame.stats, v.timings, None))
    assert "points-ssaa" in text and "patches" in text and v.frame.stats["device"] in text
    tap(window, "P")
    shots = sorted(p.name for p in (tmp_path / "shots").iterdir())
    assert shots == ["view_0000.exr", "view_0000.png"]
    tap(window, "ESCAPE")
    assert v.quit


def test_a_plugin_edit_is_picked_up_and_a_broken_one_shows_its_message(window, tmp_path):
    plugin = tmp_path / "live_blob.py"
    plugin.write_text(PLUGIN.format(sx="1.0"))
    v = Viewer(Source(plugin, SIZE), window, hud_on=True)
    v.draw_frame(0.0)
    round_ = v.image.copy()

    def edit(text):
        plugin.write_text(text)
        time.sleep(POLL_SECONDS * 1.5)   # the viewer polls this often: a save shows within a second
        v.draw_frame(0.0)

    edit(PLUGIN.format(sx="2.5"))
    assert v.error is None and not np.array_equal(v.image, round_)
    wide = v.image.copy()
    edit(PLUGIN.format(sx="2.5").replace("return radius", "return (radius"))   # a syntax error
    with pytest.raises(pl.ParamlodError) as exc:
        Source(plugin, SIZE).load()
    assert v.error == cli_message(exc.value)                       # the CLI's message
    assert v.error.startswith(f"paramlod: error: plugin file {plugin}:")
    assert np.array_equal(v.image, wide)                           # over the last good image
    shown = [t for t, colour in hud.lines(v.state(), v.frame.stats, v.timings, v.error) if colour == hud.ERROR_COLOUR]
    assert shown and shown[0] == v.error.splitlines()[0]
    edit(PLUGIN.format(sx="0.5"))
    assert v.error is None and not np.array_equal(v.image, wide)


def test_a_scene_file_edit_is_picked_up(window, tmp_path):
    scene = tmp_path / "s.toml"
    text = '[camera]\neye = [0, 0, 4]\n[[objects]]\nfunction = "sphere"\ncolor = [0.9, 0.2, 0.2]\n'
    scene.write_text(text)
    v = Viewer(Source(scene, SIZE), window, hud_on=False)
    v.draw_frame(0.0)
    red = v.image[SIZE[1] // 2, SIZE[0] // 2].astype(int)
    scene.write_text(text.replace("[0.9, 0.2, 0.2]", "[0.2, 0.2, 0.9]"))
    time.sleep(POLL_SECONDS * 1.5)
    v.draw_frame(0.0)
    blue = v.image[SIZE[1] // 2, SIZE[0] // 2].astype(int)
    assert red[0] > red[2] and blue[2] > blue[0]
    scene.write_text(text.replace('"sphere"', '"no_such_function"'))
    time.sleep(POLL_SECONDS * 1.5)
    v.draw_frame(0.0)
    assert v.error.startswith(f"paramlod: error: {scene}:") and "no_such_function" in v.error


def test_the_window_context_and_paramlods_gl_context_take_turns(window):
    """A tess frame (paramlod's EGL context) in the viewer, then a tess render outside it."""
    v = Viewer(Source("sphere", SIZE, variant="tess"), window, hud_on=False)
    v.draw_frame(0.0)
    cam = v.controls.camera()
    assert np.array_equal(v.window_image(), v.image)
    assert np.array_equal(pl.render(v.loaded.scene, cam, "tess").rgb8(), v.image)


def test_the_bench_measures_the_same_frames(window):
    from paramlod.app.bench.viewer import measure_scene

    row = measure_scene(window, "sphere", SIZE, frames=2, warmup=1, log=lambda m: None)
    assert row["device_ms"] > 0 and row["viewer_ms"] > 0 and row["render_patches"] > 0
    assert row["same_frame"]   # the viewer drew the frame render_on_device measured
    assert row["overhead_ms"] == pytest.approx(row["viewer_ms"] - row["device_ms"])


def test_mesh_debug_colours_per_cluster_and_level(window):
    from helpers.meshes import grid

    scene = pl.Scene()
    scene.add_mesh(grid(24), material=pl.Material((0.7, 0.7, 0.7)))
    cam = pl.Camera.look_at((0.3, -1.2, 2.2), (0, 0, 0), size=SIZE)
    v = Viewer(Source.of_scene(scene, cam, variant="meshlets"), window, hud_on=False)
    v.draw_frame(0.0)
    plain = v.image.copy()
    assert "clusters" in hud.frame_counts(v.frame.stats)
    seen = {}
    for _ in range(3):
        tap(window, "C")
        v.draw_frame(0.0)
        seen[v.debug] = v.image.copy()
    assert list(seen) == ["object", "cluster", "level"]
    cover = v.frame.object_id > 0
    for mode in ("cluster", "level"):
        assert not np.array_equal(seen[mode][cover], plain[cover])

    def hues(img):   # distinct chromaticities: shading changes brightness, not hue
        c = img[cover].astype(float)
        return len(np.unique(np.round(c / (c.sum(axis=1, keepdims=True) + 1), 2), axis=0))

    assert hues(plain) == 1                       # one grey material
    assert hues(seen["cluster"]) > 1 and hues(seen["level"]) > 1
    tap(window, "C")
    assert v.debug == "material"


def test_an_animated_scene_plays_and_loops(window):
    from pathlib import Path

    scene = Path(__file__).resolve().parents[2] / "gallery" / "giant_worm.toml"
    v = Viewer(Source(scene, SIZE), window, hud_on=False)
    assert not v.paused and v.time == 0.0   # [animation] t0 = 0, t1 = 2
    v.draw_frame(0.0)
    still = v.image.copy()
    v.draw_frame(0.5)
    assert v.time == pytest.approx(0.5) and not np.array_equal(v.image, still)   # the worm moved
    for _ in range(4):
        v.draw_frame(0.5)
    assert v.time == pytest.approx(0.5)   # 2.5 looped back into [0, 2]


def test_an_animation_from_t0_down_to_t1_plays_backwards(window, tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text('[camera]\neye = [0, 0, 6]\n[animation]\nt0 = 2.0\nt1 = 0.0\n[[objects]]\nfunction = "sphere"\n')
    v = Viewer(Source(scene, SIZE), window, hud_on=False)
    assert not v.paused and v.time == 2.0
    v.draw_frame(0.5)
    assert v.time == pytest.approx(1.5)
    for _ in range(4):
        v.draw_frame(0.5)
    assert v.time == pytest.approx(1.5)   # -0.5 looped back into [0, 2]


def test_a_scene_files_plugin_is_watched_and_reloaded(window, tmp_path):
    from paramlod.function import registry

    folder = tmp_path / "plugins"
    folder.mkdir()
    plugin = folder / "live_blob.py"
    plugin.write_text(PLUGIN.format(sx="1.0"))
    scene = tmp_path / "s.toml"
    scene.write_text('[camera]\neye = [0, 0, 6]\n[[objects]]\nfunction = "live_blob"\n')
    registry.add_plugin_path(folder)   # as --functions DIR does
    try:
        v = Viewer(Source(scene, SIZE), window, hud_on=False)
        assert plugin.resolve() in v.watcher.seen
        v.draw_frame(0.0)
        before = v.image.copy()
        plugin.write_text(PLUGIN.format(sx="2.5"))
        time.sleep(POLL_SECONDS * 1.5)
        v.draw_frame(0.0)
        assert v.error is None and not np.array_equal(v.image, before)
    finally:
        registry.refresh()
