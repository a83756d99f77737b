#!/usr/bin/env python3
"""Screenshots for the README: the 3D view and a sample report, drawn by headless Chromium.

    python scripts/make_readme_screenshots.py [--out docs/img] [--samples 2000] [--seed 0]

Writes docs/img/viewer.png (the built-in tool-changer at the seed's working pose with a
TCP error cloud of the seed's Table 2 errors) and docs/img/report.png (a report of the
same Monte Carlo run: a table, a histogram and the 3D view). Needs Chromium
(``apt-get install -y chromium``).
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
import matplotlib.pyplot as plt  # noqa: E402

from tcr_accuracy.model.errors import seed_budget  # noqa: E402
from tcr_accuracy.model.jacobians import error_jacobian  # noqa: E402
from tcr_accuracy.model.kinematics import pose_error, tcp_poses  # noqa: E402
from tcr_accuracy.view.report import Report  # noqa: E402
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

    nominal = tcp_poses(robot, q)
    error = pose_error(nominal, tcp_poses(robot, q, x, budget.error_model))
    jac = error_jacobian(robot, q, budget.error_model)
    first_order = np.sqrt(np.diag(jac[:3] @ budget.parameter_covariance() @ jac[:3].T)) * 1000
    dp = error.position * 1000
    rows = [[axis, dp[:, k].mean(), dp[:, k].std(), first_order[k], dp[:, k].min(), dp[:, k].max()]
            for k, axis in enumerate("xyz")]
    norm = error.position_norm * 1000
    rows.append(["|dP|", norm.mean(), norm.std(), "", norm.min(), norm.max()])

    with tempfile.TemporaryDirectory() as work:
        work = Path(work)
        view = scene.write_static_html(work / "view.html")
        screenshot(view, args.out / "viewer.png", 1200, 750)

        report = Report("TCP accuracy of the tool-changer at the working pose",
                        command=f"python scripts/make_readme_screenshots.py --samples {args.samples} "
                                f"--seed {args.seed}")
        report.add_text(f"{args.samples} as-built robots sampled from the seed's Table 2 error sources "
                        "(link lengths and drive errors), TCP position error at the working pose "
                        "(15, 30, -10 deg, 0 mm, -20, 0 deg).", heading="Setup")
        report.add_table("TCP position error", ["component", "mean", "std", "first-order std", "min", "max"],
                         rows, units=["", "mm", "mm", "mm", "mm", "mm"],
                         note="first-order std: sqrt(diag(J C J^T)) from the error Jacobian")
        fig, ax = plt.subplots(figsize=(6.4, 2.8))
        ax.hist(norm, bins=60, color="#3b6ea8")
        ax.set_xlabel("|dP| [mm]")
        ax.set_ylabel("samples")
        report.add_figure(fig, "Distribution of the TCP position error |dP|")
        plt.close(fig)
        report.add_scene(scene.static_html(), "Nominal robot, TCP error cloud and the worst as-built robot",
                         height_px=460)
        index = report.write(work / "report")
        screenshot(index, args.out / "report.png", 1000, 1750)


if __name__ == "__main__":
    main()
