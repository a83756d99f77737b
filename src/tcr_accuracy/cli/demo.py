"""``tcr-accuracy demo``: the main job on the built-in tool-changer.

Runs, in one go, the two analyses a user of the tool-changer starts with and writes one
report folder:

1. the seed paper's Monte Carlo accuracy analysis at its working pose (the
   ``montecarlo`` command with the Table 2 error sources), and
2. the sim-to-real gap diagnosis (the ``diagnose`` command) of the bundled measurement
   set: 300 laser-tracker readings of a simulated as-built tool-changer carrying the
   150 kg disc cutter in 60 % of the poses. Only after the diagnosis is the set's hidden
   truth read, to show it next to the answer.

Each step writes its own report (``DIR/accuracy/``, ``DIR/diagnosis/``); ``DIR/index.html``
sums them up and links them, and is written last.
"""

from __future__ import annotations

import importlib.resources
import json
from pathlib import Path

from .common import (EXIT_ANALYSIS, EXIT_OK, MAX_COUNT, Parser, add_quiet_argument, integer, output_folder, seed_value,
                     status)

DATA = "data"
MEASUREMENTS = "tool_changer_cutter.csv"
TRUTH = "tool_changer_cutter_truth.yaml"


def truth_verdict(hidden: list[str], selected: list[str]) -> str:
    """The diagnosis' effects against the hidden ones, in words."""
    missed = [e for e in hidden if e not in selected]
    extra = [e for e in selected if e not in hidden]
    if not missed and not extra:
        return "all hidden effects found, none invented"
    return f"missed: {', '.join(missed) or 'none'}; not hidden but selected: {', '.join(extra) or 'none'}"


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "demo", help="the main job on the built-in tool-changer: accuracy, gap diagnosis, report",
        description="On the built-in shield-machine tool-changer: the seed paper's Monte Carlo "
                    "accuracy analysis at its working pose (Table 2 error sources), then the "
                    "diagnosis of a bundled measurement set of a simulated as-built tool-changer "
                    "carrying a 150 kg disc cutter, and an HTML report of both in --out DIR.",
    )
    p.add_argument("--out", default="tcr-accuracy-demo", type=output_folder, metavar="DIR",
                   help="report folder (default: ./tcr-accuracy-demo); DIR/index.html is the report")
    p.add_argument("--samples", type=integer(low=2, high=MAX_COUNT), default=20_000,
                   help="Monte Carlo samples (default 20000)")
    p.add_argument("--seed", type=seed_value, default=0, help="random seed (default 0)")
    add_quiet_argument(p)
    p.set_defaults(run=_run_demo)


def bundled_file(name: str) -> Path:
    """Path of a file shipped in tcr_accuracy/data."""
    return Path(str(importlib.resources.files("tcr_accuracy") / DATA / name))


def _run_step(argv: list[str], max_memory_gb: float | None = None) -> int:
    """One step of the demo, run as the command line would run it (its report names the
    command), under the demo's own error handling: a parser with the two step commands only,
    so the demo does not import the command registry that lists it. The demo's memory budget
    (``--max-memory-gb``) is the step's."""
    from .diagnose import add_parsers as add_diagnose
    from .montecarlo import add_parsers as add_montecarlo

    parser = Parser(prog="tcr-accuracy")
    sub = parser.add_subparsers(dest="command", parser_class=Parser)
    add_montecarlo(sub)
    add_diagnose(sub)
    args = parser.parse_args(argv)
    args.argv = list(argv)
    args.max_memory_gb = max_memory_gb
    return args.run(args)


def _run_demo(args) -> int:
    out_dir = Path(args.out)  # checked by its argparse type
    new_folder = not out_dir.exists()
    out_dir.mkdir(parents=True, exist_ok=True)  # the steps' output options are checked against it
    code = EXIT_ANALYSIS
    try:
        code = _demo_steps(args, out_dir)
        return code
    finally:
        if code != EXIT_OK and new_folder:  # every file waits for the end of the run: still empty
            try:
                out_dir.rmdir()
            except OSError:
                pass


