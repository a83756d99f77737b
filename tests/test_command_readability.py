"""The figures the commands actually write, judged by the same readability checks as each plot
kind (tests/readability.py): the demo's report, a diagnosis of a UR10 (long joint names, a
tracker far from the robot, as real campaigns have them), and a predict and a compensate report.
The per-kind tests draw from small hand-made data; these catch what only real outputs show
(tick values in the thousands, many poses, many effects). The predict report's tables are laid
out by Chromium and must fit the page.

For the real data sets (../shared/real, not part of this repository),
``scripts/readability_check.py`` runs the same checks on any command's figures.
"""

from __future__ import annotations

import pytest
from matplotlib.pyplot import close as close_figure  # the real one: the capture makes pyplot's a no-op

import readability as check
from tcr_accuracy.cli import main
from test_calibration_report import PRINT_WIDTH_PX, _widths, chromium  # noqa: F401 (fixture)

from conftest import REPO


def _problems(figures) -> list[str]:
    """Every figure's problems; each figure is closed once judged."""
    out = []
    for fig in figures:
        name = getattr(fig, "saved_path", "?")
        out += [f"{name}: {p}" for p in check.readability_problems(fig)]
        close_figure(fig)
    return out


def _run(argv):
    assert main([*argv, "--quiet"]) == 0


def test_every_figure_of_the_demo_report_reads(monkeypatch, tmp_path):
    with check.capture_figures(monkeypatch) as figures:
        _run(["demo", "--out", str(tmp_path / "demo"), "--samples", "4000"])
    assert len(figures) >= 6  # Monte Carlo and diagnosis plots, not an empty run
    problems = _problems(figures)
    assert not problems, "\n".join(problems)


def test_every_figure_of_a_ur10_diagnosis_reads(monkeypatch, tmp_path):
    scenario = tmp_path / "ur10.yaml"
    scenario.write_text("robot: ur10\neffects:\n  frames:\n    base_mm: {dx: 2600.0, dy: -900.0, dz: 400.0}\n"
                        "    base_deg: {rz: 150.0}\n    tool_mm: {dz: 120.0}\n"
                        "  geometry: {spread_mm: 0.2, spread_mrad: 0.2}\n"
                        "  joint_offsets:\n    offsets_deg: {shoulder_lift_joint: 0.03, elbow_joint: -0.02}\n"
                        "noise_mm: 0.02\n")
    csv = tmp_path / "ur10.csv"
    _run(["simulate", "--robot", "ur10", "--scenario", str(scenario), "--n", "150", "--seed", "4",
          "--out", str(csv)])
    with check.capture_figures(monkeypatch) as figures:
        _run(["diagnose", str(csv), "--robot", "ur10", "--out", str(tmp_path / "diag")])
    assert len(figures) >= 4
    problems = _problems(figures)
    assert not problems, "\n".join(problems)


@pytest.fixture(scope="module")
def predict_report(tmp_path_factory):
    folder = tmp_path_factory.mktemp("predict")
    with pytest.MonkeyPatch.context() as mp:
        with check.capture_figures(mp) as figures:
            _run(["predict", "--train", str(REPO / "examples" / "measured.csv"),
                  "--query", str(REPO / "examples" / "poses.csv"), "--out", str(folder / "predict")])
            _run(["compensate", "--train", str(REPO / "examples" / "measured.csv"),
                  "--targets", str(REPO / "examples" / "poses.csv"), "--out", str(folder / "compensate")])
        kept = list(figures)
    return folder, kept


def test_every_figure_of_a_predict_and_a_compensate_report_reads(predict_report):
    _, figures = predict_report
    assert len(figures) >= 2  # predict's errors per pose, compensate's histogram
    problems = _problems(figures)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("report", ["predict", "compensate"])
def test_the_per_pose_tables_fit_the_page_in_chromium(chromium, predict_report, report, tmp_path):  # noqa: F811
    folder, _ = predict_report
    for width, print_rules in ((1280, False), (PRINT_WIDTH_PX, True)):
        laid = _widths(chromium, folder / report / "index.html", width, print_rules, tmp_path)
        tables = [i for i in laid["items"] if i["what"].startswith("TABLE")]
        assert tables  # the per-pose table is there
        for item in laid["items"]:
            assert item["left"] >= 0 and item["right"] <= laid["page"] + 0.5, (width, item["what"], item)
            assert item["scroll"] <= item["client"] + 1, (width, item)
