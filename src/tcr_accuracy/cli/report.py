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
                        "--json, compare --json, and export's DIR/accuracy.json (each delivered form judged)")
    p.add_argument("--out", required=True, type=output_folder, metavar="DIR", help="the report folder")
    add_campaign_arguments(p)
    add_quiet_argument(p)
    p.set_defaults(run=_run_report)


def add_campaign_arguments(parser) -> None:
    """``--campaign FILE`` and the flags that fill or override it: what the first page identifies
    (customer, robot serial, instrument certificate, operator, title) and the limits it judges by."""
    group = parser.add_argument_group(
        "the calibration report's first page (with --out; see docs/report.md)")
    group.add_argument("--campaign", default=None, metavar="FILE",
                       help="a campaign file (YAML or TOML): title, customer, robot model and serial, instrument "
                            "name, serial and certificate, temperature range, date, operator, limits_mm, names "
                            "to sign; the flags below override it")
    group.add_argument("--title", default=None, type=text_argument,
                       help="the report's title (default: 'Calibration report: ROBOT')")
    group.add_argument("--customer", default=None, type=text_argument, metavar="TEXT", help="the customer")
    group.add_argument("--serial", default=None, type=text_argument, metavar="TEXT",
                       help="the robot's serial number")
    group.add_argument("--operator", default=None, type=text_argument, metavar="TEXT", help="who measured the robot")
    group.add_argument("--certificate", default=None, type=text_argument, metavar="TEXT",
                       help="the instrument's calibration certificate (number, date)")
    group.add_argument("--limit-mm", action="append", default=None, type=limit_argument, metavar="[FIGURE=]MM",
                       help="a limit the result is judged against [mm], repeatable: FIGURE is one of "
                            f"{', '.join(LIMIT_NAMES)} (default max: the calibrated TCP position error's held-out "
                            "max); e.g. --limit-mm 0.3 --limit-mm ap=0.25")
    parser.set_defaults(campaign_facts=None)


#: The figures --limit-mm names (the keys of the campaign file's limits_mm).
LIMIT_NAMES = ("max", "rms", "mean", "ap", "rp")


def text_argument(value: str) -> str:
    """argparse type of the first page's text flags: the check a campaign file's text has
    (:func:`tcr_accuracy.io.campaign.text_problem`: no control or bidirectional-override character,
    at most a line), on the text as the page shows it (white space runs as one space)."""
    import argparse

    from ..io.campaign import text_problem

    text = " ".join(value.split())
    problem = text_problem(text)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return text


def limit_argument(text: str) -> tuple[str, float]:
    """argparse type of ``--limit-mm``: ``0.3`` (the held-out max) or ``FIGURE=MM``."""
    import argparse

    from ..exceptions import InputError
    from ..io.campaign import limit_mm
    from ..units import parse_number

    figure, _, value = text.rpartition("=")
    figure = figure.strip() or "max"
    if figure not in LIMIT_NAMES:
        raise argparse.ArgumentTypeError(f"{text}: want FIGURE=MM with FIGURE one of {', '.join(LIMIT_NAMES)}")
    try:
        return figure, limit_mm(parse_number(value), "")
    except (ValueError, InputError):
        raise argparse.ArgumentTypeError(f"{text}: want a limit in mm, a number > 0 (FIGURE=MM or MM)") from None


#: The flags of add_campaign_arguments, as (dest, field of CampaignFacts).
_CAMPAIGN_FLAGS = (("title", "title"), ("customer", "customer"), ("serial", "robot_serial"),
                   ("operator", "operator"), ("certificate", "certificate"))


