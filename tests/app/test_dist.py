"""Batch jobs on Dask (paramlod.app.dist, issue 24): frames rendered by a local cluster of 2 workers
are the serial run's bytes; a worker killed in the middle of a task has the task run elsewhere and
the job completes; a rerun skips the outputs that are there and valid; a bad input on one frame is
one clean error; turntables, camera paths, name patterns, GPU pinning, slices of a volume, many
surfel samplings and mesh builds; the bench. Frames are tiny (48x36): the point is the job, not
the picture."""
import os
import re
import signal
import textwrap
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from paramlod.app import dist
from paramlod.app.cli import main
from paramlod.errors import ParamlodError, SceneError

import distributed  # noqa: E402  (a test dependency: .[test])

GALLERY = Path(__file__).resolve().parents[2] / "gallery"
SIZE = (48, 36)


def killing_builder(marker: str):
    """A scene file's instance builder that kills the Dask worker process that first calls it
    (once: the marker file says it happened), in the middle of that worker's task."""
    try:
        distributed.get_worker()
    except ValueError:   # not in a worker: the client validating the scene, or a serial run
        return {"count": 1}
    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return {"count": 1}
    os.write(fd, str(os.getpid()).encode())
    os.close(fd)
    os.kill(os.getpid(), signal.SIGKILL)


def dying_builder():
    """An instance builder that kills every Dask worker that calls it."""
    try:
        distributed.get_worker()
    except ValueError:
        return {"count": 1}
    os.kill(os.getpid(), signal.SIGKILL)


def worm_scene(folder: Path, extra: str = "") -> Path:
    path = folder / "worm.toml"
    path.write_text(textwrap.dedent("""
        [camera]
        direction = [0.8, 0.45, 1]
        fov_y = 40
        size = [48, 36]
        [animation]
        frames = 8
        t0 = 0.0
        t1 = 2.0
        fps = 6
        [[objects]]
        function = "giant_worm"
        color = [0.55, 0.45, 0.4]
    """) + textwrap.dedent(extra))
    return path


def frames_job(scene, out: Path, **kw):
    return dist.render_job([scene], [str(out / "f_{frame:02d}.png"), str(out / "f_{frame:02d}.exr")],
                           frames="all", **kw)


def read_all(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if not p.name.startswith(".")}


@pytest.fixture(scope="module")
def cluster():
    """A local cluster of 2 worker processes for the tests that pass --scheduler. Its workers trust
    scene files (they run the tests' own builders): the environment they start with says so, as a
    user's --trust-scene would."""
    old = os.environ.get("PARAMLOD_TRUST_SCENE")
    os.environ["PARAMLOD_TRUST_SCENE"] = "1"
    try:
        c = dist._Cluster(dist.Where(workers=2), dist.WorkerSetup()).__enter__()   # workers start now
    finally:   # this process trusts no more than before
        if old is None:
            os.environ.pop("PARAMLOD_TRUST_SCENE", None)
        else:
            os.environ["PARAMLOD_TRUST_SCENE"] = old
    yield c
    c.__exit__(None, None, None)


@pytest.fixture(scope="module")
def serial_frames(tmp_path_factory):
    root = tmp_path_factory.mktemp("serial")
    scene = worm_scene(root)
    report = dist.run_job(frames_job(scene, root / "out"), progress=False)
    assert len(report.done) == 8 and report.where == "this process"
    return scene, read_all(root / "out")


def test_two_workers_render_the_serial_bytes_and_load_the_scene_once_each(tmp_path, serial_frames):
    scene, expected = serial_frames
    report = dist.run_job(frames_job(scene, tmp_path), dist.Where(workers=2), progress=False)
    assert report.where == "2 local worker(s)" and len(report.done) == 8
    got = read_all(tmp_path)
    assert sorted(got) == sorted(expected) and len(got) == 16
    for name in expected:
        assert got[name] == expected[name], f"{name} differs from the serial run"
    frames = [np.asarray(Image.open(tmp_path / f"f_{i:02d}.png")) for i in range(8)]
    assert not np.array_equal(frames[0], frames[4]), "the animation does not move"
    # each worker process loaded the scene (and built its programs) once, for all its frames
    for name, w in report.per_worker().items():
        loads = {o.info["scene_loads"] for o in report.done if o.worker == name}
        assert loads == {1}, f"worker {name} loaded the scene {sorted(loads)} times"
    assert "2 local worker(s)" in report.summary() and "frames/s" in report.summary()


