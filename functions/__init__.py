"""Built-in parametric functions, one module each (installed as ``paramlod.functions``)."""
