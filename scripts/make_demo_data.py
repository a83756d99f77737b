#!/usr/bin/env python3
"""Write the demo's bundled measurement set of a simulated as-built tool-changer.

    python scripts/make_demo_data.py

Runs the stand-in robot on examples/scenario_demo_cutter.yaml (300 poses, seed 2026)
and writes src/tcr_accuracy/data/tool_changer_cutter.csv plus its hidden truth
(tool_changer_cutter_truth.yaml). `tcr-accuracy demo` diagnoses the CSV alone and
only afterwards shows the truth next to its answer.
"""

import sys
from pathlib import Path

from tcr_accuracy.cli import main

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "src" / "tcr_accuracy" / "data"

if __name__ == "__main__":
    sys.exit(main([
        "simulate", "--scenario", str(ROOT / "examples" / "scenario_demo_cutter.yaml"),
        "--n", "300", "--seed", "2026",
        "--out", str(DATA / "tool_changer_cutter.csv"),
        "--truth", str(DATA / "tool_changer_cutter_truth.yaml"),
    ]))
