"""Issue 19, friction: no default output inside the repository's committed files; `glyphs
--subtract-min`; `surfels render` frames a set upright by its own axes whatever way it is stored;
`surfels sample` refuses an output that is not a .surfels file before sampling."""
import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from paramlod.app import surfels_cmd
from paramlod.app.cli import build_parser, main
from paramlod.app.glyphs import glyph_frame
from paramlod.surfels.format import SurfelSet
from paramlod.surfels.render import FixedCount, default_camera, principal_frame, render_surfels, up_axis

ROOT = Path(__file__).resolve().parents[2]
GALLERY = ROOT / "gallery"
BUNNY = GALLERY / "data" / "bunny.surfels"     # the pymeshfix scan: z-up, resting on z = 0
CSA = GALLERY / "data" / "small64d_csa_o8.npz"


# -- default outputs ---------------------------------------------------------------------------------
def _tracked() -> set[str]:
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return set(out.split())


def _output_defaults(parser, where=()):
    """(command, option, default) of every option of every (sub)command that names where to write."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _output_defaults(sub, where + (name,))
        elif isinstance(action.default, str) and any(w in action.dest for w in ("out", "stats", "video")):
            yield " ".join(where), "/".join(action.option_strings), action.default


def test_no_command_writes_into_committed_files_by_default():
    tracked = _tracked()
    defaults = list(_output_defaults(build_parser()))
    assert any(cmd == "gallery" for cmd, _, _ in defaults), "the walk must see gallery's --out"
    for cmd, opt, default in defaults:
        rel = Path(default)
        inside = {t for t in tracked if t == str(rel) or t.startswith(str(rel).rstrip("/") + "/")}
        assert not inside, f"paramlod {cmd} {opt} defaults to {default}, which holds committed files {sorted(inside)[:3]}"


def test_gallery_writes_to_out_gallery_by_default_and_leaves_the_committed_images(tmp_path, monkeypatch):
    committed = {p.name: p.read_bytes() for p in (GALLERY / "images").iterdir() if p.is_file()}
    monkeypatch.chdir(tmp_path)
    assert main(["gallery", "--scenes", str(GALLERY), "--size", "48x36", "--only", "hearts"]) == 0
    for name in ("hearts.png", "hearts.exr", "captions.json", "README.md"):
        assert (tmp_path / "out" / "gallery" / name).stat().st_size > 0
    assert {p.name: p.read_bytes() for p in (GALLERY / "images").iterdir() if p.is_file()} == committed
    assert "--out gallery/images" in (tmp_path / "out" / "gallery" / "README.md").read_text()


# -- glyphs --subtract-min -----------------------------------------------------------------------------
def _sh_volume(path):
    """A 3x1x2 NIfTI of order-2 SH (descoteaux07): glyphs whose ODF dips below zero."""
    import nibabel as nib

    rng = np.random.default_rng(3)
    data = np.zeros((3, 1, 2, 6), np.float32)
    data[..., 0] = 0.3
    data[..., 1:] = rng.normal(0, 0.5, (3, 1, 2, 5))
    nib.save(nib.Nifti1Image(data, np.diag([2.0, 2.0, 2.0, 1.0])), str(path))
    return path


def test_glyphs_subtract_min_changes_the_glyphs_in_single_and_slice_renders(tmp_path, capsys):
    frames = {sm: glyph_frame(CSA, "descoteaux07", False, None, 1, None, "direction", "points", (48, 36), sm)[0]
              for sm in (False, True)}
    assert not np.array_equal(frames[False].coverage, frames[True].coverage)
    assert main(["glyphs", str(CSA), "--size", "48x36", "--subtract-min", "-o", str(tmp_path / "a.png")]) == 0
    assert "minimum subtracted" in capsys.readouterr().out
    from PIL import Image

    assert np.array_equal(np.asarray(Image.open(tmp_path / "a.png"))[..., :3], frames[True].rgb8())

    vol = _sh_volume(tmp_path / "sh.nii.gz")
    for sm in (False, True):
        flag = ["--subtract-min"] if sm else []
        assert main(["glyphs", str(vol), "--size", "48x36", "--slices", "all", "-q", *flag,
                     "-o", str(tmp_path / f"s{int(sm)}_{{slice}}.png")]) == 0
    for k in (0, 1):
        on, off = (np.asarray(Image.open(tmp_path / f"s{sm}_{k}.png")) for sm in (1, 0))
        assert not np.array_equal(on, off), f"--subtract-min did not reach slice {k} of a --slices job"
        single = glyph_frame(vol, "descoteaux07", False, None, 1, k, "direction", "points", (48, 36), True)[0]
        assert np.array_equal(on[..., :3], single.rgb8())


# -- surfels render: upright by the set's own axes ----------------------------------------------------
def _rotated(s: SurfelSet, R) -> SurfelSet:
    R = np.asarray(R, np.float64)
    return SurfelSet((s.positions @ R.T).astype(np.float32), (s.normals @ R.T).astype(np.float32), s.colors,
                     s.radii, s.packing, dict(s.meta))


def _rot(axis, deg):
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


# ways a file may store the same object: z-up as scanned, y-up, x-up, upside down, turned about its up
STORED = {"z-up": np.eye(3), "y-up": _rot(0, -90), "x-up": _rot(1, 90), "-z-up": _rot(0, 180),
          "z-up turned 30": _rot(2, 30), "y-up turned 70": _rot(0, -90) @ _rot(2, 70)}


@pytest.fixture(scope="module")
def bunny():
    return SurfelSet.load(BUNNY).prefix(12000)


@pytest.mark.parametrize("name", STORED)
def test_the_default_camera_sees_the_same_upright_view_however_the_set_is_stored(bunny, name):
    R = STORED[name]
    s = _rotated(bunny, R)
    np.testing.assert_allclose(up_axis(s), R @ [0, 0, 1], atol=1e-6)
    for mine, ref in zip(principal_frame(s), principal_frame(bunny)):
        np.testing.assert_allclose(mine, R @ ref, atol=1e-3)
    cam, ref_cam = default_camera(s, (48, 36)), default_camera(bunny, (48, 36))
    assert cam.view[1, :3] @ (R @ [0, 0, 1]) > 0.8, "the image's up is not the set's up"
    got, want = (render_surfels(x, c, FixedCount(12000)).coverage for x, c in ((s, cam), (bunny, ref_cam)))
    assert want.mean() > 0.05
    assert (got != want).mean() < 0.01, f"stored {name}, the bunny is framed differently"


def test_up_axis_falls_back_to_y_without_a_base():
    rng = np.random.default_rng(0)
    ball = rng.normal(size=(4000, 3))
    ball /= np.linalg.norm(ball, axis=1, keepdims=True)
    cube = rng.uniform(-1, 1, (6000, 3))
    face = np.arange(6000) % 6
    cube[np.arange(6000), face // 2] = np.where(face % 2, 1.0, -1.0)
    cube_n = np.zeros_like(cube)
    cube_n[np.arange(6000), face // 2] = np.where(face % 2, 1.0, -1.0)
    for p, n in ((ball, ball), (cube, cube_n)):
        s = SurfelSet(p.astype(np.float32), n.astype(np.float32), np.full((len(p), 4), 200, np.uint8),
                      np.full(len(p), 0.01, np.float32), 1e-3, {})
        np.testing.assert_array_equal(up_axis(s), [0, 1, 0])
        right, up, front = principal_frame(s)
        assert abs(right @ [1, 0, 0]) > 0.99 and front @ [0, 0, 1] > 0.99   # round: world axes


def test_surfels_render_cli_frames_upright_and_checks_up(tmp_path, capsys):
    out = tmp_path / "b.png"
    assert main(["surfels", "render", str(BUNNY), "--size", "48x36", "-o", str(out), "--eye", "0,-200,30"]) == 0
    assert out.stat().st_size > 0
    args = argparse.Namespace(eye=np.array([0.0, -200, 30]), target=None, up=None, fov=35.0, size=(48, 36))
    cam = surfels_cmd._camera(args, SurfelSet.load(BUNNY))
    assert cam.view[1, :3] @ [0, 0, 1] > 0.9, "--eye without --up must keep the set's up (z)"
    capsys.readouterr()
    assert main(["surfels", "render", str(BUNNY), "--up", "0,0,0", "-o", str(tmp_path / "z.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--up" in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "z.png").exists()


# -- surfels sample -o: a .surfels file, checked before sampling -------------------------------------
@pytest.mark.parametrize("name", ["x.png", "x.exr", "x.npz", "x", "x.surfels.png"])
def test_surfels_sample_refuses_a_non_surfels_output_before_sampling(tmp_path, capsys, monkeypatch, name):
    def no_sampling(*a, **k):
        raise AssertionError("sampled before checking -o")

    monkeypatch.setattr(surfels_cmd, "sample", no_sampling)
    monkeypatch.setattr(surfels_cmd, "sample_file", no_sampling)
    mesh = str(GALLERY / "data" / "bunny.ply")
    for argv in (["surfels", "sample", mesh, "-n", "100", "-o", str(tmp_path / name)],
                 ["surfels", "sample", mesh, mesh, "-n", "100", "-o", str(tmp_path / ("{stem}_" + name))]):
        capsys.readouterr()
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "-o" in err[0] and ".surfels" in err[0] and "Traceback" not in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_surfels_sample_accepts_a_surfels_output(tmp_path, capsys):
    out = tmp_path / "X.SURFELS"     # the suffix check ignores case, as the image outputs' does
    assert main(["surfels", "sample", str(GALLERY / "data" / "bunny.ply"), "-n", "50", "--views", "2",
                 "--resolution", "32", "-q", "-o", str(out)]) == 0
    assert len(SurfelSet.load(out)) > 0


# -- warnings: one line each, no source path --------------------------------------------------------
DEGENERATE_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\nf 1 1 2\n"   # face 3 repeats a vertex


def _check_one_line_warning(stderr: str, mesh: Path):
    lines = stderr.splitlines()
    assert lines == [f"paramlod: warning: mesh file {mesh}: dropped 1 of 3 faces that are degenerate "
                     "(a repeated vertex or zero area)"], stderr
    assert ".py" not in stderr and "Warning:" not in stderr


def test_install_warning_format_makes_each_warning_one_line(tmp_path):
    """In a fresh interpreter, as a user runs the command: the formatter installed, then the CLI."""
    mesh = tmp_path / "degen.obj"
    mesh.write_text(DEGENERATE_OBJ)
    code = ("import sys; from paramlod.app.args import install_warning_format; install_warning_format(); "
            "from paramlod.app.cli import main; sys.exit(main(sys.argv[1:]))")
    r = subprocess.run([sys.executable, "-c", code, "mesh", "info", str(mesh)], capture_output=True, text=True,
                       cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr
    _check_one_line_warning(r.stderr, mesh)


def test_the_paramlod_command_shows_warnings_as_one_line(tmp_path):
    """The entry point itself (paramlod.app.cli:main installs the formatter)."""
    mesh = tmp_path / "degen.obj"
    mesh.write_text(DEGENERATE_OBJ)
    r = subprocess.run([sys.executable, "-m", "paramlod.app.cli", "mesh", "info", str(mesh)],
                       capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr
    _check_one_line_warning(r.stderr, mesh)


def test_format_warning_collapses_lines():
    from paramlod.app.args import format_warning

    assert format_warning("a\n  b\tc ") == "paramlod: warning: a b c\n"
