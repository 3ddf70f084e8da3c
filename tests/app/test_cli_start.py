"""The command line starts without importing what only other commands need: the bench (the SH
glyphs' sympy series, trimesh, scipy) and the surfel sampler (scipy) cost over a second of every
start on a laptop's CPU."""
import subprocess
import sys

import pytest

from paramlod.app.cli import main, named_command


@pytest.mark.parametrize("argv, command", [
    (["render", "scene.toml"], "render"),
    (["--cl-device", "bench", "render", "scene.toml"], "render"),   # a global option's value is not a command
    (["--functions", "dir", "--trust-scene", "bench", "sphere"], "bench"),
    (["--cl-device=pocl", "surfels", "sample"], "surfels"),
    (["--help"], None),
    ([], None),
])
def test_the_command_is_the_first_word_that_is_not_a_global_option(argv, command):
    assert named_command(argv) == command


def test_render_and_info_do_not_import_the_bench_or_the_sampler():
    code = ("import sys; from paramlod.app.cli import build_parser; build_parser('render'); "
            "print(sorted(m for m in ('paramlod.app.bench.run', 'paramlod.surfels.build.sampler', 'scipy.spatial', "
            "'trimesh') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_the_bench_still_has_its_arguments(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "--variants" in text and "--peers" in text and "--extras" in text
