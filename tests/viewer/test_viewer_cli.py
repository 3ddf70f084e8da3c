"""``paramlod view``: the scripted mode (--script, --record, --frames, --video), bad input at start
(the CLI's message and exit code 2), and no display (a message naming the headless modes)."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from paramlod.app import cli
from paramlod.errors import ParamlodError
from paramlod.viewer.script import load_script

SCRIPT = """
fps = 10
frames = 4

[[camera]]
frame = 0
eye = [0, 0, 5]
target = [0, 0, 0]

[[camera]]
frame = 3
eye = [0, 0, 2.5]
target = [0, 0, 0]

[[event]]
frame = 2
key = "C"
"""


@pytest.fixture
def no_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)


def run(argv, capsys):
    try:
        code = cli.main(argv)
    except SystemExit as exc:   # argparse's refusals
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def test_script_records_numbered_frames_and_a_video(tmp_path, capsys, no_display):
    script = tmp_path / "s.toml"
    script.write_text(SCRIPT)
    rec = tmp_path / "rec"
    code, out, err = run(["view", "sphere", "--size", "64x48", "--script", str(script), "--record", str(rec),
                          "--video", str(tmp_path / "v.gif")], capsys)
    assert code == 0, err
    names = sorted(p.name for p in rec.iterdir())
    assert names == [f"frame_{k:05d}.png" for k in range(4)]   # numbered, and no temporary left over
    imgs = [np.asarray(Image.open(rec / n)) for n in names]
    assert all(i.shape == (48, 64, 3) for i in imgs)
    # the keyframes move the camera in: the sphere grows; frame 2's C press colours per object
    lit = [int(np.any(i != i[0, 0], axis=2).sum()) for i in imgs]   # pixels not the background
    assert lit[0] < lit[1] < lit[3]
    chroma = [int(np.ptp(i.astype(int), axis=2).max()) for i in imgs]   # a grey material, then hues
    assert chroma[1] < 20 and chroma[3] > 3 * chroma[1]
    assert (tmp_path / "v.gif").stat().st_size > 0
    assert "4 frames, 4 written" in out
    # --frames cuts the script short; an existing recording is not overwritten
    code, _, err = run(["view", "sphere", "--size", "64x48", "--script", str(script), "--record", str(rec),
                        "--frames", "2"], capsys)
    assert code == 2 and "--record" in err and "--overwrite" in err
    code, _, err = run(["view", "sphere", "--size", "64x48", "--script", str(script), "--record",
                        str(tmp_path / "two"), "--frames", "2"], capsys)
    assert code == 0 and len(list((tmp_path / "two").iterdir())) == 2


def test_frames_without_a_script_run_headless(tmp_path, capsys, no_display):
    code, out, err = run(["view", "torus", "--size", "48x32", "--frames", "2", "--record", str(tmp_path / "r")], capsys)
    assert code == 0, err
    assert len(list((tmp_path / "r").glob("frame_*.png"))) == 2


def test_a_mesh_file_and_a_surfel_file_are_sources(tmp_path, capsys, no_display):
    """`paramlod view bunny.ply` drew nothing: it was taken for a function name."""
    import trimesh

    data = Path(__file__).resolve().parents[2] / "gallery" / "data"
    mesh = tmp_path / "ico.ply"
    trimesh.creation.icosphere(subdivisions=3).export(mesh)
    for source, name in ((mesh, "mesh"), (data / "bunny.surfels", "surfels")):
        code, _, err = run(["view", str(source), "--size", "48x32", "--frames", "1", "--record", str(tmp_path / name)],
                           capsys)
        assert code == 0, err
        (png,) = (tmp_path / name).glob("frame_*.png")
        img = np.asarray(Image.open(png).convert("RGB")).astype(int)
        assert (np.abs(img - img[0, 0]).sum(axis=-1) > 30).mean() > 0.1   # framed: it covers the frame's middle
    code, _, err = run(["view", str(tmp_path / "missing.ply"), "--frames", "1"], capsys)
    assert code == 2 and "mesh file" in err and "does not exist" in err


@pytest.mark.parametrize("text,message", [
    ("fps = 0\n", "fps: must be a number in (0, 1000]"),
    ("[[event]]\nframe = 1\nkey = \"Z\"\n", "event[0].key: unknown key 'Z'"),
    ("[[event]]\nframe = -1\nkey = \"W\"\n", "event[0].frame: must be an integer"),
    ("[[event]]\nframe = 1\nkey = \"W\"\nscroll = 1\n", "event[0]: needs exactly one of key, drag or scroll"),
    ("[[camera]]\nframe = 0\neye = [0, 0, 1]\n", "camera[0].target: is required"),
    ("speed = 3\n", "speed: unknown field"),
    ("fps = \n", "not valid TOML"),
])
def test_bad_scripts_are_named(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ParamlodError) as exc:
        load_script(path)
    assert str(exc.value).startswith(f"script {path}: ") and message in str(exc.value)


def test_script_events_and_keyframes():
    s = load_script_text("""
