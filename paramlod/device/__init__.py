"""The only owner of OpenCL and OpenGL objects: contexts, program builds, growable buffers."""
