"""The renderers (points, points-ssaa, tess) and their kit: registry, targets, AA, shading."""
