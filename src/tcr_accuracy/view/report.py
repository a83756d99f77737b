"""A report per run: tables, plots, 3D views, the command and the versions, as HTML and Markdown.

Build it, then write it::

    report = Report("Monte Carlo accuracy", command=["tcr-accuracy", "montecarlo", "--seed", "0"])
    report.add_text("2000 samples of the seed's Table 2 errors at the working pose.")
    report.add_table("TCP position error", ["axis", "mean", "std"], rows, units=["", "mm", "mm"])
    report.add_figure(fig, "Histogram of |dP|")          # a matplotlib figure or PNG bytes
    report.add_scene(scene.static_html(), "TCP cloud")   # a viewer.Scene's static page
    files = report.files()      # {"figure-1.png": b"...", ..., "report.md": ..., "index.html": ...}

A report can open with a first page (:meth:`Report.set_first_page`, e.g. the calibration
report of :mod:`tcr_accuracy.view.calibration_report`): it prints alone on page 1, the
items follow under "Technical detail". With ``print_pdf`` set, ``files`` also prints the page
to ``report.pdf`` through headless Chromium (:mod:`tcr_accuracy.view.pdf`) when there is one;
``pdf_problem`` then says why there is none.

``files`` returns what the report folder holds, by file name, ``index.html`` last; the caller
writes them (the command line through its one output writer,
:func:`tcr_accuracy.cli.output.write_report`). The page has no external resources: it
opens from disk with no network.

Values in tables are shown as given: convert to display units (mm, deg) before adding
them, and name the unit in ``units``.
"""

from __future__ import annotations

import html
import io
import math
import os
import platform
import shlex
import sys
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from .. import __version__
from ..exceptions import InputError
from .html_text import breakable_html
from .report_style import CSS, FIT_FIRST_PAGE_SCRIPT, PAGE_TEMPLATE

#: Distributions whose versions every report lists (when installed).
VERSION_PACKAGES = ("pin", "numpy", "scipy", "meshcat", "matplotlib", "scikit-learn", "SALib", "dask")


@dataclass(frozen=True)
class _Text:
    text: str
    heading: str | None


@dataclass(frozen=True)
class _Preformatted:
    text: str
    heading: str | None


@dataclass(frozen=True)
class _Table:
    title: str
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    note: str | None


@dataclass(frozen=True)
class _Links:
    heading: str
    links: tuple[tuple[str, str], ...]  # (label, relative href)


@dataclass(frozen=True)
class _Figure:
    filename: str
    png: bytes
    caption: str


@dataclass(frozen=True)
class _Scene:
    filename: str
    page: str
    caption: str
    height_px: int


