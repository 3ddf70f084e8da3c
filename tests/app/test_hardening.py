"""Hardening (issue 19): scene files run no code, bad arguments of every command are one line
naming the argument (exit 2, no traceback, no file), every output is checked before any work and a
command writes all its outputs or none; ``paramlod functions`` shows docstrings, ``render --time``,
progress for long steps."""
import dataclasses
import io
import json
import os
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

import paramlod as pl
from paramlod import views
from paramlod.app import args as cli_args
from paramlod.app import cli, dist
from paramlod.app.bench import peers, run as bench
from paramlod.app.scenefile import TRUST_ENV, load_scene
from paramlod.function import registry

ROOT = Path(__file__).resolve().parents[2]
DEMO = str(ROOT / "scenes" / "demo.toml")
DATA = ROOT / "gallery" / "data"

SPHERE = """[camera]
eye = [0, 0, 4]
size = [48, 36]

[[objects]]
function = "sphere"
"""


def run_cli(argv, capsys):
    """``paramlod argv`` in this process: (exit status, stdout, stderr)."""
    try:
        rc = cli.main(argv)
    except SystemExit as exc:   # argparse's own exits
        rc = exc.code
    out, err = capsys.readouterr()
    return rc, out, err


def files_under(folder: Path) -> set:
    return {p for p in folder.rglob("*") if p.is_file()}


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A scratch folder as the working directory, with a tiny scene, a file and a folder; plugin
    folders a test adds (--functions) are forgotten after it."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv(TRUST_ENV, raising=False)
    monkeypatch.delenv(registry.ENV_VAR, raising=False)
    (tmp_path / "s.toml").write_text(SPHERE)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "outdir").mkdir()
    yield tmp_path
    registry.refresh()


# --- security ------------------------------------------------------------------------------------
def builder_scene(tmp_path: Path, builder: str, args: str) -> Path:
    p = tmp_path / "b.toml"
    p.write_text(SPHERE + f'instances = {{ builder = "{builder}", args = {{ {args} }} }}\n')
    return p


def test_a_scene_file_cannot_run_a_command(work, capsys):
    marker = work / "pwned"
    p = builder_scene(work, "os:system", f'command = "touch {marker}"')
    with pytest.raises(pl.SceneError, match=r"b\.toml:\d+: objects\[0\]\.instances: builder 'os:system' is not "
                                            r"registered .*--trust-scene"):
        load_scene(p)
    rc, _, err = run_cli(["render", str(p), "-o", "x.png"], capsys)
    assert rc == 2 and "not registered" in err and len(err.strip().splitlines()) == 1
    for spec in ("subprocess:call", "builtins:exec", "builtins:eval", "importlib:import_module"):
        with pytest.raises(pl.SceneError, match="is not registered"):
            load_scene(builder_scene(work, spec, f'args = "touch {marker}"'))
    assert not marker.exists() and not (work / "x.png").exists()


def test_only_trust_lets_a_scene_import_a_builder(work, capsys, monkeypatch):
    (work / "my_builders.py").write_text(
        "import pathlib\n"
        "def rows(n, marker):\n"
        "    pathlib.Path(marker).write_text('ran')\n"
        "    return {'count': n}\n")
    monkeypatch.syspath_prepend(str(work))
    p = builder_scene(work, "my_builders:rows", f'n = 3, marker = "{work / "ran"}"')
    with pytest.raises(pl.SceneError, match="my_builders:rows' is not registered"):
        load_scene(p)
    assert not (work / "ran").exists()
    rc, out, err = run_cli(["--trust-scene", "render", str(p), "-o", "x.png"], capsys)
    assert rc == 0, err
    assert (work / "ran").read_text() == "ran" and (work / "x.png").exists()
    assert TRUST_ENV not in os.environ   # the trust ends with the command


def two(spacing=1.0):
    """Two copies, ``spacing`` apart along x."""
    tr = np.repeat(np.eye(4)[None], 2, axis=0)
    tr[1, 0, 3] = spacing
    return {"count": 2, "transforms": tr}


def test_a_registered_builder_needs_no_trust(work):
    registry.register_builder("test_hardening:two", two)
    registry.register_builder("test_hardening:two", two)   # the same callable again: fine
    sf = load_scene(builder_scene(work, "test_hardening:two", "spacing = 2.5"))
    assert sf.scene.instance_count == 2
    with pytest.raises(pl.FunctionError, match="two builders are named"):
        registry.register_builder("test_hardening:two", lambda: {"count": 1})