fps = 20
[[camera]]
frame = 2
eye = [0, 0, 4]
target = [0, 0, 0]
[[camera]]
frame = 6
eye = [4, 0, 4]
target = [0, 0, 0]
[[event]]
frame = 7
key = "W"
[[event]]
frame = 8
drag = [10, -5]
""")
    assert s.frames == 9 and s.fps == 20
    assert s.camera_at(1) is None and s.camera_at(7) is None
    eye, target = s.camera_at(4)
    assert np.allclose(eye, [2, 0, 4]) and np.allclose(target, 0)
    tap = [(e.frame, e.key, e.pressed) for e in s.events if e.kind == "key"]
    assert tap == [(7, "W", True), (8, "W", False)]   # a tap: released on the next frame
    assert [e.value for e in s.events_at(8) if e.kind == "drag"] == [(10.0, -5.0)]


def load_script_text(text, tmp=[]):
    import tempfile
    from pathlib import Path

    d = Path(tempfile.mkdtemp())
    p = d / "s.toml"
    p.write_text(text)
    return load_script(p)


def test_bad_sources_at_start_give_the_clis_message(tmp_path, capsys, no_display):
    broken = tmp_path / "broken.toml"
    broken.write_text("[camera\n")
    code, _, err = run(["view", str(broken), "--frames", "1"], capsys)
    code_r, _, err_r = run(["render", str(broken), "-o", str(tmp_path / "x.png")], capsys)
    assert code == code_r == 2
    assert err.strip() == err_r.strip() and err.startswith(f"paramlod: error: {broken}: not valid TOML")
    plugin = tmp_path / "bad_plugin.py"
    plugin.write_text("from paramlod import parametric\nraise ValueError('nope')\n")
    code, _, err = run(["view", str(plugin), "--frames", "1"], capsys)
    assert code == 2 and err.startswith(f"paramlod: error: plugin file {plugin.resolve()}:2 failed to import: "
                                        "ValueError: nope") and "Traceback" not in err
    code, _, err = run(["view", "no_such_function", "--frames", "1"], capsys)
    assert code == 2 and "unknown function 'no_such_function'" in err and len(err.strip().splitlines()) == 1
    code, _, err = run(["view", str(tmp_path / "missing.toml")], capsys)
    assert code == 2 and "does not exist" in err
    code, _, err = run(["view", "sphere", "--variant", "splats", "--frames", "1"], capsys)
    assert code == 2 and "unknown variant 'splats'" in err
    code, _, err = run(["view", "sphere", "--aa", "7xSS", "--frames", "1"], capsys)
    assert code == 2 and "7xSS" in err and len(err.strip().splitlines()) == 1
    code, _, err = run(["view", "sphere", "--size", "0x5"], capsys)
    assert code == 2 and err.startswith("paramlod: error: argument --size")
    code, _, err = run(["view", "sphere", "--video", str(tmp_path / "v.avi"), "--record", str(tmp_path / "r")], capsys)
    assert code == 2 and ".gif or .mp4" in err


def test_no_display_names_the_headless_alternatives(capsys, no_display):
    code, _, err = run(["view", "sphere"], capsys)
    assert code == 2
    for alternative in ("--script", "--record", "paramlod render", "pl.show"):
        assert alternative in err
    assert len(err.strip().splitlines()) == 1


def test_a_display_that_cannot_be_reached_is_one_line():
    env = {**__import__("os").environ, "DISPLAY": ":987"}   # no X server there
    r = subprocess.run([sys.executable, "-P", "-m", "paramlod", "view", "sphere"], capture_output=True, text=True, env=env,
                       timeout=300)
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith("paramlod: error: cannot open a window on display ':987'") and "--record" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_no_egl_names_the_alternatives(tmp_path):
    """A process whose EGL cannot be found (no libEGL on the library path): one line, exit 2."""
    code = ("import ctypes.util, sys\n"
            "ctypes.util.find_library = lambda name: None\n"   # glcontext finds libEGL through it
            "import glcontext.egl\n"
            "orig = glcontext.egl.create_context\n"
            "def create_context(**kw):\n"
            "    kw['libegl'] = '/nonexistent/libEGL.so'\n"
            "    return orig(**kw)\n"
            "glcontext.egl.create_context = create_context\n"
            "from paramlod.app import cli\n"
            "sys.exit(cli.main(['view', 'sphere', '--headless', '--frames', '1']))\n")
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith("paramlod: error: no headless OpenGL (EGL) context") and "paramlod render" in r.stderr
    assert "Traceback" not in r.stderr


def test_without_the_viewer_extra_the_message_names_it():
    code = ("import sys\n"
            "sys.modules['moderngl_window'] = None\n"   # as if not installed: importing it fails
            "sys.modules['jupyter_rfb'] = None\n"
            "import paramlod as pl\n"
            "from paramlod.app import cli\n"
            "s = pl.Scene(); s.add('sphere')\n"
            "assert type(pl.show(s, size=(32, 24))).__name__ == 'Image'\n"   # the static fallback still works
            "sys.exit(cli.main(['view', 'sphere', '--frames', '1', '--headless']))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip() == "paramlod: error: the viewer needs moderngl-window: pip install paramlod[viewer]"
