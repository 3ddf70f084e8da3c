"""The binding stack: named intermediate results of the @parametric body being built.

``define.parametric`` runs a body inside ``collect_bindings()``; ``paramlod.dsl.let`` appends
(symbol, expression) pairs to ``current_bindings()``. Both import this module, so that neither
imports the other (dsl sits above the function room).
"""
from __future__ import annotations

_stack: list = []   # one list of (symbol, expression) per body being built; None while suspended


def current_bindings() -> list | None:
    """The binding list of the @parametric body being built (None outside a body); see dsl.let."""
    return _stack[-1] if _stack else None


class collect_bindings:
    """Context manager: a fresh binding list for one body (``with collect_bindings() as b:``)."""

    def __enter__(self) -> list:
        self.bindings: list = []
        _stack.append(self.bindings)
        return self.bindings

    def __exit__(self, *exc):
        _stack.pop()


class suspend_bindings:
    """Context manager: ``let`` returns plain expressions inside (for expressions that are rewritten
    afterwards, e.g. a curve evaluated at a dummy parameter and then differentiated)."""

    def __enter__(self):
        _stack.append(None)

    def __exit__(self, *exc):
        _stack.pop()