def test_a_worker_killed_in_a_task_has_it_run_elsewhere(tmp_path, cluster, monkeypatch):
    monkeypatch.setenv("PARAMLOD_TRUST_SCENE", "1")   # the killing builder is test code (the workers inherit it)
    marker = tmp_path / "killed"
    scene = worm_scene(tmp_path, f"""
        [[objects]]
        function = "sphere"
        scale = 0.001
        instances = {{ builder = "test_dist:killing_builder", args = {{ marker = "{marker}" }} }}
    """)
    dist.run_job(frames_job(scene, tmp_path / "serial"), progress=False)   # the builder kills only workers
    expected = read_all(tmp_path / "serial")
    before = set(cluster.client.run(os.getpid).values())
    report = dist.run_job(frames_job(scene, tmp_path / "out"), dist.Where(scheduler=cluster.client.scheduler.address),
                          progress=False)
    assert marker.exists(), "no worker was killed"
    killed = int(marker.read_text())
    assert killed in before
    assert len(report.done) == 8 and all(o.error is None for o in report.done)
    assert killed not in {int(o.worker.split("pid ")[1].rstrip(")")) for o in report.done}
    got = read_all(tmp_path / "out")
    assert sorted(got) == sorted(expected)
    assert got == expected
    assert not list((tmp_path / "out").glob(".*")), "a temporary file was left behind"


def test_a_task_that_kills_every_worker_fails_the_job_with_one_message(tmp_path, monkeypatch):
    monkeypatch.setenv("PARAMLOD_TRUST_SCENE", "1")
    scene = worm_scene(tmp_path, """
        [[objects]]
        function = "sphere"
        instances = { builder = "test_dist:dying_builder" }
    """)
    job = dist.render_job([scene], [str(tmp_path / "f_{frame}.png")], frames=(0, 2, 1))
    with pytest.raises(ParamlodError, match=r"worm\.toml frame \d .*the workers running it died 1 time\(s\).*--retries") \
            as info:
        dist.run_job(job, dist.Where(workers=1, retries=0), progress=False)
    assert "Traceback" not in str(info.value)


