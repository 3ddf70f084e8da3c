"""The SH glyph field: ``ShField``, glyphs at voxel centres with coefficients in the canonical basis,
and how it becomes one object of a Scene (``ShField.to_scene``).

Every source (``paramlod.dmri.io``, ``.fit``, ``.synthetic``) ends up as an ``ShField``: voxel
centres in world millimetres and SH coefficients in the project's canonical basis, dipy's
**non-legacy descoteaux07** (``paramlod.dmri.sh``; ARCHITECTURE.md, "SH glyphs"), padded to order 12
(91 coefficients). Coefficients are converted on the way in, never reinterpreted. Needs numpy and
scipy only. See docs/dmri.md.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paramlod.dmri.sh import CANONICAL_BASIS, MAX_ORDER, coefficient_count, fibonacci_sphere, sh_evaluate, sh_matrix
from paramlod.errors import DmriError, ParamlodError
from paramlod.function import registry
from paramlod.scene.scene import Material, Scene

GLYPH_FUNCTION = "sh_glyph"


def _polar_rotation(linear: np.ndarray) -> np.ndarray:
    """The rotation nearest to ``linear`` (3x3). A reflection is replaced by its negative: even SH
    functions are antipodally symmetric, so -R draws the same glyph as R."""
    u, _, vt = np.linalg.svd(np.asarray(linear, np.float64))
    r = u @ vt
    return -r if np.linalg.det(r) < 0 else r


@dataclass
class ShField:
    """SH glyphs at voxel centres.

    ``positions`` [n, 3] float64 world mm; ``coeffs`` [n, 91] float64 canonical basis (non-legacy
    descoteaux07), zero above ``order``; ``source_basis``/``source_legacy`` say what the input was;
    ``frame`` is 'world' when the SH directions are world (scanner) axes (MRtrix) and 'voxel' when
    they are the image axes (dipy fits with FSL-style bvecs); ``affine`` maps voxel indices to
    world; ``ijk`` [n, 3] are the voxel indices; ``spacing`` is the smallest distance between two
    glyph centres (mm).
    """
    positions: np.ndarray
    coeffs: np.ndarray
    order: int
    source_basis: str
    source_legacy: bool = False
    frame: str = "world"
    affine: np.ndarray = field(default_factory=lambda: np.eye(4))
    ijk: np.ndarray | None = None
    spacing: float = 1.0
    metadata: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def synthetic(self) -> bool:
        return bool(self.metadata.get("synthetic", False))

    def radii(self, theta, phi) -> np.ndarray:
        """Signed glyph radii [n, P] at the directions (in the coefficients' own frame)."""
        return sh_evaluate(self.coeffs[:, :coefficient_count(self.order)], theta, phi)

    def glyph_rotation(self) -> np.ndarray:
        """3x3 rotation from the coefficients' frame to world."""
        return np.eye(3) if self.frame == "world" else _polar_rotation(self.affine[:3, :3])

    def radius_extremes(self, samples: int = 2000, chunk: int = 4096):
        """Sampled extremes of each glyph's signed radius over ``samples`` directions:
        (min [n], max [n], direction of the largest |r| [n, 3], direction of the max [n, 3]),
        directions as unit vectors in the coefficients' frame."""
        xyz, theta, phi = fibonacci_sphere(samples)
        B = sh_matrix(self.order, theta, phi)
        k, n = coefficient_count(self.order), len(self)
        lo, hi, d_abs, d_hi = np.empty(n), np.empty(n), np.empty((n, 3)), np.empty((n, 3))
        for a in range(0, n, chunk):
            r = self.coeffs[a:a + chunk, :k] @ B.T
            rows = np.arange(len(r))
            i_lo, i_hi = np.argmin(r, axis=1), np.argmax(r, axis=1)
            lo[a:a + chunk], hi[a:a + chunk] = r[rows, i_lo], r[rows, i_hi]
            d_hi[a:a + chunk] = xyz[i_hi]
            d_abs[a:a + chunk] = np.where((-r[rows, i_lo] > r[rows, i_hi])[:, None], xyz[i_lo], xyz[i_hi])
        return lo, hi, d_abs, d_hi

    def to_scene(self, scene=None, scale: float = 0.9, normalize: bool = True, color_by: str | None = None,
                 material=None, transform=None, subtract_min: bool = False):
        """Add the field to ``scene`` (a new Scene if None) as 'sh_glyph' instances; returns the scene.

        Each glyph sits at its voxel centre, rotated into world for a 'voxel'-frame field. ``scale``
        is the largest glyph radius as a fraction of half the spacing between glyph centres, so
        with scale < 1 neighbours do not overlap (the default 0.9 leaves a margin for the sampling). ``normalize=True`` gives every glyph that same
        largest radius (shape only); ``normalize=False`` keeps relative sizes, the field's largest
        glyph reaching ``scale``. Largest radii are sampled on 2000 directions. ``subtract_min``
        lowers each glyph's radius by its minimum (min-max display normalization: no negative lobes,
        sharper shapes; for ODFs such as CSA's, which dip below zero).

        The field is ONE object. ``color_by=None`` gives every glyph the material's colour;
        ``color_by='direction'`` colours each glyph by the |x|, |y|, |z| of its largest lobe's world
        direction (the usual dMRI colour code), as per-instance colours.
        """
        try:
            fn = registry.get_function(GLYPH_FUNCTION)
        except ParamlodError as e:
            raise DmriError(f"ShField.to_scene needs the '{GLYPH_FUNCTION}' parametric function, "
                            f"which is not available: {e}") from None
        pmap = {p.name: p for p in fn.params}
        want = coefficient_count(MAX_ORDER)
        if "coeffs" not in pmap or pmap["coeffs"].size != want:
            raise DmriError(f"'{GLYPH_FUNCTION}' must take 'coeffs' with {want} floats (order {MAX_ORDER})")
        if not 0 < scale:
            raise DmriError(f"to_scene: scale must be positive, got {scale!r}")
        if color_by not in (None, "direction"):
            raise DmriError(f"to_scene: color_by must be None or 'direction', got {color_by!r}")
        if len(self) == 0:
            raise DmriError("to_scene: the field has no glyphs")
        lo, hi, peak_dir, hi_dir = self.radius_extremes()
        coeffs = self.coeffs.copy()
        if subtract_min:
            coeffs[:, 0] -= lo * (2 * math.sqrt(math.pi))   # Y_0^0 = 1 / (2 sqrt(pi))
            rmax, peak_dir = hi - lo, hi_dir
        else:
            rmax = np.maximum(np.abs(lo), np.abs(hi))
        keep = np.isfinite(rmax) & (rmax > 0)
        if not keep.any():
            raise DmriError("to_scene: every glyph has zero radius")
        half = 0.5 * self.spacing * scale
        size = half / rmax[keep] if normalize else np.full(int(keep.sum()), half / rmax[keep].max())
        rot = self.glyph_rotation()
        n = int(keep.sum())
        tr = np.zeros((n, 4, 4))
        tr[:, :3, :3] = rot[None] * size[:, None, None]
        tr[:, :3, 3] = self.positions[keep]
        tr[:, 3, 3] = 1.0
        coeffs = coeffs[keep].astype(np.float32)
        scene = scene if scene is not None else Scene()
        colors = None
        if color_by == "direction":
            rgb = np.abs(peak_dir[keep] @ rot.T)
            colors = 0.15 + 0.85 * rgb / rgb.max(axis=1, keepdims=True)
        scene.add_instances(fn, n, per_instance={"coeffs": coeffs}, transforms=tr, transform=transform,
                            material=material or Material(color=(0.8, 0.75, 0.7)), colors=colors)
        return scene

    # -- npz round trip (the gallery's data files; read back by paramlod.dmri.io.load_field_npz) --
    def save_npz(self, path) -> Path:
        """Write positions and native-order coefficients (float32) plus metadata to ``path``."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        k = coefficient_count(self.order)
        np.savez_compressed(
            path, kind="coeffs", positions=self.positions.astype(np.float32),
            coeffs=self.coeffs[:, :k].astype(np.float32), **self.npz_header())
        return path

    def npz_header(self) -> dict:
        """The fields of the .npz format that describe the field (all but positions and coefficients)."""
        return dict(order=self.order, basis=CANONICAL_BASIS, source_basis=self.source_basis,
                    source_legacy=self.source_legacy, frame=self.frame, affine=self.affine,
                    ijk=(self.ijk if self.ijk is not None else np.zeros((0, 3))).astype(np.int32), spacing=self.spacing,
                    metadata=json.dumps(_jsonable(self.metadata)))


def _jsonable(meta: dict) -> dict:
    """Scalars and strings only (arrays stay out of the file's JSON header)."""
    out = {}
    for k, v in meta.items():
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, (list, tuple)) and all(isinstance(x, (int, float, str)) for x in v):
            out[k] = list(v)
        elif isinstance(v, (str, int, float, bool, type(None))):
            out[k] = v
    return out