def test_every_builder_the_shipped_scenes_name_is_registered():
    named = set()
    for toml in [*ROOT.glob("gallery/*.toml"), *ROOT.glob("scenes/*.toml")]:
        for o in tomllib.loads(toml.read_text()).get("objects", []):
            spec = o.get("instances")
            if isinstance(spec, dict) and "builder" in spec:
                named.add(spec["builder"])
    assert named, "the gallery names builders (yarn and fibre curtains)"
    assert named <= set(registry.builders())
    assert registry.get_builder("paramlod.functions.yarn:yarn_curtain")(loops=2, rows=1)["count"] == 2


# --- types in scene files --------------------------------------------------------------------------
def test_an_animation_whose_time_does_not_move_is_refused(work):
    p = work / "t.toml"
    p.write_text(SPHERE + "\n[animation]\nt0 = 1.5\nt1 = 1.5\n")
    with pytest.raises(pl.SceneError, match=r"t\.toml:\d+: animation\.t1: must differ from t0 = 1\.5"):
        load_scene(p)
    p.write_text(SPHERE + "\n[animation]\nt0 = 1.5\nt1 = 0.5\n")
    assert load_scene(p).animation["t1"] == 0.5   # backwards


@pytest.mark.parametrize("value", ["true", '"0.9"', "[true, 1]", "{ a = 1 }", "nan"])
def test_a_parameter_must_be_numbers(work, value):
    p = work / "t.toml"
    p.write_text(SPHERE.replace('"sphere"', '"torus"') + f"params = {{ major = {value} }}\n")
    with pytest.raises(pl.SceneError, match=r"objects\[0\]\.params\.major: must be a number or a list of numbers"):
        load_scene(p)


TYPED = [   # (table line to add or replace, the field named)
    ("[render]\nthreshold = true", "render.threshold"),
    ("[render]\nthreshold = [true, 2]", "render.threshold"),
    ("[render]\ninitial_grid = [true, 1]", "render.initial_grid"),
    ("[render]\nlevels = [true, 8]", "render.levels"),
    ("[render]\nmax_steps = true", "render.max_steps"),
    ("[render]\ndensity = nan", "render.density"),
    ("[animation]\nt0 = nan", "animation.t0"),
    ("[animation]\nframes = true", "animation.frames"),
]


@pytest.mark.parametrize("table,field", TYPED, ids=[t.replace("\n", " ") for t, _ in TYPED])
def test_booleans_and_nan_are_not_numbers(work, table, field):
    p = work / "t.toml"
    p.write_text(SPHERE + "\n" + table + "\n")
    with pytest.raises(pl.SceneError, match=rf"t\.toml:\d+: {re.escape(field)}: must be"):
        load_scene(p)


@pytest.mark.parametrize("line,field", [("rotate = [true, [1, 0, 0]]", "rotate"), ('rotate = [30, [1, "a", 0]]', "rotate"),
                                        ("scale = true", "scale"), ("specular = true", "specular"),
                                        ("color = [1, true, 0]", "color")])
def test_object_fields_refuse_booleans(work, line, field):
    p = work / "t.toml"
    p.write_text(SPHERE + line + "\n")
    with pytest.raises(pl.SceneError, match=rf"objects\[0\]\.{field}: must be"):
        load_scene(p)


def test_camera_size_refuses_booleans(work):
    p = work / "t.toml"
    p.write_text(SPHERE.replace("size = [48, 36]", "size = [true, 36]"))
    with pytest.raises(pl.SceneError, match=r"camera\.size: must be \[width, height\]"):
        load_scene(p)


@pytest.mark.parametrize("size", [(0, 0), (48, 0), (20000, 10), (True, 36)])
def test_a_size_override_is_named_as_the_flag(work, size):
    with pytest.raises(pl.SceneError, match=r"^--size: must be WxH") as info:
        load_scene(work / "s.toml", size=size)
    assert "camera.size" not in str(info.value)


def test_an_object_has_one_source(work):
    p = work / "t.toml"
    p.write_text(SPHERE + f'surfels = {{ path = "{DATA / "bunny.surfels"}" }}\n')
    with pytest.raises(pl.SceneError, match=r"objects\[0\]\.surfels: an object is one of .* it has both function "
                                            "and surfels"):
        load_scene(p)


