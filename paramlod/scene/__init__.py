"""Scenes: objects, instances, flattening into the kernels' buffers, framing, loaders."""
