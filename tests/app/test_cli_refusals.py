"""Bad command-line input is refused upfront with one line naming it (exit 2, no traceback, no
work): --scheduler files and addresses Dask cannot use, a missing --camera-path file, name patterns
str.format cannot fill, frame ranges and worker counts too large for one job or machine, negative
--retries, an empty --variant/--aa, --view-cone without --quilt and a bad surfels --fov; and a
video that cannot be written."""
import argparse
from pathlib import Path

import pytest

from paramlod.app import dist
from paramlod.app.cli import build_parser, main
from paramlod.errors import MeshError, ParamlodError

ROOT = Path(__file__).resolve().parents[2]
DEMO = str(ROOT / "scenes" / "demo.toml")


def refused(argv, capsys) -> str:
    """The one-line error of ``paramlod argv``, which must fail with status 2 (argparse or not)."""
    try:
        rc = main(argv)
    except SystemExit as exc:   # argparse's own exits
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


def parse_refused(argv, capsys) -> str:
    """The error of parsing ``argv`` alone: refused before any scene is loaded."""
    with pytest.raises(SystemExit) as info:
        build_parser().parse_args(argv)
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.strip().splitlines()) == 1, err
    return err


def test_scheduler_files_and_addresses_dask_cannot_use(tmp_path, capsys):
    (tmp_path / "empty.json").write_text("{}")
    (tmp_path / "text.json").write_text("not json")
    (tmp_path / "noport.json").write_text('{"address": "tcp://127.0.0.1"}')
    cases = [(tmp_path / "nope.json", "does not exist"),
             (tmp_path / "empty.json", "is not a Dask scheduler file"),
             (tmp_path / "text.json", "cannot read the scheduler file"),
             (tmp_path / "noport.json", "'tcp://127.0.0.1' is not a Dask scheduler address (missing port"),
             ("tcp://localhost", "'tcp://localhost' is not a Dask scheduler address (missing port")]
    for scheduler, message in cases:
        err = parse_refused(["render", DEMO, "--frames", "0:2", "--scheduler", str(scheduler)], capsys)
        assert "argument --scheduler:" in err and message in err, (scheduler, err)
    (tmp_path / "sched.json").write_text('{"address": "tcp://127.0.0.1:8786"}')
    for ok in (str(tmp_path / "sched.json"), "tcp://login1:8786"):
        assert build_parser().parse_args(["render", DEMO, "--scheduler", ok]).scheduler == ok


def test_a_missing_camera_path_file_is_named(tmp_path, capsys):
    err = refused(["render", DEMO, "--camera-path", str(tmp_path / "nope.toml"), "--frames", "0:2", "-q",
                   "-o", str(tmp_path / "f_{frame}.png")], capsys)
    assert f"camera path file {tmp_path / 'nope.toml'} does not exist" in err
    assert not list(tmp_path.iterdir())


def test_every_pattern_str_format_cannot_fill_is_one_clean_error(tmp_path, capsys):
    items = [{"frame": i, "time": 0.0, "angle": 0.0, "scene": "s"} for i in range(2)]
    for field, exc in (("{frame[0]}", "TypeError"), ("{frame.x}", "AttributeError"), ("{0}", "IndexError"),
                       ("{frame:q}", "ValueError"), ("{frmae}", "KeyError")):
        with pytest.raises(ParamlodError, match=rf"not a usable name pattern \({exc}: .*the fields are \{{frame\}}"):
            dist.format_outputs([str(tmp_path / f"f_{field}.png")], "frames", items)
    with pytest.raises(MeshError, match=r"not a usable name pattern.*\{stem\} and \{name\}"):
        dist.mesh_build_job([tmp_path / "a.ply"], out="{stem[x]}.meshlod")
    err = refused(["render", DEMO, "--frames", "0:2", "-q", "-o", str(tmp_path / "f_{frame[0]}.png")], capsys)
    assert "f_{frame[0]}.png: not a usable name pattern (TypeError" in err
    err = refused(["render", DEMO, "--frames", "0:2", "-q", "-o", str(tmp_path / "f_{frame}.png"),
                   "--video", str(tmp_path / "{scene[x]}.gif")], capsys)
    assert "--video" in err and "not a usable name pattern (TypeError" in err
    err = refused(["render", DEMO, "--quilt", "2x1", "-o", str(tmp_path / "v_{view[0]}.png")], capsys)
    assert "v_{view[0]}.png: only {view} may be filled in" in err
    assert not list(tmp_path.glob("*.png"))