@pytest.mark.parametrize("key", ["surfels", "sh_field"])
def test_a_missing_data_file_names_its_field(work, key):
    p = work / "t.toml"
    p.write_text(SPHERE.replace('function = "sphere"\n', f'{key} = {{ path = "nope.bin" }}\n'))
    with pytest.raises(pl.SceneError, match=rf"t\.toml:\d+: objects\[0\]\.{key}\.path: file .*nope\.bin does not exist"):
        load_scene(p)


# --- every command, bad arguments -------------------------------------------------------------------
S = "s.toml"
BAD = [
    # render
    (["render", S, "--size", "0x0", "-o", "a.png"], "--size"),
    (["render", S, "--size", "48x36", "-o", "a.png", "-o", "b.jpg"], "b.jpg"),
    (["render", S, "-o", "a.png", "-o", "missing/b.png"], "missing/b.png"),
    (["render", S, "-o", "/proc/x.png"], "/proc/x.png"),
    (["render", S, "-o", "a.png", "-o", "./a.png"], "given twice"),
    (["render", S, "-o", "outdir"], "outdir"),
    (["render", S, "-o", "afile/x.png"], "afile"),
    (["render", S, "-o", "a.png", "--stats", "missing/s.json"], "--stats"),
    (["render", S, "-o", "a.png", "--stats", "/proc/s.json"], "--stats"),
    (["render", S, "--time", "nan"], "--time"),
    (["render", S, "--time", "x"], "--time"),
    (["render", "nope.toml", "-o", "a.png"], "nope.toml"),
    (["render", "afile", "-o", "a.png"], "a scene file is TOML"),
    (["render", S, "--frobnicate"], "--frobnicate"),
    # info, functions
    (["info", "--frobnicate"], "--frobnicate"),
    (["functions", "extra"], "extra"),
    (["--functions", "/nonexistent-plugins", "functions"], "/nonexistent-plugins"),
    # bench
    (["bench", "--size", "0x0"], "--size"),
    (["bench", "--frames", "0"], "--frames"),
    (["bench", "--distances", "0"], "--distances"),
    (["bench", "--distances", "nan"], "--distances"),
    (["bench", "--distances", "1", "-2"], "--distances"),
    (["bench", "--warmup", "-1"], "--warmup"),
    (["bench", "--variants", "nope"], "--variants"),
    (["bench", "--out", "/proc/bench"], "--out"),
    (["bench", "--out", "afile"], "--out"),
    (["bench", "nosuchscenario"], "nosuchscenario"),
    # mesh
    (["mesh", "build", "nope.ply"], "nope.ply"),
    (["mesh", "build", str(DATA / "bunny.ply"), "-o", "x.png"], "x.png"),
    (["mesh", "build", str(DATA / "bunny.ply"), "-o", "/proc/x.meshlod"], "/proc/x.meshlod"),
    (["mesh", "build", str(DATA / "bunny.ply"), "-o", "missing/x.meshlod"], "missing"),
    (["mesh", "info", "nope.meshlod"], "nope.meshlod"),
    (["mesh", "info", str(DATA / "bunny.ply"), "--lod", "nope"], "--lod"),
    # gallery, glyphs, surfels: their own option parsing
    (["gallery", "--size", "0x0"], "--size"),
    (["glyphs", str(DATA / "small64d_csa_o8.npz"), "--size", "0x0", "-o", "g.png"], "--size"),
    (["surfels", "render", str(DATA / "bunny.surfels"), "--size", "0x0", "-o", "s.png"], "--size"),
    (["surfels", "info", "nope.surfels"], "nope.surfels"),
    (["surfels", "sample", "nope.ply", "-n", "100", "-o", "x.surfels"], "nope.ply"),
    (["surfels", "frobnicate"], "frobnicate"),
]


