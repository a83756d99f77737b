"""What an analysis command shows besides its printed text: report, plots, 3D view, JSON.

Every analysis command ends the same way: the tables it prints, the plots it draws and
its 3D view go, as asked, to ``--out DIR`` (an HTML report, ``DIR/index.html``, through
:class:`tcr_accuracy.view.report.Report`), ``--plots DIR`` (PNG files), ``--view [HTML]`` /
``--serve`` (meshcat) and ``--json [FILE]``. A command adds the options with
:func:`add_output_arguments` and hands its results to a :class:`RunOutput`::

    out = RunOutput(args, "Monte Carlo accuracy")
    out.add_table("TCP error", columns, rows, units=[...])      # what the command prints
    out.add_plots(lambda folder: plots_of(result, folder))      # PlotFiles: --plots and/or --out
    if out.scene_wanted:                                        # --view, --serve or --out
        out.set_scene(build_scene(...), "TCP error cloud")
    return out.finish(payload, lambda: print_results(...))

The output options are checked when the command line is read (their argparse types), so
a path that cannot be written fails before any work. Every file of the run, plots
included, is staged (:func:`tcr_accuracy.cli.staging.staged_outputs`, around every command)
and written only when the command ends without an error, each through a temporary file
and a rename (plots are drawn in memory, as PNG bytes, and written only where ``--plots``
asks). The ``--out`` and ``--plots`` folders are written whole
(:func:`tcr_accuracy.cli.staging.stage_folder`): new content beside the old, swapped in at once,
other files of the old folder carried over. So a run that fails half-way leaves no report,
no plots and no JSON, never half a file, and never a report folder mixing two runs. Status
lines (which file was written) go to stderr and are silenced by ``--quiet``; results go to
stdout.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable

from .common import EXIT_OK, add_quiet_argument, emit_json, output_file, output_folder, status


def add_output_arguments(parser: argparse.ArgumentParser, *, plots: bool = True, view: bool = False,
                         json_help: str = "write JSON (SI units, unit-suffixed keys) to FILE, or to stdout "
                                          "without FILE") -> None:
    """Add ``--json [FILE]``, ``--out DIR``, ``--quiet`` and, as asked, ``--plots DIR`` and
    ``--view [HTML]`` / ``--serve`` / ``--open``."""
    parser.add_argument("--json", nargs="?", const="-", default=None, type=output_file, metavar="FILE",
                        help=json_help)
    parser.add_argument("--out", default=None, type=output_folder, metavar="DIR",
                        help="write an HTML report to DIR/index.html (tables, plots, 3D view, the command "
                             "and the versions; also DIR/report.md)")
    if plots:
        parser.add_argument("--plots", default=None, type=output_folder, metavar="DIR",
                            help="write the PNG plots to DIR")
    if view:
        from .view import add_view_arguments

        add_view_arguments(parser)
    add_quiet_argument(parser)


def progress_bar(total: int | None, desc: str, quiet: bool, **tqdm_options):
    """A tqdm bar on stderr as ``(update, close)``; off with ``--quiet`` or when stderr is no terminal."""
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, file=sys.stderr, leave=False,
               disable=quiet or not sys.stderr.isatty(), **tqdm_options)
    return bar.update, bar.close


class RunOutput:
    """The report, plots, 3D view and JSON of one command run (see the module docstring).

    Parameters
    ----------
    args : argparse.Namespace
        With the options of :func:`add_output_arguments`.
    title : str
        The report's title.
    """

    def __init__(self, args: argparse.Namespace, title: str):
        if getattr(args, "open", False) and not getattr(args, "serve", False):
            from ..exceptions import InputError

            raise InputError("--open needs --serve")
        self.args = args
        self.plot_files: list[str] = []
        self.scene = None
        self.report = None
        if getattr(args, "out", None) is not None:
            from ..view.report import Report

            self.report = Report(title, command=getattr(args, "argv", None))

    @property
    def scene_wanted(self) -> bool:
        """Whether a 3D scene will be shown (``--view``, ``--serve`` or ``--out``): build it only then."""
        a = self.args
        return self.report is not None or getattr(a, "view", None) is not None or getattr(a, "serve", False)

    @property
    def plots_wanted(self) -> bool:
        return self.report is not None or getattr(self.args, "plots", None) is not None

    # -- content ---------------------------------------------------------------------
    def add_text(self, text: str, heading: str | None = None) -> None:
        if self.report is not None:
            self.report.add_text(text, heading)

    def add_preformatted(self, text: str, heading: str | None = None) -> None:
        """Printed text kept as printed (line breaks and alignment) in the report."""
        if self.report is not None:
            self.report.add_preformatted(text, heading)

    def add_table(self, title: str, columns, rows, units=None, *, note: str | None = None,
                  float_format: str = "{:.4g}") -> None:
        """A table of the report (values in display units, named in ``units`` or the column names)."""
        if self.report is not None:
            self.report.add_table(title, columns, rows, units, note=note, float_format=float_format)

    def add_plots(self, draw: Callable[[Path], list], captions: dict[str, str] | None = None) -> list[str]:
        """Draw the plots if ``--plots`` or ``--out`` asks for them.

        Parameters
        ----------
        draw : callable
            ``draw(folder) -> list of PlotFile``: the command's plot function, each plot meant
            for a file in ``folder`` (the ``--plots`` folder, or a name only, without it).
        captions : dict, optional
            Report captions by file name (default: the file name).

        Returns
        -------
        list of str
            The files written to the ``--plots`` folder (empty without ``--plots``).
        """
        if not self.plots_wanted:
            return []
        folder = getattr(self.args, "plots", None)
        plots = draw(Path(folder if folder is not None else "plots"))
        if self.report is not None:
            for plot in plots:
                name = plot.path.name
                self.report.add_figure(plot.png, (captions or {}).get(name, name))
        if folder is None:
            return []
        from .writers import write_plots

        files = write_plots(plots, folder)  # its PNGs are swapped in together at the end of the run
        self.plot_files += files
        return files

    def set_scene(self, scene, caption: str = "3D view (meshcat)") -> None:
        """The run's :class:`~tcr_accuracy.view.viewer.Scene`, for ``--view``, ``--serve`` and the report."""
        self.scene = scene
        if self.report is not None:
            self.report.add_scene(scene.static_html(), caption)

    # -- output ----------------------------------------------------------------------
    def finish(self, payload: dict, print_results: Callable[[], None]) -> int:
        """Write what was asked, print the results, then serve the view if asked.

        ``--json -`` prints the JSON instead of the results. The files go in this order:
        3D view, JSON, report (its ``index.html`` last). Returns the exit code (0).
        """
        from .view import serve_view, write_view

        args = self.args
        if self.plot_files:
            payload["plots"] = list(self.plot_files)
        if self.scene is not None:
            write_view(self.scene, args)
        target = getattr(args, "json", None)
        if target is not None and target != "-":
            emit_json(payload, target)
            status(args, f"JSON written to {target}")
        if self.report is not None:
            from .writers import write_report

            index = write_report(self.report, args.out)
            status(args, f"report written to {index}")
            from .report import pdf_status

            pdf_status(args, self.report)  # a calibration report's PDF, or why there is none
        if self.plot_files:
            status(args, "plots: " + ", ".join(self.plot_files))
        if target == "-":
            emit_json(payload, "-")
        else:
            print_results()
        if self.scene is not None:
            serve_view(self.scene, args)
        return EXIT_OK
