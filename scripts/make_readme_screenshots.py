#!/usr/bin/env python3
"""Screenshots for the README: the 3D view and a sample report, drawn by headless Chromium.

    python scripts/make_readme_screenshots.py [--out docs/img] [--samples 2000] [--seed 0]

Writes docs/img/viewer.png (the built-in tool-changer at the seed's working pose with a
TCP error cloud of the seed's Table 2 errors), and docs/img/demo.png and docs/img/report.png:
the index and the diagnosis report that ``tcr-accuracy demo`` writes, and the demo's plots
under docs/img/figures/, and docs/img/calibration_report.png: page 1 of the printed report of the
README's "The report" commands (diagnosis, ISO 9283 test, export, report), at 120 dpi, and
docs/img/export.png and docs/img/iso9283.png: the figures of the README's export and ISO 9283
commands. Needs
Chromium (``apt-get install -y chromium``) and poppler's pdftoppm (``apt-get install -y poppler-utils``).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")

from tcr_accuracy.model.errors import seed_budget  # noqa: E402
from tcr_accuracy.model.robot import load_robot  # noqa: E402
from tcr_accuracy.view.viewer import Scene  # noqa: E402

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--hide-scrollbars",
         "--virtual-time-budget=8000"]


def screenshot(page: Path, png: Path, width: int, height: int) -> None:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        sys.exit("chromium not found: apt-get install -y chromium")
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([chromium, *FLAGS, f"--user-data-dir={profile}", f"--window-size={width},{height}",
                        f"--screenshot={png}", page.resolve().as_uri()],
                       check=True, capture_output=True, timeout=180)
    print(f"wrote {png}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/img"))
    parser.add_argument("--samples", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    robot = load_robot()
    q = robot.working_pose
    budget = seed_budget(robot, "table2")
    x = budget.sample(args.samples, np.random.default_rng(args.seed))

    scene = Scene("Tool-changer at the seed's working pose: TCP error cloud, Table 2 errors")
    scene.add_robot(robot, q, "nominal")
    magnify = scene.add_tcp_error_cloud(robot, q, x, budget.error_model)
    scene.add_note(f"{args.samples} Monte Carlo samples, seed {args.seed}; cloud and ghost magnified "
                   f"x {magnify:g} about the nominal TCP")

    with tempfile.TemporaryDirectory() as work:
        work = Path(work)
        view = work / "view.html"
        view.write_text(scene.static_html(), encoding="utf-8")
        screenshot(view, args.out / "viewer.png", 1200, 750)

        # the report is the one `tcr-accuracy demo` writes, not one made up for the picture
        from tcr_accuracy.cli import main as cli_main

        code = cli_main(["demo", "--out", str(work / "demo"), "--seed", str(args.seed), "--quiet"])
        if code != 0:
            sys.exit(f"tcr-accuracy demo failed with exit code {code}")
        screenshot(work / "demo" / "index.html", args.out / "demo.png", 1000, 1100)
        screenshot(work / "demo" / "diagnosis" / "index.html", args.out / "report.png", 1000, 2600)
        # the demo's plots as they are written, to look at without running it
        figures = args.out / "figures"
        figures.mkdir(exist_ok=True)
        for part in ("accuracy", "diagnosis"):
            for png in sorted((work / "demo" / part).glob("figure-*.png")):
                shutil.copyfile(png, figures / f"demo-{part}-{png.name}")
                print(f"wrote {figures / f'demo-{part}-{png.name}'}")
        calibration_report_page(work, args.out / "calibration_report.png")
        task_figures(work, args.out)


#: The README's "The report" commands (the report's page 1 is the README's image).
REPORT_COMMANDS = [
    ["diagnose", "examples/measured.csv", "--json", "diagnosis.json", "--as-built-urdf", "as_built.urdf"],
    ["iso9283", "plan", "--cube-centre-mm", "0", "1400", "300", "--cube-size-mm", "200", "--cycles", "5", "--out",
     "iso_plan.csv"],
    ["simulate", "--scenario", "examples/scenario_compliance.yaml", "--poses", "iso_plan.csv", "--seed", "3", "--out",
     "iso.csv"],
    ["iso9283", "evaluate", "iso.csv", "--model", "diagnosis.json", "--json", "iso.json"],
    ["export", "diagnosis.json", "--to", "calibration"],
    ["report", "diagnosis.json", "iso.json", "calibration/accuracy.json", "--out", "calibration-report", "--campaign",
     "examples/report_campaign.yaml", "--operator", "K. Lee"],
]


def run_in_copy(folder: Path, commands) -> Path:
    """Run the README's commands (``tcr-accuracy`` argument lists) in ``folder``, holding a copy of
    the repository's examples, as the README's reader would; exit on the first that fails."""
    import contextlib
    import io
    import os

    from tcr_accuracy.cli import main as cli_main

    shutil.copytree(Path(__file__).resolve().parents[1] / "examples", folder / "examples")
    here = os.getcwd()
    os.chdir(folder)
    try:
        for argv in commands:
            with contextlib.redirect_stdout(io.StringIO()):
                if cli_main([*argv, "--quiet"]) != 0:
                    sys.exit(f"tcr-accuracy {' '.join(argv)} failed")
    finally:
        os.chdir(here)
    return folder


def calibration_report_page(work: Path, png: Path) -> None:
    """Page 1 of the README's calibration report, printed by Chromium, rasterised by pdftoppm."""
    folder = run_in_copy(work / "readme-report", REPORT_COMMANDS)
    subprocess.run(["pdftoppm", "-r", "120", "-f", "1", "-l", "1", "-singlefile", "-png",
                    str(folder / "calibration-report" / "report.pdf"), str(png.with_suffix(""))], check=True)
    print(f"wrote {png}")


#: The README's "Export to the controller" and "ISO 9283" commands, and the figure each screen shows.
TASK_COMMANDS = [
    ["simulate", "--robot", "ur5", "--scenario", "examples/scenario_ur5_reflector.yaml", "--n", "300", "--seed", "1",
     "--out", "ur5.csv"],
    ["diagnose", "ur5.csv", "--robot", "ur5", "--json", "ur5.json"],
    ["export", "ur5.json", "--to", "ur5_calibration", "--targets", "examples/ur5_targets.csv"],
    ["iso9283", "plan", "--robot", "ur10", "--out", "plan.csv"],
    ["simulate", "--robot", "ur10", "--poses", "plan.csv", "--random", "--seed", "1", "--out", "iso.csv"],
    ["iso9283", "evaluate", "iso.csv", "--robot", "ur10", "--out", "iso-report"],
]
TASK_FIGURES = {"ur5_calibration/accuracy.png": "export.png", "iso-report/figure-1.png": "iso9283.png"}


def task_figures(work: Path, out: Path) -> None:
    """The figures of the README's export and ISO 9283 screens, from the README's own commands."""
    folder = run_in_copy(work / "readme-tasks", TASK_COMMANDS)
    for source, name in TASK_FIGURES.items():
        shutil.copyfile(folder / source, out / name)
        print(f"wrote {out / name}")


if __name__ == "__main__":
    main()
