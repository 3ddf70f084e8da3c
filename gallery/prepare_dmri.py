"""Prepare the diffusion-MRI gallery data (needs the extra: pip install 'paramlod[dmri]').

Writes, next to this script:

* ``data/small64d_csa_o8.npz``: dipy's constant-solid-angle Q-ball fit (order 8) of dipy's bundled
  small_64D scan, 1000 glyphs, positions and coefficients (float32, canonical non-legacy
  descoteaux07);
* ``data/synthetic_140x140_o12.npz``: the synthetic 140 x 140 crossing-fibre field (order 12),
  stored as its model (fibre directions and fractions); ``paramlod.dmri.load_field_npz`` refits the
  coefficients with numpy in a few seconds (91 float32 coefficients per glyph would be 7 MB).

Idempotent: a file whose recipe matches is kept; ``--force`` rewrites. Read the files with
``paramlod.dmri.load_field_npz`` (numpy and scipy, no dipy).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from paramlod import dmri
from paramlod.errors import ParamlodError

DATA = Path(__file__).resolve().parent / "data"


def _recipe_matches(path: Path, recipe: str) -> bool:
    try:
        with np.load(path, allow_pickle=False) as z:
            return json.loads(str(z["metadata"])).get("recipe") == recipe
    except Exception:  # noqa: BLE001 - missing or unreadable: make it again
        return False


def _recipes() -> dict[str, str]:
    import dipy

    return {
        "small64d_csa_o8.npz": f"csa order=8 smooth=0.006 small_64D dipy={dipy.__version__}",
        "synthetic_140x140_o12.npz": f"synthetic nx=140 ny=140 order=12 seed=0 subtract_min=1 "
                                     f"evals={list(dmri.SYNTHETIC_EVALS)} sphere={dmri.SYNTHESIS_SPHERE}",
    }


def prepare(out: Path = DATA, force: bool = False) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    recipes = _recipes()
    written = []
    with tqdm(total=len(recipes), desc="dMRI gallery data", unit="file") as bar:
        for name, recipe in recipes.items():
            path = out / name
            if not force and _recipe_matches(path, recipe):
                bar.write(f"up to date: {path}")
                bar.update()
                continue
            if name.startswith("small64d"):
                fld = dmri.fit_csa_odf("small_64D", order=8)
                fld.metadata["recipe"] = recipe
                fld.save_npz(path)
            else:
                fld = dmri.synthetic_crossing_field(140, 140, order=12, seed=0, progress=True)
                fld.metadata["recipe"] = recipe
                dmri.save_synthetic_npz(fld, path)
            bar.write(f"wrote {path} ({len(fld)} glyphs, order {fld.order}, {path.stat().st_size / 1e3:.0f} kB)")
            written.append(path)
            bar.update()
    return written


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=DATA, help="output folder (default: gallery/data)")
    ap.add_argument("--force", action="store_true", help="rewrite files that are up to date")
    args = ap.parse_args(argv)
    try:
        prepare(args.out, args.force)
    except ParamlodError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
