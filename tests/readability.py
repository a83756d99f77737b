"""Checks that a matplotlib figure reads at a glance, measured on the drawn canvas.

Used by tests/test_plot_readability.py. Each check returns a list of problems (empty when
the figure passes), so a failing test names every offending label, legend or axes at once.
The plot functions close their figure after saving; the tests capture it just before
(:func:`capture_figures`), then draw it again here.
"""

from __future__ import annotations

import contextlib

import numpy as np


@contextlib.contextmanager
def capture_figures(monkeypatch):
    """Keep the figures that ``save_figure`` draws (its PlotFile is still returned), in order."""
    import tcr_accuracy.view.plots_common as common

    kept = []
    original = common.save_figure

    def keep(fig, path, **kwargs):
        kept.append(fig)
        plot = original(fig, path, **kwargs)
        fig.saved_path = plot.path
        fig.saved_margins = white_margins(plot.png)
        return plot

    for module in _plot_modules():
        monkeypatch.setattr(module, "save_figure", keep)
    monkeypatch.setattr(common.pyplot(), "close", lambda *a, **k: None)
    yield kept


def _plot_modules():
    import tcr_accuracy.view.plots_diagnose as d
    import tcr_accuracy.view.plots_montecarlo as m
    import tcr_accuracy.view.plots_prediction as p
    import tcr_accuracy.view.plots_results as r
    import tcr_accuracy.view.plots_sensitivity as s

    return (d, m, p, r, s)


def _renderer(fig):
    fig.canvas.draw()
    return fig.canvas.get_renderer()


def _drawn_tick_labels(axis):
    lo, hi = sorted(axis.get_view_interval())
    span = (hi - lo) * 1e-9
    return [t.label1 for t in [*axis.get_major_ticks(), *axis.get_minor_ticks()]
            if t.label1.get_visible() and t.label1.get_text() and lo - span <= t.get_loc() <= hi + span]


def _axes_list(fig):
    return [ax for ax in fig.axes if ax.get_visible() and ax.axison]


def _axis_name(ax, letter):
    title = ax.get_title() or ax.get_xlabel() or ax.get_ylabel() or ("colorbar" if hasattr(ax, "_colorbar") else "")
    return f"{letter}-axis of '{title}'"


def overlapping_tick_labels(fig) -> list[str]:
    """Pairs of tick labels of one axis (colour bars and 3D axes included) whose boxes overlap."""
    renderer = _renderer(fig)
    problems = []
    for ax in _axes_list(fig):
        for letter in "xyz":
            axis = getattr(ax, f"{letter}axis", None)
            if axis is None:
                continue
            labels = _drawn_tick_labels(axis)
            # labels closer than a third of their font size read as one ("0.00050.0010")
            boxes = [(lab.get_text(), lab.get_window_extent(renderer).padded(lab.get_fontsize() / 6.0))
                     for lab in labels]
            for i, (ta, a) in enumerate(boxes):
                for tb, b in boxes[i + 1:]:
                    if a.overlaps(b):
                        problems.append(f"{_axis_name(ax, letter)}: '{ta}' overlaps '{tb}'")
    return problems


def _data_display_points(ax) -> np.ndarray:
    """Display coordinates (n, 2) of the data drawn in ax: line vertices, scatter offsets, bar
    and patch corners, filled areas' vertices (only what lies inside the axes box)."""
    from matplotlib.collections import Collection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle

    points = []
    for line in ax.get_lines():
        if isinstance(line, Line2D) and line.get_visible() and line.get_xydata().size:
            xy = line.get_xydata()
            if not _is_reference_line(line):
                points.append(line.get_transform().transform(xy))
    for coll in ax.collections:
        if not coll.get_visible() or not isinstance(coll, Collection):
            continue
        offsets = coll.get_offsets()
        if len(offsets) and len(coll.get_paths()) <= 1:  # scatter: one marker path, many offsets
            points.append(coll.get_offset_transform().transform(offsets))
        else:
            for path in coll.get_paths()[:2000]:
                points.append(coll.get_transform().transform(path.vertices))
    for patch in ax.patches:
        if isinstance(patch, Rectangle) and patch.get_visible() and patch.get_height() != 0:
            points.append(patch.get_window_extent().corners())
    if not points:
        return np.zeros((0, 2))
    pts = np.vstack([p for p in points if len(p)])
    box = ax.get_window_extent()
    inside = ((pts[:, 0] >= box.x0) & (pts[:, 0] <= box.x1) & (pts[:, 1] >= box.y0) & (pts[:, 1] <= box.y1))
    return pts[inside & np.all(np.isfinite(pts), axis=1)]