def read_campaign_arguments(args):
    """The campaign facts of ``--campaign`` and the flags (read once, before any work; kept as
    ``args.campaign_facts``). A flag without ``--out`` is refused: there is no page to show it."""
    from ..exceptions import InputError
    from ..io.campaign import CampaignFacts, read_campaign

    given = [f"--{dest.replace('_', '-')}" for dest in ("campaign", *(d for d, _ in _CAMPAIGN_FLAGS), "limit_mm")
             if getattr(args, dest, None) is not None]
    if given and getattr(args, "out", None) is None:
        raise InputError(f"{given[0]}: fills the report's first page; give --out DIR for the report")
    figures = [figure for figure, _ in args.limit_mm or ()]
    twice = next((f for f in figures if figures.count(f) > 1), None)
    if twice is not None:  # argparse keeps the last: --limit-mm max=0.05 --limit-mm max=0.2 judged by 0.2 alone
        given = " and ".join(f"{value:g}" for figure, value in args.limit_mm if figure == twice)
        raise InputError(f"--limit-mm: {twice} is limited twice ({given} mm); give one limit per figure")
    facts = read_campaign(args.campaign) if args.campaign else CampaignFacts()
    facts = facts.updated(**{field: getattr(args, dest) for dest, field in _CAMPAIGN_FLAGS},
                          limits_mm=dict(args.limit_mm) if args.limit_mm else None)
    args.campaign_facts = facts
    return facts


def _run_report(args) -> int:
    from ..exceptions import InputError
    from ..results.kinds import kind_of
    from ..view.calibration_report import Campaign, RobotFacts
    from ..view.result_tables import add_technical_tables
    from ..view.uncertainty_words import add_budget_tables
    from ..view.report import Report

    facts = read_campaign_arguments(args)
    files = list(args.results)
    seen: dict = {}
    for path in files:  # one file through two paths (a link, ./x) is still one result
        key = _identity(path)
        if key in seen:
            also = "" if seen[key] == path else f" (as {seen[key]})"
            raise InputError(f"RESULT.json: {path} is given twice{also}")
        seen[key] = path
    documents = [(path, _read_result(path)) for path in files]  # each validated (results.files)
    for key, what in (("robot", "robots"), ("tool_frame", "TCP frames")):
        given = {doc[key] for _, doc in documents if key in doc}
        if len(given) > 1:
            named = ", ".join(f"{path} ({doc.get(key, 'not recorded')})" for path, doc in documents)
            raise InputError(f"RESULT.json: results of different {what} ({named}): one report is of one robot and TCP")
    _check_exports_match(documents)
    robot = _robot_facts(RobotFacts.from_documents(documents), documents)
    title = facts.title or f"Calibration report: {robot.name}"
    report = Report(title, command=getattr(args, "argv", None))
    links = [(f"{kind_of(doc, path)} JSON", path) for path, doc in documents]
    for path, doc in documents:
        for key, label, suffix in (("as_built_urdf", "calibration URDF", ".urdf"),
                                   ("as_built_effects", "the whole model", ".effects.yaml")):
            found = _find(doc[key], path, suffix) if isinstance(doc.get(key), str) else None
            if found is not None:
                links.append((label, str(found)))
    campaign = Campaign(robot, documents)
    add_calibration_page(report, args, campaign, links)
    add_technical_tables(report, campaign)
    add_budget_tables(report, campaign)
    _add_result_plots(report, campaign)
    from .writers import write_report

    index = write_report(report, args.out)
    status(args, f"report written to {index}")
    pdf_status(args, report)
    for line in verdict_lines(campaign):
        print(f"Result: {line}")
    return EXIT_OK


def verdict_lines(campaign) -> list[str]:
    """The first page's pass/fail lines, one per form judged (``STATUS for FORM: why``)."""
    from ..view.accuracy_verdict import form_verdicts
    from ..view.uncertainty_words import exports_of

    diagnoses, isos = campaign.of_kind("diagnosis"), campaign.of_kind("iso9283")
    return [v.line for v in form_verdicts(diagnoses[-1][1] if diagnoses else None, isos, exports_of(campaign),
                                          campaign.facts.limits_mm)]


