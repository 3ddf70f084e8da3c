"""The interactive viewer: not built yet."""
