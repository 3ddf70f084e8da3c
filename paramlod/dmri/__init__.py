"""Diffusion MRI for SH glyphs: the SH bookkeeping (``sh``), the glyph field (``field``), NIfTI and
.npz files (``io``), dipy's CSA Q-ball fit (``fit``) and a synthetic crossing-fibre field
(``synthetic``). See docs/dmri.md."""
from paramlod.errors import DmriError
from paramlod.dmri.sh import (BASES, CANONICAL_BASIS, MAX_ORDER, SH_ORDERS, ShError, allowed_counts, cart_to_angles,
                              check_basis, check_order, coefficient_count, conversion_matrix, convert_basis,
                              dipy_basis_matrix, fibonacci_sphere, from_canonical, order_for_count, order_of,
                              pad_to_order, require_dipy, sh_degrees, sh_evaluate, sh_index, sh_matrix, to_canonical)
from paramlod.dmri.field import GLYPH_FUNCTION, ShField
from paramlod.dmri.synthetic import (SYNTHESIS_SPHERE, SYNTHETIC_EVALS, coeffs_from_model, synthetic_crossing_field,
                                     tensor_odf)
from paramlod.dmri.io import load_field_npz, load_sh_volume, save_synthetic_npz
from paramlod.dmri.fit import fit_csa_odf

__all__ = [
    "DmriError", "ShError",
    # sh
    "BASES", "CANONICAL_BASIS", "MAX_ORDER", "SH_ORDERS", "allowed_counts", "cart_to_angles", "check_basis",
    "check_order", "coefficient_count", "conversion_matrix", "convert_basis", "dipy_basis_matrix",
    "fibonacci_sphere", "from_canonical", "order_for_count", "order_of", "pad_to_order", "require_dipy",
    "sh_degrees", "sh_evaluate", "sh_index", "sh_matrix", "to_canonical",
    # field
    "GLYPH_FUNCTION", "ShField",
    # synthetic
    "SYNTHESIS_SPHERE", "SYNTHETIC_EVALS", "coeffs_from_model", "synthetic_crossing_field", "tensor_odf",
    # io, fit
    "load_field_npz", "load_sh_volume", "save_synthetic_npz", "fit_csa_odf",
]
