"""One frame: settings, plan, passes, composite and the frame driver."""