def test_a_rerun_skips_the_frames_that_are_done_and_valid(tmp_path):
    scene = worm_scene(tmp_path)
    out = tmp_path / "out"
    first = dist.run_job(frames_job(scene, out), progress=False)
    assert len(first.done) == 8 and not first.skipped
    before = read_all(out)
    (out / "f_02.png").unlink()
    (out / "f_05.exr").unlink()
    data = (out / "f_06.png").read_bytes()
    (out / "f_06.png").write_bytes(data[: len(data) // 2])   # cut short: not valid
    Image.new("RGB", (10, 10)).save(out / "f_07.png")        # the wrong size: not valid
    leftover = out / ".f_02.png.abcd1234.png"
    leftover.write_bytes(b"left by a killed worker")
    again = dist.run_job(frames_job(scene, out), progress=False)
    assert not leftover.exists()
    ran = sorted(int(o.name.split("frame ")[1].split(" ")[0]) for o in again.done)
    assert ran == [2, 5, 6, 7] and len(again.skipped) == 4
    assert read_all(out) == before
    assert "4 already done (skipped)" in again.summary()
    third = dist.run_job(frames_job(scene, out), progress=False)
    assert not third.done and len(third.skipped) == 8
    redo = dist.run_job(frames_job(scene, out), progress=False, overwrite=True)
    assert len(redo.done) == 8 and read_all(out) == before


def test_a_bad_input_on_one_frame_is_one_clean_error(tmp_path, cluster, capsys):
    scene = worm_scene(tmp_path)
    path = tmp_path / "path.toml"
    # the eye passes through the target at t = 0.5, frame 2 of 8 over t in [0, 2)
    path.write_text(textwrap.dedent("""
        [camera_path]
        [[camera_path.keys]]
        t = 0.0
        eye = [0, 0, 3]
        [[camera_path.keys]]
        t = 1.0
        eye = [0, 0, -3]
    """))
    out = tmp_path / "out"
    rc = main(["render", str(scene), "--camera-path", str(path), "-q", "-o", str(out / "f_{frame}.png"),
               "--scheduler", cluster.client.scheduler.address])
    err = capsys.readouterr().err
    assert rc == 2
    lines = [ln for ln in err.splitlines() if "paramlod: error" in ln]
    assert len(lines) == 1, err
    assert "worm.toml frame 2 (t = 0.5)" in lines[0] and "path.toml" in lines[0]
    assert "eye and target are the same point" in lines[0]
    assert "Traceback" not in err
    assert not (out / "f_2.png").exists()


def test_turntable_frames_differ_and_are_deterministic(tmp_path, capsys):
    scene = worm_scene(tmp_path)
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        assert main(["render", str(scene), "--turntable", "4", "-q", "-o", str(out / "t_{frame}_{angle:03.0f}.png")]) == 0
    assert "4 frame(s) made" in capsys.readouterr().out
    names = sorted(p.name for p in a.iterdir())
    assert names == ["t_0_000.png", "t_1_090.png", "t_2_180.png", "t_3_270.png"]
    assert read_all(a) == read_all(b)
    imgs = [np.asarray(Image.open(a / n)) for n in names]
    for i in range(4):
        for j in range(i):
            assert not np.array_equal(imgs[i], imgs[j]), f"turntable frames {j} and {i} are the same"


def test_video_of_the_frames(tmp_path):
    scene = worm_scene(tmp_path)
    out = tmp_path / "out"
    assert main(["render", str(scene), "--frames", "0:6", "-q", "-o", str(out / "{frame}.png"),
                 "--video", str(tmp_path / "worm.gif")]) == 0
    import imageio.v3 as iio

    gif = iio.imread(tmp_path / "worm.gif", index=None)
    assert gif.shape[0] == 6 and gif.shape[1:3] == (SIZE[1], SIZE[0])
    assert main(["render", str(scene), "--frames", "0:6", "-q", "-o", str(out / "{frame}.png"),
                 "--video", str(tmp_path / "worm.avi")]) == 2
    assert main(["render", str(scene), "--frames", "0:6", "-q", "-o", str(out / "{frame}.png"),
                 "--video", str(tmp_path / "worm.mp4")]) == 0
    mp4 = iio.imread(tmp_path / "worm.mp4", index=None, plugin="FFMPEG")
    assert mp4.shape[0] == 6 and mp4.shape[1:3] == (SIZE[1], SIZE[0])


def test_camera_path_keys_and_interpolation(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text(textwrap.dedent("""
        [camera_path]
        interpolation = "smooth"
        [[camera_path.keys]]
        t = 0.0
        eye = [0, 0, 4]
        [[camera_path.keys]]
        t = 1.0
        eye = [4, 0, 0]
        fov_y = 30
        [[camera_path.keys]]
        t = 3.0
        eye = [0, 0, -4]
        target = [0, 1, 0]
    """))
    cp = dist.load_camera_path(path, default_fov=50)
    box = (-np.ones(3), np.ones(3))
    for t, eye in ((0.0, [0, 0, 4]), (1.0, [4, 0, 0]), (3.0, [0, 0, -4]), (-1.0, [0, 0, 4]), (9.0, [0, 0, -4])):
        np.testing.assert_allclose(cp.camera(t, SIZE, box).eye, eye, atol=1e-12)
    assert cp.camera(1.0, SIZE, box).fov_y == 30 and cp.camera(0.0, SIZE, box).fov_y == 50
    lin = dist.load_camera_path(path.write_text(path.read_text().replace('"smooth"', '"linear"')) and path)
    np.testing.assert_allclose(lin.camera(0.5, SIZE, box).eye, [2, 0, 2])
    # smooth: the curve bulges past the chord and its velocity is continuous at the middle key
    assert np.linalg.norm(cp.camera(0.5, SIZE, box).eye) > np.linalg.norm([2, 0, 2])
    v = [(cp._interp(cp.eyes, 1 + s * 1e-5) - cp._interp(cp.eyes, 1)) / (s * 1e-5) for s in (1, -1)]
    np.testing.assert_allclose(v[0], v[1], rtol=1e-3, atol=1e-3)


@pytest.mark.parametrize("table, message", [
    ("[camera]\neye = [0, 0, 1]\n", r"has no \[camera_path\] table"),
    ("[camera_path]\nspeed = 2\n", r"camera_path\.speed: unknown field"),
    ("[camera_path]\n[[camera_path.keys]]\nt = 0\n", r"keys\[0\]: needs t .* and eye"),
    ("[camera_path]\n[[camera_path.keys]]\nt = 1\neye = [0, 0, 1]\n[[camera_path.keys]]\nt = 1\neye = [1, 0, 0]\n",
     r"times t must increase"),
    ("[camera_path]\n[[camera_path.keys]]\nt = 0\neye = [0, 1]\n", r"keys\[0\]\.eye: must be a list of 3 numbers"),
    ("[camera_path]\ninterpolation = \"cubic\"\n[[camera_path.keys]]\nt = 0\neye = [0, 0, 1]\n", r"interpolation"),
])
def test_camera_path_errors_name_the_file_and_field(tmp_path, table, message):
    path = tmp_path / "bad_path.toml"
    path.write_text(table)
    with pytest.raises(SceneError, match=message) as info:
        dist.load_camera_path(path)
    assert "bad_path.toml" in str(info.value)


def test_ranges_and_name_patterns(tmp_path):
    assert dist.parse_range("0:240") == (0, 240, 1) and dist.parse_range("3") == (3, 4, 1)
    assert dist.parse_range("2:10:4") == (2, 10, 4) and dist.parse_range("ALL") == "all"
    for bad in ("5:5", "-1:3", "a:b", "1:2:0"):
        with pytest.raises(Exception, match="A:B"):
            dist.parse_range(bad)
    assert dist.expand_range((2, 10, 4), None) == [2, 6]
    with pytest.raises(ParamlodError, match="give --frames A:B"):
        dist.expand_range("all", None)
    items = [{"frame": i, "time": i / 4, "angle": 0.0, "scene": "s"} for i in range(3)]
    names = dist.format_outputs([str(tmp_path / "f_{frame:03d}_{time:.2f}.png")], "frames", items)
    assert [Path(n[0]).name for n in names] == ["f_000_0.00.png", "f_001_0.25.png", "f_002_0.50.png"]
    with pytest.raises(ParamlodError, match=r"3 frames would share the name .*put a field"):
        dist.format_outputs([str(tmp_path / "same.png")], "frames", items)
    with pytest.raises(ParamlodError, match=r"not a usable name pattern.*\{frame\}, \{time\}"):
        dist.format_outputs([str(tmp_path / "{frmae}.png")], "frames", items)
    with pytest.raises(ParamlodError, match=r"must end with .png or .exr"):
        dist.format_outputs([str(tmp_path / "{frame}.jpg")], "frames", items)


def test_render_job_refuses_bad_requests_before_any_work(tmp_path, capsys):
    scene = worm_scene(tmp_path)
    static = tmp_path / "static.toml"
    static.write_text('[[objects]]\nfunction = "sphere"\n')
    cases = [
        (["--frames", "0:4", "-o", str(tmp_path / "one.png")], "would share the name"),
        (["--turntable", "4", "--camera-path", str(tmp_path / "x.toml")], "give one of them"),
        ([str(static), "--frames", "all", "-o", str(tmp_path / "{scene}_{frame}.png")], "give --frames A:B"),
        ([str(static), "-o", str(tmp_path / "{frame}.png")], "several scenes would write the same files"),
        (["--frames", "0:2", "--video", str(tmp_path / "v.gif"), "-o", str(tmp_path / "{frame}.exr")],
         "made from the PNG frames"),
        (["--gpus", "all", "--frames", "0:2"], "no OpenCL GPU"),
    ]
    for extra, message in cases:
        if extra[0] == "--gpus" and dist.usable_gpus():
            continue   # a machine with a GPU would start a worker on it
        rc = main(["render", str(scene), *extra, "-q"])
        err = capsys.readouterr().err
        assert rc == 2 and message in err and "Traceback" not in err, (extra, err)
    assert not list(tmp_path.glob("*.png"))


def test_gpu_workers_are_pinned_by_name_and_by_the_driver_s_ordinal():
    nv = [{"platform": "NVIDIA CUDA", "name": "NVIDIA H200", "vendor": "NVIDIA Corporation", "ordinal": k, "pci": p}
          for k, p in ((0, 0x19), (1, 0x3b))]
    envs = dist.gpu_worker_envs(nv)
    assert envs == [{"PARAMLOD_CL_DEVICE": "NVIDIA H200", "CUDA_DEVICE_ORDER": "PCI_BUS_ID", "CUDA_VISIBLE_DEVICES": "0"},
                    {"PARAMLOD_CL_DEVICE": "NVIDIA H200", "CUDA_DEVICE_ORDER": "PCI_BUS_ID", "CUDA_VISIBLE_DEVICES": "1"}]
    assert dist.gpu_worker_envs(nv, "1") == envs[1:]
    mixed = [{"platform": "NVIDIA CUDA", "name": "NVIDIA A100", "vendor": "NVIDIA", "ordinal": 0, "pci": 1},
             {"platform": "AMD Accelerated Parallel Processing", "name": "gfx90a", "vendor": "AMD", "ordinal": 0,
              "pci": None}]
    assert dist.gpu_worker_envs(mixed) == [{"PARAMLOD_CL_DEVICE": "NVIDIA A100"}, {"PARAMLOD_CL_DEVICE": "gfx90a"}]
    amd = [dict(mixed[1], ordinal=k) for k in range(2)]
    assert [e["GPU_DEVICE_ORDINAL"] for e in dist.gpu_worker_envs(amd)] == ["0", "1"]
    other = [{"platform": "Intel", "name": "Arc", "vendor": "Intel", "ordinal": k, "pci": None} for k in range(2)]
    with pytest.raises(ParamlodError, match="start one Dask worker per GPU yourself"):
        dist.gpu_worker_envs(other)
    with pytest.raises(ParamlodError, match="there are 2 usable GPUs"):
        dist.gpu_worker_envs(nv, "2")
    with pytest.raises(ParamlodError, match="no OpenCL GPU"):
        dist.gpu_worker_envs([])


def _mesh_files(folder: Path, n: int = 2):
    import trimesh

    paths = []
    for k in range(n):
        m = trimesh.creation.icosphere(subdivisions=2 + k)
        m.apply_translation([k, 0, 0])
        p = folder / f"ball{k}.ply"
        m.export(p)
        paths.append(p)
    return paths


def test_surfel_sampling_of_many_files_with_a_bad_one(tmp_path, cluster, capsys):
    good = _mesh_files(tmp_path)
    bad = tmp_path / "broken.ply"
    bad.write_text("ply\nthis is not a mesh\n")
    out = str(tmp_path / "out" / "{stem}.surfels")
    common = ["-n", "200", "--views", "4", "--resolution", "64", "-q", "-o", out,
              "--scheduler", cluster.client.scheduler.address]
    rc = main(["surfels", "sample", *map(str, good), str(bad), *common])
    err = capsys.readouterr().err
    assert rc == 2 and "broken.ply" in err and "Traceback" not in err, err
    assert len([ln for ln in err.splitlines() if "paramlod: error" in ln]) == 1
    finished = len(list((tmp_path / "out").glob("*.surfels")))   # good files done before the bad one stopped the job
    assert main(["surfels", "sample", *map(str, good), *common]) == 0
    # the rest made now; a good file already on a worker when the job stopped may have landed since
    # (each is written atomically), and is then skipped as done
    out = capsys.readouterr().out
    made = int(re.search(r"(\d+) file\(s\) made", out).group(1))
    skipped = re.search(r"(\d+) already done \(skipped\)", out)
    skipped = int(skipped.group(1)) if skipped else 0
    assert made + skipped == 2 and skipped >= finished, out
    from paramlod.surfels.format import SurfelSet

    sets = [SurfelSet.load(tmp_path / "out" / f"ball{k}.surfels") for k in range(2)]
    assert all(len(s) == 200 and s.meta["views"] == 4 for s in sets)
    serial = tmp_path / "serial.surfels"
    assert main(["surfels", "sample", str(good[0]), "-n", "200", "--views", "4", "--resolution", "64", "-q",
                 "-o", str(serial)]) == 0
    assert serial.read_bytes() == (tmp_path / "out" / "ball0.surfels").read_bytes()
    capsys.readouterr()
    serial_run = ["surfels", "sample", *map(str, good), *common[:-2]]   # in this process
    assert main(serial_run) == 0
    assert "0 file(s) made" in capsys.readouterr().out   # both were there: skipped
    assert main(serial_run + ["-n", "150"]) == 0
    assert "2 file(s) made" in capsys.readouterr().out   # another count: sampled again


def _sh_volume(path: Path):
    import nibabel as nib

    rng = np.random.default_rng(1)
    data = np.zeros((3, 3, 4, 15), np.float32)
    data[..., 0] = 1.0
    data[..., 1:] = 0.15 * rng.normal(size=(3, 3, 4, 14))
    data[:, :, 2] = 0.0   # slice 2 is outside the "brain"
    nib.save(nib.Nifti1Image(data, np.diag([2.0, 2.0, 2.0, 1.0])), str(path))
    return path


def test_glyph_slices_are_the_single_slice_images(tmp_path, capsys):
    pytest.importorskip("dipy")
    vol = _sh_volume(tmp_path / "fod.nii.gz")
    out = tmp_path / "slices"
    assert main(["glyphs", str(vol), "--slices", "all", "--size", "48x48", "-q",
                 "-o", str(out / "s_{slice}.png")]) == 0
    text = capsys.readouterr().out
    assert "1 slice(s) without a voxel to draw" in text and "fod.nii.gz slice 2" in text
    assert sorted(p.name for p in out.iterdir()) == ["s_0.png", "s_1.png", "s_3.png"]
    one = tmp_path / "one.png"
    assert main(["glyphs", str(vol), "--slice", "1", "--size", "48x48", "-o", str(one)]) == 0
    assert one.read_bytes() == (out / "s_1.png").read_bytes()
    assert main(["glyphs", str(vol), "--slices", "2:9", "--size", "48x48", "-o", str(out / "{slice}.png")]) == 2
    assert "has 4 axial slices" in capsys.readouterr().err


def test_mesh_builds_of_many_files(tmp_path):
    paths = _mesh_files(tmp_path)
    job = dist.mesh_build_job(paths, out="built/{stem}.meshlod", cache=False)
    report = dist.run_job(job, progress=False)
    assert len(report.done) == 2 and report.unit == "mesh"
    from paramlod.meshlod.format import load_meshlod

    for p in paths:
        lod = load_meshlod(tmp_path / "built" / f"{p.stem}.meshlod")
        assert len(lod.clusters) > 0
    again = dist.run_job(dist.mesh_build_job(paths, out="built/{stem}.meshlod", cache=False), progress=False)
    assert not again.done and len(again.skipped) == 2
    with pytest.raises(ParamlodError, match=r"would both be written"):
        dist.mesh_build_job(paths, out="built/same.meshlod")
    (tmp_path / "broken.obj").write_text("v 0 0 0\nf 1 2 3\n")
    with pytest.raises(ParamlodError, match=r"broken\.obj"):
        dist.run_job(dist.mesh_build_job([tmp_path / "broken.obj"], cache=False), progress=False)


def test_bench_measures_serial_and_each_worker_count(tmp_path):
    res = dist.bench_scaling(worm_scene(tmp_path), frames=4, size=SIZE, workers=(1, 2), out_dir=tmp_path)
    wheres = [r["where"] for r in res["runs"]]
    assert wheres == ["serial", "1 workers", "2 workers"]
    assert all(r["fps"] > 0 for r in res["runs"])
    assert res["runs"][1]["efficiency"] == pytest.approx(1.0)
    assert sum(res["runs"][2]["per_worker"].values()) == 4
    text = dist.format_bench(res)
    assert "serial" in text and "2 workers" in text
