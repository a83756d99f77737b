"""Files the layers below the command line describe and only the edge writes.

The layers below ``cli`` return what a file holds (:func:`tcr_accuracy.io.measurements.format_measurements`,
:meth:`tcr_accuracy.view.report.Report.files`, a plot's
:class:`~tcr_accuracy.view.plots_common.PlotFile`, :meth:`tcr_accuracy.view.viewer.Scene.static_html`);
the functions here write it through the one output writer (:mod:`tcr_accuracy.cli.staging`):
whole, through a temporary file and a rename, never through a link planted in an output
folder, never over an input of the run.
"""

from __future__ import annotations

from pathlib import Path

from .staging import stage_folder, write_bytes, write_text


def write_measurements(path, robot, mset, unit: str = "mm", comment: str | None = None) -> Path:
    """Write a measurement CSV whole (temporary file + rename).

    Parameters
    ----------
    path : str or Path
        The CSV file to write.
    robot : RobotModel
        Names the joint columns and their units.
    mset : MeasurementSet
        The rows to write [SI].
    unit : str, default="mm"
        ``mm``: positions in mm and joints in deg (mm for prismatic joints); ``m``: SI.
    comment : str, optional
        Written as ``#`` lines above the header.

    Returns
    -------
    Path
        The path written.

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> q = np.random.default_rng(0).uniform(-1, 1, (20, 6))
    >>> measured = tcr.MeasurementSet(joint_names=list(robot.joint_names), q=q, position=tcr.tcp_poses(robot, q).position)
    >>> path = tcr.write_measurements(tempfile.mkdtemp() + "/m.csv", robot, measured)
    >>> len(tcr.read_measurements(path, robot))
    20
    """
    from ..io.measurements import format_measurements

    return write_text(Path(path), format_measurements(robot, mset, unit, comment))


def write_report(report, folder) -> Path:
    """Write a :class:`~tcr_accuracy.view.report.Report` into ``folder`` (created if missing),
    ``index.html`` last; inside a staged run the folder is written whole (swapped in at once,
    other files of the old folder kept). Returns the path of ``index.html``."""
    folder = Path(folder)
    stage_folder(folder)
    for name, data in report.files().items():
        write_bytes(folder / name, data)
    return folder / "index.html"


def write_plots(plots, folder=None) -> list[str]:
    """Write each :class:`~tcr_accuracy.view.plots_common.PlotFile` to its path, the folder
    ``folder`` (their common folder, if given) written whole; returns the paths written."""
    if folder is not None:
        stage_folder(folder)
    return [str(write_bytes(plot.path, plot.png)) for plot in plots]
