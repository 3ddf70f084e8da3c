"""The command line starts without importing the third-party modules only some commands use:
scipy's k-d trees (the surfel sampler, the peers bench) and trimesh (mesh files, the peers bench)
took about 0.9 s of every start on a 2-core laptop CPU."""
import subprocess
import sys


def test_the_cli_imports_neither_scipy_spatial_nor_trimesh():
    code = ("import sys, paramlod.app.cli; "
            "print(sorted(m for m in ('scipy.spatial', 'trimesh') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