@pytest.mark.parametrize("argv,needle", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_arguments_are_one_line_naming_the_argument(work, capsys, argv, needle):
    before = files_under(work)
    rc, out, err = run_cli(argv, capsys)
    lines = err.strip().splitlines()
    assert rc == 2, (out, err)
    assert len(lines) == 1 and lines[0].startswith("paramlod: error: "), err
    assert needle in lines[0], err
    assert "Traceback" not in err
    assert files_under(work) == before   # nothing written, not even a part


# --- half-done work --------------------------------------------------------------------------------
def test_outputs_are_checked_before_the_render(work, capsys, monkeypatch):
    """A bad second output (or --stats) fails before anything renders; the first is not written."""
    calls = []
    monkeypatch.setattr(cli, "render", lambda *a, **k: calls.append(1))
    for extra in (["-o", "b.jpg"], ["-o", "missing/b.png"], ["--stats", "missing/s.json"]):
        rc, _, err = run_cli(["render", S, "-o", "a.png", *extra], capsys)
        assert rc == 2 and not calls and not (work / "a.png").exists(), err


def test_bench_checks_its_folder_before_measuring(work, capsys, monkeypatch):
    monkeypatch.setattr(bench, "cl_device", lambda: pytest.fail("measured before checking --out"))
    rc, _, err = run_cli(["bench", "--out", "/proc/nope", "--only-extras", "--extras", "functions"], capsys)
    assert rc == 2 and "--out" in err


def test_bench_extras_without_their_modules(work, capsys, monkeypatch):
    """An extra asked for by name whose optional module is missing stops the bench before anything
    is measured, naming the module; the default extras leave it out with a note."""
    real = bench.importlib.util.find_spec
    monkeypatch.setattr(bench.importlib.util, "find_spec", lambda m, *a: None if m == "pymeshfix" else real(m, *a))
    monkeypatch.setattr(bench, "cl_device", lambda: pytest.fail("measured before checking --extras"))
    rc, _, err = run_cli(["bench", "--out", "b", "--only-extras", "--extras", "functions", "meshes"], capsys)
    assert rc == 2 and "--extras meshes needs pymeshfix" in err and not (work / "b").exists()
    assert bench._usable_extras(None) == ["ceilings", "functions", "surfels"]
    assert "leaving out the meshes extra: it needs pymeshfix" in capsys.readouterr().out


def test_cluster_work_without_dask_says_so_before_any_frame(work, capsys, monkeypatch):
    """Without Dask, --workers and bench-scale fail with one line naming the extra to install,
    before a frame is drawn or a progress bar drawn (bench-scale said it with a traceback)."""
    real = dist.importlib.util.find_spec
    monkeypatch.setattr(dist.importlib.util, "find_spec", lambda m, *a: None if m == "distributed" else real(m, *a))
    monkeypatch.setattr(dist, "render_frame", lambda *a, **k: pytest.fail("rendered before checking for Dask"))
    rc, _, err = run_cli(["render", S, "--frames", "0:2", "-o", "f{frame}.png", "--workers", "2"], capsys)
    assert rc == 2 and "need Dask" in err and "paramlod[dist]" in err and "frame/s" not in err, err
    assert not list(work.glob("f*.png"))
    rc, _, err = run_cli(["bench-scale", "--scene", S, "--frames", "1"], capsys)
    assert rc == 2 and "need Dask" in err and "Traceback" not in err, err


def test_missing_writers_and_meshes_are_named_before_the_work(work, capsys, monkeypatch):
    """An MP4 without imageio-ffmpeg and the peers' bunny without pymeshfix stop the command before
    the frames or renders it would otherwise finish first."""
    real = dist.importlib.util.find_spec
    monkeypatch.setattr(dist.importlib.util, "find_spec", lambda m, *a: None if m == "imageio_ffmpeg" else real(m, *a))
    monkeypatch.setattr(dist, "render_frame", lambda *a, **k: pytest.fail("rendered before checking the video"))
    rc, _, err = run_cli(["render", S, "--frames", "0:2", "-o", "f{frame}.png", "--video", "v.mp4"], capsys)
    assert rc == 2 and "imageio-ffmpeg" in err and not list(work.glob("f*.png")), err

    def no_pymeshfix(name):
        raise ModuleNotFoundError(f"No module named {name!r}")
    monkeypatch.setattr(peers.importlib.resources, "files", no_pymeshfix)
    monkeypatch.setattr(peers, "reference_silhouette", lambda *a: pytest.fail("rendered before finding the bunny"))
    rc, _, err = run_cli(["bench", "--peers", "--peers-tools", "paramlod", "--out", "pb"], capsys)
    assert rc == 2 and "pymeshfix" in err and "--peers-samples" in err, err


def test_every_setting_of_another_kind_is_a_named_error():
    """Each field of each RenderSettings group set to a string, a list, None, a table or NaN validates
    or fails with a ParamlodError (a string density met '<=' with a TypeError)."""
    groups = [f.name for f in dataclasses.fields(pl.RenderSettings())
              if dataclasses.is_dataclass(getattr(pl.RenderSettings(), f.name))]
    assert {"lod", "points", "tess"} <= set(groups)
    for group in groups:
        for field in dataclasses.fields(getattr(pl.RenderSettings(), group)):
            for odd in ("x", [1], None, {"a": 1}, float("nan"), (1, 2, 3)):
                rs = pl.RenderSettings()
                setattr(getattr(rs, group), field.name, odd)
                try:
                    getattr(rs, group).validate()
                except pl.ParamlodError:
                    pass


def test_api_arguments_of_another_kind_are_named_errors():
    """Were a ValueError from numpy, a TypeError from len(None), an AttributeError on a dict and a
    ValueError from numpy."""
    scene = pl.Scene()
    scene.add("torus")
    cam = pl.Camera.look_at((0, -3, 2), (0, 0, 0), up=(0, 0, 1), size=(16, 12))
    for call, needle in ((lambda: views.cube_faces("x"), "cube_faces: position must be three numbers"),
                         (lambda: views.equirect([1, 2], None), "equirect needs the six cube_faces frames"),
                         (lambda: views.equirect([1] * 6, [cam] * 6), "equirect needs paramlod Frames"),
                         (lambda: pl.render(scene, cam, settings={"lod": 1}), "settings must be a paramlod.RenderSettings"),
                         (lambda: pl.evaluate("torus", "a", 0), "evaluate 'torus': u must be numbers")):
        with pytest.raises(pl.ParamlodError, match=re.escape(needle)):
            call()


def test_a_mesh_or_surfel_file_renders_as_it_is(work, capsys):
    """`paramlod render bunny.ply` was a UTF-8 decoding error: a mesh or surfel file is a scene of
    that one object, framed (a job of frames too)."""
    from PIL import Image

    for source, out in ((DATA / "bunny.ply", "m.png"), (DATA / "bunny.surfels", "s.png")):
        rc, _, err = run_cli(["render", str(source), "--size", "64x48", "-o", out], capsys)
        assert rc == 0, err
        img = np.asarray(Image.open(work / out).convert("RGB")).astype(int)
        assert (np.abs(img - img[0, 0]).sum(axis=-1) > 30).mean() > 0.1
    rc, _, err = run_cli(["render", str(DATA / "bunny.ply"), "--size", "32x24", "--turntable", "2", "-o",
                          "t_{frame}.png"], capsys)
    assert rc == 0 and len(list(work.glob("t_*.png"))) == 2, err
    rc, _, err = run_cli(["render", "nope.ply", "-o", "n.png"], capsys)
    assert rc == 2 and "mesh file nope.ply does not exist" in err


def test_all_outputs_or_none(work):
    def fail(path):
        raise pl.ParamlodError(f"cannot write {path}")

    items = [(work / "a.png", lambda p: Path(p).write_text("a")), (work / "b.png", fail)]
    with pytest.raises(pl.ParamlodError):
        cli_args.write_all_or_none(items)
    assert not (work / "a.png").exists()
    cli_args.write_all_or_none(items[:1])
    assert (work / "a.png").read_text() == "a"


def test_render_writes_image_and_stats(work, capsys):
    rc, out, err = run_cli(["render", S, "-o", "a.png", "-o", "a.exr", "--stats", "s.json"], capsys)
    assert rc == 0, err
    assert (work / "a.png").stat().st_size and (work / "a.exr").stat().st_size
    assert json.loads((work / "s.json").read_text())["pixels_written"] > 0
    assert not [p for p in work.iterdir() if p.name.startswith(".")]   # no temporaries left


# --- friction --------------------------------------------------------------------------------------
def test_functions_shows_the_docstrings(capsys):
    rc, out, _ = run_cli(["functions"], capsys)
    assert rc == 0
    for name, fn in registry.all_functions().items():
        assert fn.summary, f"{name} has no docstring"
        assert re.search(rf"^{re.escape(name)} .*\n\s+{re.escape(fn.summary)}$", out, re.M), name


def test_render_time_drives_the_implicit_time(work, capsys):
    plugins = work / "plugins"
    plugins.mkdir()
    (plugins / "slide.py").write_text(
        "from paramlod import parametric\n\n\n"
        "@parametric(u=(0, 1), v=(0, 1))\n"
        "def slide(u, v, t):\n"
        '    """A unit square that moves right with the time."""\n'
        "    return u - 0.5 + t, v - 0.5, 0 * u\n")
    (work / "m.toml").write_text(SPHERE.replace('"sphere"', '"slide"'))
    images = []
    for t in ("0", "0.6"):
        rc, _, err = run_cli(["--functions", str(plugins), "render", "m.toml", "--time", t, "-o", f"t{t}.png"],
                             capsys)
        assert rc == 0, err
        images.append((work / f"t{t}.png").read_bytes())
    assert images[0] != images[1]
    rc, _, err = run_cli(["render", S, "--time", "1", "--turntable", "2"], capsys)
    assert rc == 2 and "--time" in err


def test_progress_shows_the_stage_of_a_long_step(monkeypatch):
    monkeypatch.setenv(cli_args.PROGRESS_ENV, "1")
    buf = io.StringIO()
    with cli_args.progress("rendering 48x36", delay=0.0, stream=buf):
        import time
        time.sleep(0.4)
    text = buf.getvalue()
    assert "rendering 48x36 ..." in text and text.endswith("\n") and re.search(r"rendering 48x36: \d\.\d s", text)
    quick = io.StringIO()
    with cli_args.progress("quick", delay=5.0, stream=quick):
        pass
    assert quick.getvalue() == ""   # short steps say nothing
    monkeypatch.delenv(cli_args.PROGRESS_ENV)
    piped = io.StringIO()        # not a terminal: nothing, unless asked for
    with cli_args.progress("piped", delay=0.0, stream=piped):
        time.sleep(0.3)
    assert piped.getvalue() == ""


def test_progress_says_when_an_opencl_compile_runs(monkeypatch):
    """A first run waits for the OpenCL compiler: the progress line names what it compiles, and
    the note goes when the compile ends, also when it fails."""
    import threading
    import time

    import pyopencl as cl

    from paramlod.device import programs

    monkeypatch.setenv(cli_args.PROGRESS_ENV, "1")
    real_build = cl.Program.build
    seen = []

    def slow_build(self, *a, **kw):
        seen.append(programs.compiling_now())
        time.sleep(0.6)   # a compile the spinner sees
        return real_build(self, *a, **kw)

    monkeypatch.setattr(cl.Program, "build", slow_build)
    buf = io.StringIO()
    with cli_args.progress("rendering 48x36", delay=0.0, stream=buf):
        t = threading.Thread(target=programs.build, args=(["common/keys.cl"],), kwargs={"defines": {"PL_UNIQUE": 7}})
        t.start()
        t.join()
        time.sleep(0.3)
    text = buf.getvalue()
    assert seen == ["common/keys.cl"]
    assert "compiling OpenCL: common/keys.cl; the driver caches it" in text
    assert text.rstrip().endswith("s") and "compiling" not in text.splitlines()[-1].split("\r")[-1]
    assert programs.compiling_now() is None
    with pytest.raises(pl.FunctionError):   # a failed compile clears the note too
        programs.build(["common/keys.cl"], defines={"PL_BROKEN": 1}, generated="this is not OpenCL;")
    assert programs.compiling_now() is None


def test_a_bench_row_says_what_it_ran():
    assert bench._row_label("tess-4xSS+8xMS", {"aa_effective": "4xSS+4xMS"}) == "tess-4xSS+8xMS (ran 4xSS+4xMS)"
    assert bench._row_label("tess-4xSS+8xMS", {"aa_effective": "4xSS+8xMS"}) == "tess-4xSS+8xMS"
    assert bench._row_label("points", {}) == "points"


def test_patch_budget_in_a_scene_file(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('[render]\npatch_budget = 4096\n\n[[objects]]\nfunction = "sphere"\n')
    assert load_scene(p).settings.lod.patch_budget == 4096
    p.write_text('[render]\npatch_budget = 0\n\n[[objects]]\nfunction = "sphere"\n')
    with pytest.raises(pl.SceneError, match="render.patch_budget"):
        load_scene(p)
