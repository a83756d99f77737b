"""``tcr-accuracy import``: a tracker export and a joint log into the measurement CSV."""

from __future__ import annotations

from .common import (EXIT_OK, add_quiet_argument, add_robot_arguments, check_csv_memory, number, output_file_only,
                     status)


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "import", help="turn a tracker export (and a timestamped joint log) into a measurement CSV",
        description="Reads a laser tracker's or motion-capture system's export (semicolons, tabs or "
                    "commas; decimal commas; metadata lines above the header; units in the header or "
                    "the cells, e.g. 'X [mm]', '1234,5 mm', inches) and, with --joints, the robot's "
                    "joint log, joins each point to the log sample nearest in time (within "
                    "--tolerance-ms) and writes the measurement CSV that diagnose, predict and "
                    "compensate read. Points that join no log sample are listed, not dropped silently.",
    )
    p.add_argument("tracker", metavar="TRACKER_FILE", help="the tracker's export (delimited text)")
    p.add_argument("--map", nargs="+", action="extend", default=[], metavar="TARGET=SOURCE",
                   help="tracker columns: measurement-CSV column = the export's header, e.g. "
                        "x_mm=\"Point X\" y_mm=\"Point Y\" z_mm=\"Point Z\" time_s=\"Time\" (default: "
                        "found by name: X, Point X, X [mm], Time, Timestamp, ...)")
    p.add_argument("--joints", metavar="LOG", default=None,
                   help="the robot's joint log: a timestamp column and the joint columns (named like "
                        "the measurement CSV, j1_deg ..., or mapped with --log-map)")
    p.add_argument("--log-map", nargs="+", action="extend", default=[], metavar="TARGET=SOURCE",
                   help="joint-log columns, e.g. j1_deg=\"A1\" time_s=\"Timestamp\"")
    p.add_argument("--tolerance-ms", type=number(low=0, low_open=True, high=3.6e6, unit="ms"), default=50.0,
                   help="largest time between a tracker point and the joint-log sample it is joined to "
                        "[ms] (default 50)")
    add_robot_arguments(p)
    p.add_argument("--out", required=True, type=output_file_only, metavar="CSV", help="measurement CSV to write")
    add_quiet_argument(p)
    p.set_defaults(run=_run_import)


#: Memory [bytes] importing takes per line of a tracker export or joint log beyond the 12 per
#: byte of text check_csv_memory counts: cells as strings, parsed numbers and the joined rows
#: (measured: 649 MB for a 22 MB export of 200,000 lines).
IMPORT_ROW_BYTES = 2_000


def _run_import(args) -> int:
    from pathlib import Path

    from .staging import write_text
    from ..exceptions import InputError
    from ..io.measurements import parse_measurements
    from ..io.tracker_import import import_tracker
    from .common import robot_from_args

    for path in (args.tracker, args.joints):  # before either is read
        if path is not None:
            check_csv_memory(args, path, "importing", IMPORT_ROW_BYTES, hint="use a smaller file")
    robot = robot_from_args(args)
    out = Path(args.out)
    result = import_tracker(args.tracker, parse_map(args.map, "--map"), args.joints,
                            parse_map(args.log_map, "--log-map"), args.tolerance_ms * 1e-3)
    if not result.rows:
        nearest = min((u.nearest_s for u in result.unjoined), default=float("inf"))
        raise InputError(f"{args.tracker}: none of its {result.n_tracker_rows} points has a joint-log sample "
                         f"within {args.tolerance_ms:g} ms (the nearest is {nearest:.3f} s away): do the two "
                         "clocks agree? a larger --tolerance-ms, or shift one file's times")
    joined = f", joined with {args.joints} within {args.tolerance_ms:g} ms" if args.joints else ""
    text = result.csv_text(f"imported by tcr-accuracy import from {args.tracker}{joined}")
    # checked as diagnose will read it (the same parser, on the text), before anything is written
    try:
        parse_measurements(text, robot, source=str(out), min_rows=1)
    except InputError as exc:
        raise InputError(f"{exc} (in the imported rows)", parameter=exc.parameter, value=exc.value) from None
    write_text(out, text)
    print(f"{len(result.rows)} of {result.n_tracker_rows} tracker points from {args.tracker}{joined} "
          f"-> {out} ({robot.name}: {', '.join(result.columns)})")
    if result.unjoined:
        print(f"{len(result.unjoined)} not joined (no joint-log sample within {args.tolerance_ms:g} ms), "
              "left out of the CSV:")
        for u in result.unjoined:
            print(f"  {args.tracker} row {u.line}: time {u.time}, nearest joint-log sample {u.nearest_s:.3f} s away")
    status(args, f"measurements written to {out}")
    return EXIT_OK


def parse_map(items, option: str = "--map") -> dict[str, str]:
    """``['x_mm=Point X', ...]`` (``--map``, ``--log-map``) -> {target: source}; one-line errors naming
    the option."""
    from ..exceptions import InputError

    out: dict[str, str] = {}
    for item in items or []:
        target, sep, source = item.partition("=")
        target, source = target.strip(), source.strip().strip('"').strip("'")
        if not sep or not target or not source:
            raise InputError(f"{option} {item!r}: expected TARGET=SOURCE, e.g. x_mm=\"Point X\"")
        if target in out:
            raise InputError(f"{option} {item!r}: {target} is mapped twice")
        twice = next((t for t, s in out.items() if s == source), None)
        if twice is not None:
            raise InputError(f"{option} {item!r}: column {source!r} is already mapped to {twice}; "
                             "one column fills one target")
        out[target] = source
    return out
