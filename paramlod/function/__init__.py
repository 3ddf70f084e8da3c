"""Parametric functions: definition, code generation (OpenCL, GLSL), registry and plugins."""
