"""The renderers (points, points-ssaa, tess) and their kit: registry, targets, aa, shading,
sampling. Importing the package registers the built-in renderers and the parametric object kind."""
from paramlod.renderers import points, points_lfb, tess  # noqa: F401  (they register themselves)
from paramlod.renderers.registry import ObjectKind, register_kind

register_kind(ObjectKind("parametric", "points", "objects"))
