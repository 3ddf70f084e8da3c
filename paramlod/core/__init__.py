"""Camera, transforms, Frame, atomic files, colour and the CPU<->GPU record layouts (stdlib + numpy only)."""
