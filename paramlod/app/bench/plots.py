"""The bench's figures: matplotlib when it is installed (the optional ``bench`` extra), each
figure written atomically like the bench's other outputs."""
from __future__ import annotations

from pathlib import Path

from paramlod.core.files import write_atomically


def pyplot():
    """matplotlib.pyplot on the Agg backend, or None when matplotlib is not installed."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    return plt


def save_figure(fig, path) -> Path:
    """Lay ``fig`` out, write it to ``path`` as a PNG (atomically) and close it."""
    import matplotlib.pyplot as plt  # pyplot() found it

    fig.tight_layout()
    try:
        return write_atomically(path, lambda tmp: fig.savefig(tmp, dpi=90, format="png"))
    finally:
        plt.close(fig)
