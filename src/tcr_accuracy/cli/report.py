"""``tcr-accuracy report``: one calibration report from the JSON results of a campaign.

Edge layer: reads the ``--json`` results of ``diagnose``, ``iso9283 evaluate`` and ``compare``,
checks they are of one robot, and writes the calibration report
(:mod:`tcr_accuracy.view.calibration_report`: a first page to sign, the technical tables after
it) as ``DIR/index.html``, ``DIR/report.md`` and, with Chromium, ``DIR/report.pdf``. The
``--out`` reports of those three commands open with the same first page
(:func:`add_calibration_page`).
"""

from __future__ import annotations

import os
from pathlib import Path

from .common import EXIT_OK, add_quiet_argument, output_folder, status


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "report", help="a calibration report to sign from a campaign's JSON results (HTML, Markdown, PDF)",
        description="Gather the --json results of diagnose, iso9283 evaluate and compare of one robot into one "
                    "calibration report: a first page for the customer (robot, instrument, date, data, accuracy "
                    "before and after, the effects found with their values, units, 95 % intervals and physical "
                    "ranges, what remains, what to do next, lines to sign), the technical tables after it, and "
                    "links to the files. Writes DIR/index.html, DIR/report.md and, when headless Chromium is "
                    "installed, DIR/report.pdf (A4).")
    p.add_argument("results", metavar="RESULT.json", nargs="+",
                   help="JSON results: diagnose --json (the last one is the calibration shown), iso9283 evaluate "
                        "--json, compare --json")
    p.add_argument("--out", required=True, type=output_folder, metavar="DIR", help="the report folder")
    p.add_argument("--title", default=None, help="the report's title (default: 'Calibration report: ROBOT')")
    add_quiet_argument(p)
    p.set_defaults(run=_run_report)


def _run_report(args) -> int:
    from ..exceptions import InputError
    from ..view.calibration_report import Campaign, RobotFacts, add_technical_tables, kind_of
    from ..view.report import Report

    files = list(args.results)
    seen: dict = {}
    for path in files:  # one file through two paths (a link, ./x) is still one result
        key = _identity(path)
        if key in seen:
            raise InputError(f"RESULT.json: {path} is given twice" + ("" if seen[key] == path else f" (as {seen[key]})"))
        seen[key] = path
    documents = [(path, _read_result(path)) for path in files]
    for path, doc in documents:
        kind_of(doc, path)
    robots = {doc["robot"] for _, doc in documents if isinstance(doc.get("robot"), str)}
    if len(robots) > 1:
        named = ", ".join(f"{path} ({doc.get('robot')})" for path, doc in documents)
        raise InputError(f"RESULT.json: results of different robots ({named}): one report is of one robot")
    robot = _robot_facts(RobotFacts.from_documents(documents))
    title = args.title or f"Calibration report: {robot.name}"
    report = Report(title, command=getattr(args, "argv", None))
    links = [(f"{kind_of(doc, path)} JSON", path) for path, doc in documents]
    for path, doc in documents:
        for key, label in (("as_built_urdf", "as-built URDF"), ("as_built_effects", "effects YAML")):
            if isinstance(doc.get(key), str) and _find(doc[key], path) is not None:
                links.append((label, str(_find(doc[key], path))))
    campaign = Campaign(robot, documents)
    add_calibration_page(report, args.out, campaign, links)
    add_technical_tables(report, campaign)
    from .writers import write_report

    index = write_report(report, args.out)
    status(args, f"report written to {index}")
    pdf_status(args, report)
    return EXIT_OK


def _identity(path: str):
    """(device, inode) of an existing file, else its real path: one key per file however spelt."""
    try:
        st = os.stat(path)
    except OSError:
        return os.path.realpath(path)
    return st.st_dev, st.st_ino


def _read_result(path: str):
    from ..input_files import read_json_file

    return read_json_file(path, "JSON result", hint="give the --json result of diagnose, iso9283 evaluate or compare")


def _robot_facts(facts):
    """The robot's joints from the robot itself when the results do not record them and it loads."""
    if facts.joints or facts.source in ("", "not recorded"):
        return facts
    from ..exceptions import InputError
    from ..model.robot import load_robot
    from ..view.calibration_report import RobotFacts

    try:
        tool = None if facts.tool_frame == "not recorded" else facts.tool_frame
        return RobotFacts.of_robot(load_robot(facts.source, tool), facts.source)
    except InputError:
        return facts


def _find(path: str, result: str) -> Path | None:
    """A file a result names: as given (from where the command ran), else beside the result."""
    for candidate in (Path(path), Path(result).parent / Path(path).name):
        if candidate.is_file():
            return candidate
    return None


def add_calibration_page(report, out_dir, campaign, files) -> None:
    """Open ``report`` with the calibration report's first page and have it printed to PDF.

    Parameters
    ----------
    report : tcr_accuracy.view.report.Report
    out_dir : path
        The report folder: ``files`` are linked relative to it.
    campaign : tcr_accuracy.view.calibration_report.Campaign
    files : list of (label, path)
        Files written with the report or read by it (paths as the user gave them).
    """
    from ..view.calibration_report import first_page

    base = Path(out_dir).resolve()
    campaign.files = [(label if Path(path).name in label else f"{label} ({Path(path).name})",
                       Path(os.path.relpath(Path(path).resolve(), base)).as_posix()) for label, path in files]
    report.set_first_page(*first_page(campaign, report.created))
    report.print_pdf = True


def pdf_status(args, report) -> None:
    """One status line on the printed PDF, or on why there is none."""
    if not report.print_pdf:
        return
    if report.pdf_problem:
        status(args, f"PDF not written: {report.pdf_problem}; the HTML report is complete")
    else:
        status(args, f"PDF written to {Path(args.out) / report.PDF_NAME}")
