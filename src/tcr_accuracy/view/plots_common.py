"""What every plotting module shares: matplotlib without a display, and whole PNG files."""

from __future__ import annotations

import io
from pathlib import Path

from ..atomic import write_bytes_atomically


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, *, dpi: int = 110, tight: bool = False) -> Path:
    """Write a figure as a PNG file, whole or not at all, and close it; returns the path.

    The folder is created when missing; ``tight`` applies ``fig.tight_layout()`` first.
    """
    path = Path(path)
    try:
        if tight:
            fig.tight_layout()
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=dpi)
        return write_bytes_atomically(path, buffer.getvalue())  # creates the folder
    finally:
        pyplot().close(fig)