def test_a_job_too_large_to_hold_is_refused_before_any_list_is_made(tmp_path, capsys):
    most = dist.MAX_JOB_TASKS
    assert len(dist.expand_range((0, most, 1), None)) == most
    for spec, total, given in (((0, most + 1, 1), None, "0:100001"), ((0, 10**9, 3), None, "0:1000000000:3"),
                               ("all", most + 1, "all")):
        with pytest.raises(ParamlodError, match=rf"--frames {given}: \d+ frames; one job takes at most {most}"):
            dist.expand_range(spec, total)
    with pytest.raises(ParamlodError, match=rf"--turntable N needs 1 <= N <= {most}"):
        dist.render_job([DEMO], [str(tmp_path / "f_{frame}.png")], frames=(0, 1, 1), turntable=most + 1)
    err = refused(["render", DEMO, "--frames", "0:100000000", "-q", "-o", str(tmp_path / "f_{frame}.png")], capsys)
    assert "--frames 0:100000000: 100000000 frames" in err


def test_more_local_workers_than_the_machine_takes_are_refused(capsys, monkeypatch):
    monkeypatch.setattr(dist, "_cores", lambda: 2)
    assert build_parser().parse_args(["render", DEMO, "--workers", "8"]).workers == 8
    err = parse_refused(["render", DEMO, "--frames", "0:2", "--workers", "9"], capsys)
    assert "argument --workers: at most 8 local workers (4 per CPU core, 2 here), got 9" in err
    with pytest.raises(argparse.ArgumentTypeError, match="at most 8 local workers"):
        dist._local_workers("1000")


@pytest.mark.parametrize("argv, message", [
    (["render", DEMO, "--frames", "0:2", "--retries", "-1"], "argument --retries: must be an integer >= 0"),
    (["render", DEMO, "--variant", ""], "argument --variant: must not be empty"),
    (["render", DEMO, "--aa", " "], "argument --aa: must not be empty"),
    (["surfels", "render", "x.surfels", "-o", "x.png", "--fov", "0"], "argument --fov: must be a number of degrees "
                                                                       "in (0, 180), got '0'"),
    (["surfels", "render", "x.surfels", "-o", "x.png", "--fov", "nan"], "argument --fov"),
    (["surfels", "render", "x.surfels", "-o", "x.png", "--fov", "180"], "argument --fov"),
])
def test_values_that_were_accepted_without_effect_or_sense(argv, message, capsys):
    assert message in parse_refused(argv, capsys)


def test_view_cone_without_quilt_is_refused(tmp_path, capsys):
    for extra in ([], ["--stereo", "0.1"]):
        err = refused(["render", DEMO, "--view-cone", "30", *extra, "-o", str(tmp_path / "x.png")], capsys)
        assert "--view-cone 30: is the angle the views of --quilt span; it has no effect without --quilt" in err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_a_video_that_cannot_be_written_is_one_message(tmp_path, monkeypatch, suffix):
    """A full disk gave the clean error inside a screen of ffmpeg's output and a second traceback
    from imageio's clean-up; now one message with the cause, and no file left."""
    import imageio_ffmpeg
    from PIL import Image

    frames = []
    for k in range(2):
        frames.append(tmp_path / f"f{k}.png")
        Image.new("RGB", (8, 6), (40 * k, 0, 0)).save(frames[-1])
    fake = tmp_path / "ffmpeg"   # fails as ffmpeg does on a full disk
    fake.write_text("#!/bin/sh\ncat > /dev/null\necho '[out#0/mp4 @ 0x5571f58aa7c0] Could not write header: "
                    "No space left on device' >&2\necho '[vf#0:0 @ 0x1] Task finished with error code: -28' >&2\n"
                    "exit 228\n")
    fake.chmod(0o755)
    monkeypatch.setattr(imageio_ffmpeg, "get_ffmpeg_exe", lambda: str(fake))

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Image.Image, "save", full)
    out = tmp_path / f"v{suffix}"
    why = "ffmpeg failed: Could not write header: No space left on device" if suffix == ".mp4" else \
        "No space left on device"
    with pytest.raises(ParamlodError, match=f"cannot write {out}: {why}$"):
        dist.write_video(out, frames, 24.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f0.png", "f1.png", "ffmpeg"]


def test_where_built_in_python_is_checked_as_the_options_are(tmp_path):
    """dist.Where took any values from Python (a missing scheduler file reached Dask)."""
    for kw, what in ((dict(scheduler=str(tmp_path / "nope.json")), "Where scheduler: scheduler file .* does not exist"),
                     (dict(workers=10_000), "Where workers: at most"), (dict(retries=-1), "Where retries"),
                     (dict(gpus="first"), "Where gpus"), (dict(threads=0), "Where threads")):
        with pytest.raises(ParamlodError, match=what):
            dist.Where(**kw)
    assert dist.Where(workers=1, retries=0).workers == 1
