"""Generate the rigged, animated giant worm for the gallery (paramlod.meshlod.build.worm_rig, full
size: 307,200 triangles, 64 bones, a wave along the spine): writes gallery/data/skinned_worm.glb
(10.5 MB, not committed) and builds its culling bounds into the mesh cache, so that
``paramlod gallery --only skinned_worm`` only renders. Idempotent: skips what exists."""
import argparse
from pathlib import Path

from paramlod.meshlod.build.worm_rig import write_worm
from paramlod.meshlod.skinned import load_skinned
from paramlod.meshlod.source import skinned_bounds

OUT = Path(__file__).parent / "data" / "skinned_worm.glb"


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--size", choices=["full", "small"], default="full", help="worm size (default full)")
    ap.add_argument("--force", action="store_true", help="generate again even if the file exists")
    args = ap.parse_args()
    if OUT.exists() and not args.force:
        print(f"{OUT} exists (use --force to generate again)")
    else:
        write_worm(OUT, args.size)
        print(f"{OUT}: written")
    mesh = load_skinned(OUT)
    b = skinned_bounds(mesh, progress=True)
    print(f"{OUT.name}: {len(mesh.triangles):,} triangles, {len(mesh.clusters):,} meshlets; bounds "
          f"(built in {b.stats.get('seconds', 0):.1f} s) s_r {b.radius_scale:.3f}, classes {b.class_counts()}")


if __name__ == "__main__":
    main()
