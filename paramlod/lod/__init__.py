"""The per-frame LOD stages (parametric patches) and their numpy twins."""
