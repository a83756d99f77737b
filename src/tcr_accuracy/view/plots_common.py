"""What every plotting module shares: matplotlib without a display, figures laid out so that
they read at a glance, and whole PNG files.

Readable at a glance means: tick labels that never run into each other, legends beside the
data rather than over it, text of at least :data:`MIN_FONT_PT`, and a saved image cropped to
its content (no wide white margins). :func:`figure` and :func:`save_figure` do the layout
part for every plot, which returns its PNG as a :class:`PlotFile` for the caller to write;
``tests/test_plot_readability.py`` checks the result on each kind of plot.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path


#: The smallest text a figure uses [pt]: tick labels, legends, panel titles.
MIN_FONT_PT = 7.5


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figure(rows: int = 1, cols: int = 1, *, size, **subplot_kw):
    """(fig, axes (rows, cols)) with matplotlib's constrained layout: it makes room for tick
    labels, colour bars, titles and legends placed outside the axes (``loc="outside ..."``)."""
    plt = pyplot()
    fig, axes = plt.subplots(rows, cols, figsize=size, squeeze=False, layout="constrained", **subplot_kw)
    return fig, axes


def legend_beside(ax, *, fontsize: float = 8, **kwargs):
    """The axes' legend outside it, to the right of the plotted data (never over it)."""
    return ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=fontsize,
                     **kwargs)


def shared_legend(fig, axes, handles, labels, *, fontsize: float = 8):
    """One legend for all panels, where it covers no data: in an empty panel slot when the
    grid has one (an axes turned off), else in a row under the panels."""
    spare = [ax for ax in axes.ravel() if not ax.axison and ax.get_visible()]
    if spare:
        return spare[-1].legend(handles, labels, loc="center", fontsize=fontsize + 1, frameon=False)
    return fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 4), fontsize=fontsize)


def whole_numbers():
    """A tick locator for counts (histograms): whole numbers only."""
    from matplotlib.ticker import MaxNLocator

    return MaxNLocator(integer=True)


def _tick_labels(axis, renderer):
    """The drawn tick labels of an axis, major and minor (those inside its view interval, with text:
    a log axis spanning less than a decade labels its minor ticks, "2x10^-1 3x10^-1 4x10^-1")."""
    lo, hi = sorted(axis.get_view_interval())
    span = (hi - lo) * 1e-9
    return [t.label1 for t in [*axis.get_major_ticks(), *axis.get_minor_ticks()]
            if t.label1.get_visible() and t.label1.get_text() and lo - span <= t.get_loc() <= hi + span]


#: The mantissas a log axis labels, fewest last: each tried until the labels stand apart.
LOG_LABELS = ((1, 2, 5), (1, 3), (1,))


def _plain_log_ticks(axis, subs) -> None:
    """Label a log axis at ``subs`` x 10^k in plain numbers (0.05, 0.1, 0.2), its other ticks unlabelled:
    matplotlib's own minor labels on a short log axis are "2x10^-1"-style and run into each other."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    axis.set_major_locator(LogLocator(base=10.0, subs=subs))
    axis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    axis.set_minor_locator(LogLocator(base=10.0, subs=tuple(s for s in range(1, 10) if s not in subs)))
    axis.set_minor_formatter(NullFormatter())


def tick_labels_overlap(axis, renderer) -> bool:
    """Whether two of an axis' visible tick labels come closer than a third of their font size
    on the drawn canvas (closer, "0.00050.0010" reads as one number)."""
    boxes = [label.get_window_extent(renderer).padded(label.get_fontsize() / 6.0)
             for label in _tick_labels(axis, renderer)]
    boxes = [b for b in boxes if b.width > 0 and b.height > 0]
    return any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])


def _thin_ticks(fig) -> None:
    """Fewer ticks on every numeric axis whose tick labels run into each other.

    matplotlib picks the number of ticks from the axis length without measuring the labels
    ("-5000-4000-3000" on a narrow panel): draw, measure, and ask its MaxNLocator for fewer
    ticks until the labels stand apart. A log axis is labelled in plain numbers at 1, 2 and 5 x 10^k,
    then fewer (:data:`LOG_LABELS`). Axes with fixed (named) ticks are left alone.
    """
    from matplotlib.ticker import AutoLocator, MaxNLocator

    log_labels = {}  # log axis -> index into LOG_LABELS
    for ax in fig.axes:
        for axis in _axes_of(ax):
            if axis.get_scale() == "log":
                log_labels[axis] = 0
                _plain_log_ticks(axis, LOG_LABELS[0])
    for _ in range(6):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        crowded = False
        for ax in fig.axes:
            for axis in _axes_of(ax):
                if axis in log_labels and log_labels[axis] + 1 < len(LOG_LABELS) \
                        and tick_labels_overlap(axis, renderer):
                    log_labels[axis] += 1
                    _plain_log_ticks(axis, LOG_LABELS[log_labels[axis]])
                    crowded = True
                    continue
                if axis.get_scale() != "linear" or not tick_labels_overlap(axis, renderer):
                    continue
                locator = axis.get_major_locator()
                if not isinstance(locator, (AutoLocator, MaxNLocator)):
                    continue
                n = max(2, len(_tick_labels(axis, renderer)) - 2)
                axis.set_major_locator(MaxNLocator(nbins=n, steps=[1, 2, 2.5, 5, 10]))
                crowded = True
        if not crowded:
            return


def _axes_of(ax):
    return [a for a in (getattr(ax, "xaxis", None), getattr(ax, "yaxis", None), getattr(ax, "zaxis", None))
            if a is not None]


def _cropped_png(fig, dpi: int, pad_px: int = 8) -> bytes:
    """The figure as PNG bytes, cropped to its non-white pixels plus ``pad_px``.

    ``bbox_inches="tight"`` crops to the artists' boxes, and a 3D axes' box is much wider
    than its drawing; cropping the rendered pixels removes every white band.
    """
    import numpy as np
    from matplotlib.image import imread, imsave

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight", pad_inches=0.05, facecolor="white")
    buffer.seek(0)
    image = (imread(buffer, format="png")[..., :3] * 255).round().astype(np.uint8)
    ink = np.any(image < 250, axis=-1)
    rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    if rows.size:
        image = image[max(rows[0] - pad_px, 0):rows[-1] + pad_px + 1, max(cols[0] - pad_px, 0):cols[-1] + pad_px + 1]
    out = io.BytesIO()
    imsave(out, image, format="png", dpi=dpi)
    return out.getvalue()


@dataclass(frozen=True)
class PlotFile:
    """A drawn plot: its PNG image and the file it is meant for. Nothing is written: the
    caller writes ``png`` to ``path`` (the command line through its one output writer) or
    puts it in a report."""

    path: Path
    png: bytes


def save_figure(fig, path, *, dpi: int = 110) -> PlotFile:
    """A figure as a :class:`PlotFile` for ``path`` (the figure is closed).

    Crowded tick labels are thinned first, and the image is cropped to what is drawn.
    """
    try:
        _thin_ticks(fig)
        return PlotFile(Path(path), _cropped_png(fig, dpi))
    finally:
        pyplot().close(fig)