def _is_reference_line(line) -> bool:
    """axhline / axvline (a zero line, a noise floor) span the axes: a legend may sit on them."""
    t = line.get_transform()
    return getattr(t, "_b", None) is not None and line.get_xydata().shape[0] == 2 and (
        "BlendedGenericTransform" in type(t).__name__ or "Blended" in type(t).__name__)


def legends_over_data(fig) -> list[str]:
    """Legends whose box covers plotted data of any axes (a legend outside the axes passes)."""
    renderer = _renderer(fig)
    problems = []
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None] + list(fig.legends)
    for legend in legends:
        box = legend.get_window_extent(renderer)
        for ax in _axes_list(fig):
            pts = _data_display_points(ax)
            hit = ((pts[:, 0] >= box.x0) & (pts[:, 0] <= box.x1) & (pts[:, 1] >= box.y0) & (pts[:, 1] <= box.y1))
            if hit.any():
                texts = [t.get_text() for t in legend.get_texts()][:3]
                problems.append(f"legend {texts} covers {int(hit.sum())} data points of '{ax.get_title()}'")
    return problems


def small_texts(fig, min_pt: float = 7.0) -> list[str]:
    """Visible texts (tick labels, labels, titles, legend entries) smaller than min_pt."""
    from matplotlib.text import Text

    _renderer(fig)
    problems = []
    for text in fig.findobj(Text):
        if text.get_visible() and text.get_text().strip() and text.get_fontsize() < min_pt - 1e-9:
            if _inside_figure(fig, text):
                problems.append(f"'{text.get_text()}' at {text.get_fontsize():.1f} pt")
    return problems


def _inside_figure(fig, text) -> bool:
    renderer = fig.canvas.get_renderer()
    box = text.get_window_extent(renderer)
    fbox = fig.bbox
    return box.x1 > fbox.x0 and box.x0 < fbox.x1 and box.y1 > fbox.y0 and box.y0 < fbox.y1


def rotated_tick_labels(ax) -> list[str]:
    """Tick labels of ax drawn at an angle (read sideways)."""
    _renderer(ax.figure)
    return [f"'{lab.get_text()}' at {lab.get_rotation():.0f} deg" for axis in (ax.xaxis, ax.yaxis)
            for lab in _drawn_tick_labels(axis) if abs(lab.get_rotation() % 180.0) > 1.0]


def display_aspect(ax) -> tuple[float, float]:
    """(drawn height / width of the axes box, data height / width of its limits)."""
    _renderer(ax.figure)
    box = ax.get_window_extent()
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    return box.height / box.width, abs(y1 - y0) / abs(x1 - x0)


def white_margins(png, white: int = 250) -> tuple[int, int, int, int]:
    """Widths [pixels] of the white bands at the (left, right, top, bottom) of a PNG (its bytes or its path)."""
    import io

    import matplotlib.image as mpimg

    source = io.BytesIO(png) if isinstance(png, bytes) else str(png)
    rgb = mpimg.imread(source, format="png")[..., :3]
    if rgb.dtype != np.uint8:
        rgb = (rgb * 255).round()
    ink = np.any(rgb < white, axis=-1)
    rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    if rows.size == 0:
        return ink.shape[1], ink.shape[1], ink.shape[0], ink.shape[0]
    return int(cols[0]), int(ink.shape[1] - 1 - cols[-1]), int(rows[0]), int(ink.shape[0] - 1 - rows[-1])


def readability_problems(fig, *, min_pt: float = 7.0, max_margin_px: int = 20) -> list[str]:
    """Every generic check at once: tick labels, legends, text size, and the saved PNG's margins."""
    problems = overlapping_tick_labels(fig) + legends_over_data(fig) + small_texts(fig, min_pt)
    path = getattr(fig, "saved_path", None)
    if path is not None:
        margins = getattr(fig, "saved_margins", None) or white_margins(path)
        if max(margins) > max_margin_px:
            problems.append(f"{path}: white margins (left, right, top, bottom) {margins} px, more than "
                            f"{max_margin_px} px")
    return problems
