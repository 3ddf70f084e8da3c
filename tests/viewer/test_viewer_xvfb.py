"""A real window (pyglet, GLX) on an X server: Xvfb, started here when it is installed (CI installs
Debian's xvfb). Key events go through pyglet's own event dispatch, then moderngl-window's
translation, to the viewer: the whole path of a key press on a desktop."""
import os
import shutil
import subprocess
import sys
import textwrap

import pytest

CHILD = textwrap.dedent("""
    import numpy as np
    import pyglet
    import paramlod as pl
    from paramlod.viewer.app import Viewer, open_window
    from paramlod.viewer.reload import Source

    win = open_window((64, 48), vsync=False)
    assert type(win).__module__.startswith("moderngl_window.context.pyglet"), type(win)
    v = Viewer(Source("sphere", (64, 48)), win, hud_on=False)
    v.draw_frame(0.0)
    first = v.image.copy()
    eye, fwd, speed = v.controls.fly.eye.copy(), v.controls.fly.forward.copy(), v.controls.fly.speed
    # pyglet queues the events; the swap at the end of a frame delivers them
    win._window.dispatch_event("on_key_press", pyglet.window.key.W, 0)
    v.draw_frame(0.0)
    assert v.controls.held == {"forward"}
    v.draw_frame(0.4)
    win._window.dispatch_event("on_key_release", pyglet.window.key.W, 0)
    v.draw_frame(0.0)
    assert not v.controls.held
    moved = eye + fwd * speed * 0.4
    cam = v.controls.camera()
    assert np.allclose(cam.eye, moved), (cam.eye, moved)
    assert not np.array_equal(first, v.image)
    assert np.array_equal(pl.render(v.loaded.scene, cam).rgb8(), v.image)
    assert np.array_equal(v.window_image(), v.image), "the window shows another image"
    win._window.dispatch_event("on_key_press", pyglet.window.key.V, 0)   # points -> points-ssaa
    win._window.dispatch_event("on_key_press", pyglet.window.key.V, 0)   # -> tess: paramlod's EGL context
    v.draw_frame(0.0)
    v.draw_frame(0.0)
    assert v.variant == "tess" and v.error is None, (v.variant, v.error)
    assert np.array_equal(v.window_image(), v.image)
    v.close()
    print("REAL WINDOW OK", win.ctx.info["GL_RENDERER"])
""")


@pytest.fixture(scope="module")
def display():
    if shutil.which("Xvfb") is None:
        msg = "Xvfb is not installed (Debian: apt-get install xvfb): the real-window test did not run"
        print(msg)
        pytest.skip(msg)
    r, w = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(w), "-screen", "0", "320x240x24", "-nolisten", "tcp"],
                            pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(w)
    with os.fdopen(r) as f:
        number = f.readline().strip()
    if not number:
        proc.kill()
        pytest.fail("Xvfb started but gave no display number")
    yield f":{number}"
    proc.terminate()
    proc.wait(timeout=30)


def env_for(display):
    return {**os.environ, "DISPLAY": display}


def test_a_real_window_draws_what_the_keys_ask(display):
    r = subprocess.run([sys.executable, "-c", CHILD], env=env_for(display), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "REAL WINDOW OK" in r.stdout
    print(r.stdout.strip())


def test_the_command_records_from_a_window(display, tmp_path):
    script = tmp_path / "s.toml"
    script.write_text('frames = 3\n[[event]]\nframe = 1\nkey = "W"\naction = "press"\n')
    r = subprocess.run([sys.executable, "-P", "-m", "paramlod", "view", "sphere", "--size", "64x48", "--script", str(script),
                        "--record", str(tmp_path / "rec")], env=env_for(display), capture_output=True, text=True,
                       timeout=600, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "rec").iterdir()) == [f"frame_{k:05d}.png" for k in range(3)]