def _demo_steps(args, out_dir: Path) -> int:
    from ..input_files import read_settings_file
    from ..view.report import Report

    quiet = ["--quiet"] if args.quiet else []
    accuracy_json, diagnosis_json = out_dir / "accuracy.json", out_dir / "diagnosis.json"

    print("=" * 78)
    print("1/2  Accuracy by design: Monte Carlo of the seed's Table 2 errors at its working pose")
    print("=" * 78)
    code = _run_step(["montecarlo", "--preset", "table2", "--samples", str(args.samples),
                 "--seed", str(args.seed), "--json", str(accuracy_json),
                 "--out", str(out_dir / "accuracy"), *quiet], args.max_memory_gb)
    if code != EXIT_OK:
        return code

    measurements = bundled_file(MEASUREMENTS)
    print()
    print("=" * 78)
    print("2/2  Sim-to-real gap: diagnosis of the bundled tracker measurements (disc cutter on)")
    print("=" * 78)
    # the bundled set was measured by a simulated laser tracker of 0.02 mm per axis: say so
    code = _run_step(["diagnose", str(measurements), "--seed", str(args.seed), "--noise-mm", "0.02",
                 "--json", str(diagnosis_json),
                 "--out", str(out_dir / "diagnosis"),
                 "--as-built-urdf", str(out_dir / "tool_changer_as_built.urdf"), *quiet], args.max_memory_gb)
    if code != EXIT_OK:
        return code

    from .staging import read_output

    # the steps' files are staged with the demo's own, written together at its end
    accuracy = json.loads(read_output(accuracy_json))
    diagnosis = json.loads(read_output(diagnosis_json))
    # the hidden truth, read only now that the diagnosis is done
    truth = read_settings_file(bundled_file(TRUTH), "hidden truth", "yaml")
    hidden = [name for name in truth["effects"]]
    selected = list(diagnosis["selected_effects"])
    final = diagnosis["steps"][-1]
    stats = accuracy["stats_mm"]

    summary_rows = [
        ("std of dx, dy, dz at the working pose (Table 2 errors)",
         f"{stats['dx']['std']:.3f}, {stats['dy']['std']:.3f}, {stats['dz']['std']:.3f} mm"),
        ("mean |dP|", f"{stats['norm']['mean']:.3f} mm"),
        ("P(|dP| < 0.25 mm)", f"{accuracy['reliability_position']['0.25']:.4f}"),
        ("gap after fitting the tracker frame (RMS)", f"{diagnosis['gap']['rms_mm']:.4f} mm"),
        ("primary effect found", str(diagnosis["primary_effect"])),
        ("effects selected", ", ".join(selected)),
        ("effects hidden in the simulated robot", ", ".join(hidden)),
        ("held-out RMS after diagnosis", f"{final['heldout_rms_mm']:.4f} mm "
                                         f"({final['heldout_rms_mm'] / diagnosis['noise_floor_mm']:.2f} x the "
                                         f"noise floor {diagnosis['noise_floor_mm']:.4f} mm)"),
        ("structure remains", "yes" if diagnosis.get("structure_remains") else "no"),
        ("diagnosis vs hidden truth", truth_verdict(hidden, selected)),
    ]
    print()
    print("=" * 78)
    print("Summary")
    print("=" * 78)
    for label, value in summary_rows:  # the report's summary table has the same rows
        print(f"  {label:44s} {value}")

    report = Report("tcr-accuracy demo: the shield-machine tool-changer", command=getattr(args, "argv", None))
    report.add_text(
        "The built-in tool-changer (5 revolute + 1 telescopic joint) at the seed paper's working pose "
        "(15, 30, -10 deg, 0 mm, -20, 0 deg): how accurate its design tolerances make it, and, from "
        "300 laser-tracker readings of a simulated as-built robot carrying the 150 kg disc cutter, "
        "where the sim-to-real gap lies, which effect causes it and how far it shrinks once modelled.",
        heading="What this is")
    report.add_table("Summary", ["quantity", "value"], summary_rows)
    report.add_links("Reports of the two steps", [
        ("1. Monte Carlo accuracy analysis (tables, error cloud, projection densities, 3D view)",
         "accuracy/index.html"),
        ("2. Sim-to-real gap diagnosis (gap, where, which effect, how far it shrinks, plots)",
         "diagnosis/index.html"),
    ])
    report.add_links("Files", [
        ("accuracy.json", "accuracy.json"), ("diagnosis.json", "diagnosis.json"),
        ("as-built URDF of the diagnosed robot", "tool_changer_as_built.urdf"),
    ])
    from .writers import write_report

    index = write_report(report, out_dir)
    status(args, f"report written to {index}")
    return EXIT_OK
