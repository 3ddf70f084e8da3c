"""SurfelSet and the ``.surfels`` file (docs/surfels.md): an uncompressed npz, written
deterministically (fixed zip timestamps) and atomically."""
from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paramlod.core.files import write_atomically
from paramlod.errors import SurfelError

FORMAT = "paramlod.surfels"
VERSION = 1
PACKING_PREFIX = 1000
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)
_ARRAYS = {"positions": (np.float32, 3), "normals": (np.float32, 3), "colors": (np.uint8, 4),
           "radii": (np.float32, None)}


def nearest_neighbour_distances(points: np.ndarray, block: int = 1024) -> np.ndarray:
    """Distance of each point to its nearest other point (brute force in blocks, float64)."""
    p = np.asarray(points, np.float64)
    n = len(p)
    out = np.full(n, np.inf)
    if n < 2:
        return out
    sq = np.sum(p * p, axis=1)
    for i in range(0, n, block):
        a = p[i:i + block]
        d2 = sq[i:i + block, None] + sq[None, :] - 2.0 * a @ p.T
        d2[np.arange(len(a)), np.arange(i, i + len(a))] = np.inf
        out[i:i + block] = np.sqrt(np.maximum(d2.min(axis=1), 0.0))
    return out


def packing_constant(positions: np.ndarray, radii: np.ndarray) -> float:
    """(mean nearest-neighbour distance of the first m = min(1000, N) surfels)^2 * m; a single
    surfel uses its insertion radius."""
    m = min(PACKING_PREFIX, len(positions))
    if m == 0:
        raise SurfelError("an empty surfel set has no packing constant")
    if m == 1:
        r = float(radii[0])
        return r * r if r > 0 else 1e-12
    nn = nearest_neighbour_distances(positions[:m])
    return float(np.mean(nn) ** 2 * m)


@dataclass
class SurfelSet:
    positions: np.ndarray   # float32 (N, 3), world (object) space, in sampling order
    normals: np.ndarray     # float32 (N, 3), unit
    colors: np.ndarray      # uint8 (N, 4), sRGB RGBA
    radii: np.ndarray       # float32 (N,), insertion radius (distance to the nearer samples)
    packing: float          # see packing_constant
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.validate("surfel set")

    def __len__(self) -> int:
        return len(self.positions)

    @classmethod
    def build(cls, positions, normals, colors, radii, meta=None) -> "SurfelSet":
        positions = np.ascontiguousarray(positions, np.float32)
        radii = np.ascontiguousarray(radii, np.float32)
        return cls(positions, np.ascontiguousarray(normals, np.float32), np.ascontiguousarray(colors, np.uint8),
                   radii, packing_constant(positions, radii), dict(meta or {}))

    def validate(self, what: str):
        n = len(self.positions)
        if n == 0:
            raise SurfelError(f"{what}: holds no surfels")
        for name, (dtype, cols) in _ARRAYS.items():
            a = getattr(self, name)
            shape = (n,) if cols is None else (n, cols)
            if not isinstance(a, np.ndarray) or a.dtype != dtype or a.shape != shape:
                got = f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
                raise SurfelError(f"{what}: '{name}' must be {np.dtype(dtype).name} {shape}, got {got}")
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                raise SurfelError(f"{what}: '{name}' contains NaN or infinite values")
        if not (np.isfinite(self.packing) and self.packing > 0):
            raise SurfelError(f"{what}: packing constant must be positive and finite, got {self.packing}")
        if np.any(self.radii < 0):
            raise SurfelError(f"{what}: 'radii' must not be negative")

    def prefix(self, n: int) -> "SurfelSet":
        n = max(1, min(int(n), len(self)))
        return SurfelSet(self.positions[:n], self.normals[:n], self.colors[:n], self.radii[:n],
                         self.packing, dict(self.meta))

    @property
    def bounds(self) -> np.ndarray:
        return np.stack([self.positions.min(axis=0), self.positions.max(axis=0)]).astype(np.float64)

    def bounding_sphere(self):
        lo, hi = self.bounds
        c = (lo + hi) / 2
        r = float(np.sqrt(np.max(np.sum((self.positions.astype(np.float64) - c) ** 2, axis=1))))
        return c, max(r, float(np.max(self.radii)), 1e-12)

    def spacing(self, n: int) -> float:
        """World spacing of a prefix of n surfels: sqrt(packing / n)."""
        return float(np.sqrt(self.packing / max(1, n)))

    def prefix_for_spacing(self, r: float) -> int:
        """n = packing / r^2, clamped to [1, N]."""
        if not r > 0:
            return len(self)
        return int(min(len(self), max(1, np.ceil(self.packing / (r * r)))))

    # --- file ------------------------------------------------------------------------------------
    def save(self, path) -> Path:
        self.validate(f"surfel set for {path}")
        entries = {
            "format": np.array(FORMAT), "version": np.array(VERSION, np.int32),
            "positions": self.positions, "normals": self.normals, "colors": self.colors,
            "radii": self.radii, "packing": np.array(self.packing, np.float64),
            "meta": np.array(json.dumps(self.meta, sort_keys=True, default=_json_default)),
        }

        def write(tmp):
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED) as zf:
                for name, arr in entries.items():
                    buf = io.BytesIO()
                    np.lib.format.write_array(buf, arr if arr.ndim == 0 else np.ascontiguousarray(arr),
                                              allow_pickle=False)
                    info = zipfile.ZipInfo(name + ".npy", date_time=_ZIP_TIME)
                    info.external_attr = 0o644 << 16
                    zf.writestr(info, buf.getvalue())

        return write_atomically(path, write)

    @classmethod
    def load(cls, path) -> "SurfelSet":
        path = Path(path)
        if not path.exists():
            raise SurfelError(f"surfel file {path} does not exist")
        if path.is_dir():
            raise SurfelError(f"surfel file {path} is a folder")
        try:
            with np.load(path, allow_pickle=False) as z:
                names = set(z.files)
                missing = {"format", "version", "packing", "meta", *_ARRAYS} - names
                if missing:
                    raise SurfelError(f"{path} is not a .surfels file (missing {', '.join(sorted(missing))})")
                if str(z["format"]) != FORMAT:
                    raise SurfelError(f"{path} is not a .surfels file (format '{z['format']}')")
                version = int(z["version"])
                if version > VERSION:
                    raise SurfelError(f"{path} is .surfels version {version}; this paramlod reads up to {VERSION}")
                arrays = {k: z[k] for k in _ARRAYS}
                packing = float(z["packing"])
                meta = json.loads(str(z["meta"]))
        except SurfelError:
            raise
        except (zipfile.BadZipFile, EOFError, ValueError, OSError, KeyError, TypeError, json.JSONDecodeError) as exc:
            raise SurfelError(f"cannot read {path}: the file is truncated or corrupt "
                              f"({type(exc).__name__}: {exc})") from None
        try:
            return cls(arrays["positions"], arrays["normals"], arrays["colors"], arrays["radii"], packing, meta)
        except SurfelError as exc:
            raise SurfelError(f"{path}: {exc}") from None


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"cannot store {type(x).__name__} in .surfels metadata")


def load_surfels(path_or_set) -> SurfelSet:
    return path_or_set if isinstance(path_or_set, SurfelSet) else SurfelSet.load(path_or_set)
