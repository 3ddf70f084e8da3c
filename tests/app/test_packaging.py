"""The wheel installs a working paramlod (kernels as package data, functions, CLI)."""
import os
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_wheel_installs_and_renders(tmp_path):
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                    "-w", str(wheels), str(ROOT)], check=True)
    (wheel,) = wheels.glob("paramlod-*.whl")
    # every kernel source of the tree is in the wheel (a new kernel room must be named in pyproject.toml)
    with zipfile.ZipFile(wheel) as z:
        shipped = {n.removeprefix("paramlod/kernels/") for n in z.namelist() if n.startswith("paramlod/kernels/")}
    sources = {str(f.relative_to(ROOT / "kernels")) for f in (ROOT / "kernels").rglob("*.*")
               if f.suffix in (".cl", ".glsl")}
    assert sources and not sources - shipped, sorted(sources - shipped)
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(site), str(wheel)],
                   check=True)
    env = dict(os.environ, PYTHONPATH=str(site))
    code = (
        "import paramlod, paramlod.kernels, paramlod.functions, paramlod.surfels\n"
        f"assert paramlod.__file__.startswith({str(site)!r}), paramlod.__file__\n"
        "assert 'lod_step' in paramlod.kernels.source('lod/lod.cl')\n"
        "from paramlod.function.registry import all_functions\n"
        "assert {'sphere', 'torus'} <= set(all_functions())\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, env=env, cwd=tmp_path)
    out = tmp_path / "demo.png"
    r = subprocess.run([sys.executable, "-m", "paramlod", "render", str(ROOT / "scenes" / "demo.toml"),
                        "--size", "96x54", "-o", str(out)], env=env, cwd=tmp_path, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert out.stat().st_size > 500
