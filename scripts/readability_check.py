#!/usr/bin/env python3
"""Run any tcr-accuracy command and judge every figure it writes with the readability checks
of the test suite (tests/readability.py: tick labels apart, legends off the data, text of at
least 7 pt, PNGs without wide white margins). For data that cannot live in the repository,
such as the real robots' measurements:

    python scripts/readability_check.py -- diagnose ../shared/real/ur5_tracker/ur5_grid_1000.csv \\
        --robot ur5 --out /tmp/ur5_report

prints one line per figure (its file and "readable" or its problems) and exits 1 when any
figure has a problem.
"""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the checks live with the tests that hold them

import pytest  # noqa: E402  (MonkeyPatch: the same capture the tests use)

import readability as check  # noqa: E402
from tcr_accuracy.cli import main as cli_main  # noqa: E402


def main(argv: list[str]) -> int:
    if argv[:1] == ["--"]:
        argv = argv[1:]
    if not argv:
        print(__doc__.strip().splitlines()[0], file=sys.stderr)
        return 2
    with pytest.MonkeyPatch.context() as patch:
        with check.capture_figures(patch) as figures:
            code = cli_main([*argv, "--quiet"])
        if code != 0:
            print(f"readability_check: the command exited {code}", file=sys.stderr)
            return code
        failed = 0
        for fig in figures:
            problems = check.readability_problems(fig)
            name = Path(str(getattr(fig, "saved_path", "?"))).name
            print(f"{name}: " + ("readable" if not problems else "; ".join(problems)))
            failed += bool(problems)
    print(f"{len(figures) - failed} of {len(figures)} figures readable")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