def command_line(argv: list[str] | None = None) -> str:
    """The command as typed: ``tcr-accuracy`` and the arguments (default: this process's)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] in ("tcr-accuracy", "tcr_accuracy"):
        args = args[1:]
    return shlex.join(["tcr-accuracy", *args])


def versions() -> dict[str, str]:
    """Versions of tcr-accuracy, Python, the platform and the libraries in VERSION_PACKAGES."""
    from importlib import metadata

    out = {"tcr-accuracy": __version__, "python": platform.python_version(),
           "platform": f"{platform.system()} {platform.machine()}"}
    for name in VERSION_PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def _cell(value, float_format: str) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int):
        return str(value)
    try:
        number = float(value)
    except (TypeError, ValueError):
        return str(value)
    if not isinstance(value, str):
        if math.isnan(number):
            return "NaN"
        return float_format.format(number)
    return str(value)


#: A table with more columns than this (a per-pose table: joints, errors, spreads) is set in a
#: smaller type with narrower cell padding, so that it fits the page's width on screen and on A4.
WIDE_TABLE_COLUMNS = 9

def _td(value: str) -> str:
    """A table cell; a long word in it breaks after its separators (:func:`breakable_html`)."""
    return f"<td>{breakable_html(value)}</td>"


class Report:
    """An HTML (and Markdown) report under construction.

    Parameters
    ----------
    title : str
    command : str or list of str, optional
        The command that produced the report (default: this process's arguments, see
        :func:`command_line`).
    """

    def __init__(self, title: str, *, command: str | list[str] | None = None):
        self.title = title
        self.command = command if isinstance(command, str) else command_line(command)
        # SOURCE_DATE_EPOCH (the reproducible-builds convention) pins the date, so that two
        # runs with the same --seed write byte-identical reports
        epoch = os.environ.get("SOURCE_DATE_EPOCH")
        when = datetime.fromtimestamp(int(epoch), timezone.utc) if epoch and epoch.isdigit() \
            else datetime.now(timezone.utc)
        self.created = when.strftime("%Y-%m-%d %H:%M:%S UTC")
        self.items: list = []
        self._n_figures = 0
        self._n_scenes = 0
        self.first_page: tuple[str, str] | None = None  # (HTML fragment, Markdown)
        self.print_pdf = False  # files() also prints report.pdf (when Chromium is there)
        self.pdf_problem = ""  # after files(): why no PDF was printed, if one was asked for

    #: File name of the printed report in the report folder.
    PDF_NAME = "report.pdf"

    def set_first_page(self, html_fragment: str, markdown: str) -> None:
        """The page the report opens with, alone on page 1 when printed.

        Parameters
        ----------
        html_fragment : str
            Its HTML, escaped by the caller (the inside of a ``<section>``).
        markdown : str
            The same content as Markdown.
        """
        self.first_page = (str(html_fragment), str(markdown))

    # -- content ---------------------------------------------------------------------
    def add_text(self, text: str, heading: str | None = None) -> None:
        """A paragraph (blank lines start new paragraphs), optionally under a heading."""
        self.items.append(_Text(str(text), heading))

    def add_preformatted(self, text: str, heading: str | None = None) -> None:
        """Text shown as printed, in a fixed-width font with its line breaks and alignment kept
        (a command's printed summary with its aligned tables)."""
        self.items.append(_Preformatted(str(text).rstrip("\n"), heading))

    def add_table(self, title: str, columns, rows, units=None, *, note: str | None = None,
                  float_format: str = "{:.4g}") -> None:
        """A table.

        Parameters
        ----------
        title : str
        columns : sequence of str, length n_columns
        rows : sequence of sequences, each of length n_columns
            Numbers are formatted with ``float_format``; other values with ``str``.
        units : sequence of str, optional
            One per column (``""`` for none): shown in the header as ``name [unit]``.
        note : str, optional
            A line under the table (source, settings).
        """
        columns = [str(c) for c in columns]
        if units is not None:
            units = list(units)
            if len(units) != len(columns):
                raise InputError(f"table {title!r}: {len(units)} units for {len(columns)} columns")
            columns = [f"{c} [{u}]" if u else c for c, u in zip(columns, units)]
        formatted = []
        for i, row in enumerate(rows):
            row = list(row)
            if len(row) != len(columns):
                raise InputError(f"table {title!r}: row {i + 1} has {len(row)} values for {len(columns)} columns")
            formatted.append(tuple(_cell(v, float_format) for v in row))
        self.items.append(_Table(str(title), tuple(columns), tuple(formatted), note))

    def add_links(self, heading: str, links) -> None:
        """A list of links (label, relative href), e.g. to the reports of sub-runs."""
        self.items.append(_Links(str(heading), tuple((str(label), str(href)) for label, href in links)))

    def add_figure(self, figure, caption: str, *, dpi: int = 110) -> str:
        """A plot: a matplotlib ``Figure`` (saved as PNG now) or the bytes of a PNG image.

        Returns the file name the PNG gets in the report folder.
        """
        if hasattr(figure, "savefig"):
            buffer = io.BytesIO()
            figure.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
            png = buffer.getvalue()
        else:
            png = bytes(figure)
            if not png.startswith(b"\x89PNG\r\n\x1a\n"):
                raise InputError(f"figure {caption!r}: not a PNG image")
        self._n_figures += 1
        filename = f"figure-{self._n_figures}.png"
        self.items.append(_Figure(filename, png, str(caption)))
        return filename

    def add_scene(self, static_html: str, caption: str = "3D view", *, height_px: int = 540) -> str:
        """A 3D view: the page of :meth:`tcr_accuracy.view.viewer.Scene.static_html`.

        It is written next to ``index.html`` and shown in an iframe (with a link to open
        it alone). Returns its file name.
        """
        self._n_scenes += 1
        filename = f"scene-{self._n_scenes}.html"
        self.items.append(_Scene(filename, str(static_html), str(caption), int(height_px)))
        return filename

    # -- rendering -------------------------------------------------------------------
    def html(self, *, pdf: str | None = None) -> str:
        """The index page (figures and scenes referenced by their file names; ``pdf``: the file
        name of the printed report, linked when given)."""
        esc = html.escape
        printed = (' Also as <a href="report.md">Markdown</a>'
                   + (f' and printed (A4): <a href="{esc(pdf)}">{esc(pdf)}</a>.' if pdf else ".")
                   if self.first_page is not None else "")
        body: list[str] = []
        if self.first_page is not None:
            body.append(f'<section class="first-page">\n{self.first_page[0]}\n</section>')
            body.append(f'<h1 class="part">Technical detail: {esc(self.title)}</h1>')
        else:
            body.append(f"<h1>{esc(self.title)}</h1>")
        body.append(f'<p class="meta">Written {esc(self.created)} by tcr-accuracy {esc(__version__)}.{printed}</p>')
        for item in self.items:
            if isinstance(item, _Text):
                if item.heading:
                    body.append(f"<h2>{esc(item.heading)}</h2>")
                for para in (p.strip() for p in item.text.split("\n\n")):
                    if para:
                        body.append(f"<p>{esc(para)}</p>")
            elif isinstance(item, _Preformatted):
                if item.heading:
                    body.append(f"<h2>{esc(item.heading)}</h2>")
                body.append(f'<pre class="printed">{esc(item.text)}</pre>')
            elif isinstance(item, _Table):
                body.append(f"<h2>{esc(item.title)}</h2>")
                head = "".join(f"<th>{esc(c)}</th>" for c in item.columns)
                rows = "".join("<tr>" + "".join(_td(v) for v in row) + "</tr>" for row in item.rows)
                note = f'<p class="note">{esc(item.note)}</p>' if item.note else ""
                kind = "table wide" if len(item.columns) > WIDE_TABLE_COLUMNS else "table"
                body.append(f'<div class="{kind}"><table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody>'
                            f"</table>{note}</div>")
            elif isinstance(item, _Links):
                body.append(f"<h2>{esc(item.heading)}</h2>")
                body.append("<ul>" + "".join(f'<li><a href="{esc(href)}">{esc(label)}</a></li>'
                                             for label, href in item.links) + "</ul>")
            elif isinstance(item, _Figure):
                body.append(f'<figure><img src="{esc(item.filename)}" alt="{esc(item.caption)}">'
                            f"<figcaption>{esc(item.caption)}</figcaption></figure>")
            elif isinstance(item, _Scene):
                body.append(
                    f'<figure class="scene"><iframe src="{esc(item.filename)}" title="{esc(item.caption)}" '
                    f'style="height:{item.height_px}px"></iframe>'
                    f'<figcaption>{esc(item.caption)} (<a href="{esc(item.filename)}">open alone</a>; '
                    "drag to turn, scroll to zoom)</figcaption>"
                    f'<p class="print-only">3D view: open {esc(item.filename)} in a browser.</p></figure>')
        body.append("<h2>How this report was made</h2>")
        body.append(f"<pre class=\"command\">{esc(self.command)}</pre>")
        rows = "".join(f"<tr><td>{esc(k)}</td><td>{esc(v)}</td></tr>" for k, v in versions().items())
        body.append(f'<table class="versions"><thead><tr><th>software</th><th>version</th></tr></thead>'
                    f"<tbody>{rows}</tbody></table>")
        if self.first_page is not None:
            body.append(FIT_FIRST_PAGE_SCRIPT)
        return PAGE_TEMPLATE.format(title=esc(self.title), css=CSS, body="\n".join(body))

    def markdown(self, *, pdf: str | None = None) -> str:
        """The same content as Markdown (tables as pipe tables); every string from outside made
        safe there (:mod:`tcr_accuracy.view.markdown_text`: no raw HTML, no fence closed early)."""
        from . import markdown_text as md

        out = []
        if self.first_page is not None:
            out += [self.first_page[1].rstrip("\n"), "", "---", "", f"# Technical detail: {md.line(self.title)}", ""]
        else:
            out += [f"# {md.line(self.title)}", ""]
        out += [f"Written {md.line(self.created)} by tcr-accuracy {__version__}."
                + (f" Printed: [{md.label(pdf)}]({md.href(pdf)})." if pdf else ""), ""]
        for item in self.items:
            if isinstance(item, _Text):
                if item.heading:
                    out += [f"## {md.line(item.heading)}", ""]
                out += [md.text(item.text.strip()), ""]
            elif isinstance(item, _Preformatted):
                if item.heading:
                    out += [f"## {md.line(item.heading)}", ""]
                out += [*md.fenced(item.text), ""]
            elif isinstance(item, _Table):
                out += [f"## {md.line(item.title)}", "",
                        "| " + " | ".join(md.cell(c) for c in item.columns) + " |",
                        "|" + "|".join("---" for _ in item.columns) + "|"]
                out += ["| " + " | ".join(md.cell(v) for v in row) + " |" for row in item.rows]
                out.append("")
                if item.note:
                    out += [md.text(item.note), ""]
            elif isinstance(item, _Links):
                out += [f"## {md.line(item.heading)}", ""] + [f"- [{md.label(label)}]({md.href(href)})"
                                                              for label, href in item.links] + [""]
            elif isinstance(item, _Figure):
                out += [f"![{md.label(item.caption)}]({md.href(item.filename)})", "", f"*{md.line(item.caption)}*", ""]
            elif isinstance(item, _Scene):
                out += [f"[{md.label(item.caption)} (3D, opens in a browser)]({md.href(item.filename)})", ""]
        out += ["## How this report was made", "", *md.fenced(self.command), "",
                "| software | version |", "|---|---|"]
        out += [f"| {md.cell(k)} | {md.cell(v)} |" for k, v in versions().items()]
        return "\n".join(out) + "\n"

    def files(self) -> dict[str, bytes]:
        """What the report folder holds, by file name: the PNGs, the scene pages, ``report.pdf``
        (with ``print_pdf``, when Chromium printed it), ``report.md`` and ``index.html``, last,
        so that a writer going in order never leaves an index naming a file not yet there."""
        pdf = self._printed() if self.print_pdf else None
        pdf_name = self.PDF_NAME if pdf is not None else None
        files: dict[str, bytes] = {}
        for item in self.items:
            if isinstance(item, _Figure):
                files[item.filename] = item.png
            elif isinstance(item, _Scene):
                files[item.filename] = item.page.encode("utf-8")
        if pdf is not None:
            files[self.PDF_NAME] = pdf
        files["report.md"] = self.markdown(pdf=pdf_name).encode("utf-8")
        files["index.html"] = self.html(pdf=pdf_name).encode("utf-8")
        return files

    def _printed(self) -> bytes | None:
        """The page printed to PDF by Chromium from a copy of it in a temporary folder (Chromium
        reads files, and the report folder is written by the caller afterwards), or None with
        ``pdf_problem`` saying why."""
        import tempfile

        from .pdf import print_to_pdf

        with tempfile.TemporaryDirectory(prefix="tcr-print-") as tmp:
            folder = Path(tmp)
            for item in self.items:  # the 3D views are not printed (see the print CSS)
                if isinstance(item, _Figure):
                    (folder / item.filename).write_bytes(item.png)
            page = folder / "index.html"
            page.write_text(self.html(pdf=self.PDF_NAME), encoding="utf-8")
            pdf, self.pdf_problem = print_to_pdf(page)
        return pdf
