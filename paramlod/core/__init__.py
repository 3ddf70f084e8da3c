"""Camera, transforms, Frame, atomic files, colour, shading constants and the CPU<->GPU record layouts (stdlib + numpy only)."""
