"""Helpers shared by the tests (analytic masks, hole counts)."""