def _check_exports_match(documents) -> None:
    """An export result judged beside a diagnosis is that diagnosis' export (by its file name): the
    forms of another calibration are not this one's."""
    from ..exceptions import InputError
    from ..results.kinds import kind_of

    diagnoses = [Path(path).name for path, doc in documents if kind_of(doc, path) == "diagnosis"]
    for path, doc in documents:
        if kind_of(doc, path) == "export" and diagnoses and doc["diagnosis"] != diagnoses[-1]:
            raise InputError(f"RESULT.json: {path} is the export of {doc['diagnosis']}, not of {diagnoses[-1]} (the "
                             "diagnosis judged): give the export of the same diagnosis")


def _identity(path: str):
    """(device, inode) of an existing file, else its real path: one key per file however spelt."""
    try:
        st = os.stat(path)
    except OSError:
        return os.path.realpath(path)
    return st.st_dev, st.st_ino


def _read_result(path: str) -> dict:
    """The JSON form of a result read through the one reader (:func:`tcr_accuracy.read_result`)."""
    from ..results.types import read_result

    return read_result(path, hint="give the --json result of diagnose, iso9283 evaluate or compare, or export's "
                                  "accuracy.json").to_dict()


def _robot_facts(facts, documents):
    """The robot's joints from the robot itself when the results do not record them and it loads;
    where it loads, each diagnosis' parameters are held to their effects' physical ranges
    (:func:`tcr_accuracy.results.files.check_physics`): a forged value never reaches the page."""
    if facts.source in ("", "not recorded"):
        return facts
    from ..exceptions import InputError
    from ..model.robot import load_robot
    from ..results.kinds import kind_of
    from ..view.calibration_report import RobotFacts
    from ..results.files import check_physics

    try:
        tool = None if facts.tool_frame == "not recorded" else facts.tool_frame
        robot = load_robot(facts.source, tool)
    except InputError:  # a URDF that is not here: the results' own facts
        return facts
    for path, doc in documents:
        if kind_of(doc, path) == "diagnosis":
            check_physics(doc, robot, path)
    return facts if facts.joints else RobotFacts.of_robot(robot, facts.source)


def _find(path: str, result: str, suffix: str) -> Path | None:
    """A file a result names, if it is what the key says (a regular file whose name ends in
    ``suffix``) and lies in the result's folder or the current one: as given (from where the
    command ran), else beside the result. Anything else (``/proc/<pid>/environ``) is not linked."""
    import os
    import stat

    roots = {Path(os.path.realpath(Path(result).parent)), Path(os.getcwd()).resolve()}
    for candidate in (Path(path), Path(result).parent / Path(path).name):
        real = Path(os.path.realpath(candidate))
        try:
            regular = stat.S_ISREG(os.stat(real).st_mode)
        except OSError:
            continue
        if regular and real.name.endswith(suffix) and real.parent in roots:
            return candidate
    return None


def _add_result_plots(report, campaign) -> None:
    """The plots of the results, drawn from their JSON (after the tables)."""
    from ..view.plots_results import write_result_plots

    for plot, caption in write_result_plots(campaign.documents, Path("plots"), campaign.facts.limits_mm):
        report.add_figure(plot.png, caption)


def add_calibration_page(report, args, campaign, files) -> None:
    """Open ``report`` with the calibration report's first page and have it printed to PDF.

    Parameters
    ----------
    report : tcr_accuracy.view.report.Report
    args : argparse.Namespace
        The command's: ``args.out`` is the report folder (``files`` are linked relative to it),
        ``args.campaign_facts`` (or the flags of :func:`add_campaign_arguments`) what the page
        identifies and the limits it judges by.
    campaign : tcr_accuracy.view.calibration_report.Campaign
    files : list of (label, path)
        Files written with the report or read by it (paths as the user gave them).
    """
    from ..view.calibration_report import first_page

    facts = args.campaign_facts if getattr(args, "campaign_facts", None) is not None else \
        read_campaign_arguments(args)
    campaign.facts = facts
    base = Path(args.out).resolve()
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
