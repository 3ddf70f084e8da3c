"""Sample the Stanford bunny (a real scan shipped in the pymeshfix wheel) into blue surfels for the
gallery: writes gallery/data/bunny.surfels. Idempotent: skips the work if the file exists."""
import argparse
import importlib.resources
from pathlib import Path

from paramlod.surfels.build import sample_mesh

OUT = Path(__file__).parent / "data" / "bunny.surfels"


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("-n", type=int, default=30_000, help="surfels (default 30000)")
    ap.add_argument("--force", action="store_true", help="sample again even if the file exists")
    args = ap.parse_args()
    if OUT.exists() and not args.force:
        print(f"{OUT} exists (use --force to sample again)")
        return
    mesh = importlib.resources.files("pymeshfix").joinpath("examples/StanfordBunny.ply")
    surfels = sample_mesh(str(mesh), args.n, progress=True)
    surfels.save(OUT)
    print(f"{OUT}: {len(surfels)} surfels")


if __name__ == "__main__":
    main()
