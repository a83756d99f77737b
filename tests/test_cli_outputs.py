"""What the analysis commands write: reports, JSON, exit codes, determinism, no half-written files.

Determinism is checked by running each command twice in-process with the same --seed
(byte-identical JSON) and once with another seed (other numbers). Reports are read back
from the HTML and compared with the JSON of the same run.
"""

import json
import re
from html.parser import HTMLParser

import numpy as np
import pytest

from tcr_accuracy.view import plots_montecarlo, plots_sensitivity
from tcr_accuracy.cli import main

#: Small runs of each seeded command (a few seconds each).
SMALL = {
    "montecarlo": ["montecarlo", "--samples", "3000", "--tail-samples", "400", "--chunk", "1000"],
    "sensitivity": ["sensitivity", "--sobol-samples", "16"],
    "tolerance": ["tolerance", "--samples", "1000"],
    "trajectory": ["trajectory", "--samples", "60", "--steps", "9"],
}


def _json_of(tmp_path, capsys, argv, name):
    target = tmp_path / f"{name}.json"
    assert main([*argv, "--quiet", "--json", str(target)]) == 0
    capsys.readouterr()
    return target.read_bytes()


def _numbers(command, data):
    """A few results that depend on the random draws."""
    if command == "montecarlo":
        return [data["stats_mm"]["dx"]["mean"], data["stats_mm"]["norm"]["std"]]
    if command == "sensitivity":
        return [s["S1"] for s in data["sobol"]["outputs"]["norm"]["sources"]]
    if command == "tolerance":
        return [data["factor"], data["nominal_probability"]]
    return [row[0] for row in data["std_m"]]


@pytest.mark.parametrize("command", sorted(SMALL))
def test_same_seed_same_json_other_seed_other_numbers(command, tmp_path, capsys):
    argv = SMALL[command]
    first = _json_of(tmp_path, capsys, [*argv, "--seed", "5"], "a")
    again = _json_of(tmp_path, capsys, [*argv, "--seed", "5"], "b")
    assert first == again, f"{command}: the same --seed gave different JSON"
    other = _json_of(tmp_path, capsys, [*argv, "--seed", "6"], "c")
    a, b = _numbers(command, json.loads(first)), _numbers(command, json.loads(other))
    assert len(a) == len(b) and a != b, f"{command}: --seed 5 and --seed 6 gave the same numbers"


def test_sobol_intervals_repeat_with_seed_zero(tmp_path, capsys):
    # SALib seeds its bootstrap only for a truthy seed; 0 must repeat all the same
    argv = [*SMALL["sensitivity"], "--seed", "0"]
    first = json.loads(_json_of(tmp_path, capsys, argv, "a"))
    again = json.loads(_json_of(tmp_path, capsys, argv, "b"))
    conf = [s["S1_conf"] for s in first["sobol"]["outputs"]["norm"]["sources"]]
    assert conf == [s["S1_conf"] for s in again["sobol"]["outputs"]["norm"]["sources"]]
    assert any(c and c > 0 for c in conf)


# ---------------------------------------------------------------------------------------
# Nothing half-written
# ---------------------------------------------------------------------------------------
def _boom(*args, **kwargs):
    raise RuntimeError("plot failed")


@pytest.mark.parametrize("command, module, function", [
    ("montecarlo", plots_montecarlo, "plot_projection_densities"),  # the second of two plots
    ("trajectory", plots_sensitivity, "plot_trajectory_bands"),
])
def test_a_failure_mid_run_leaves_no_report_and_no_json(command, module, function, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(module, function, _boom)
    code = main([*SMALL[command], "--quiet", "--out", str(tmp_path / "report"), "--json", str(tmp_path / "r.json"),
                 "--view", str(tmp_path / "view.html")])
    assert code == 1 and "RuntimeError: plot failed" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.rglob("*")) == []  # no report, JSON, view or temporary file


def test_plots_of_a_failed_run_are_whole_files_and_temporaries_are_gone(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(plots_montecarlo, "plot_projection_densities", _boom)
    assert main([*SMALL["montecarlo"], "--quiet", "--plots", str(tmp_path / "plots"),
                 "--json", str(tmp_path / "r.json")]) == 1
    # the first plot was drawn before the second failed, but a failed run writes nothing:
    # no plot, no plot folder, no JSON, no temporary file (issue 12 #1)
    assert sorted(p.name for p in tmp_path.rglob("*")) == []


# ---------------------------------------------------------------------------------------
# Reports
# ---------------------------------------------------------------------------------------
class _Tables(HTMLParser):
    """Title (the <h2> before it) and rows of every <table>, as cell texts."""

    def __init__(self):
        super().__init__()
        self.tables, self._cell, self._heading, self._last_heading = {}, None, None, None

    def handle_starttag(self, tag, attrs):
        if tag == "h2":
            self._heading = ""
        elif tag == "table":
            self.tables[self._last_heading] = self._rows = []
        elif tag == "tr":
            self._rows.append([])
        elif tag in ("td", "th"):
            self._cell = ""

    def handle_endtag(self, tag):
        if tag == "h2":
            self._last_heading, self._heading = self._heading, None
        elif tag in ("td", "th") and self._cell is not None:
            self._rows[-1].append(self._cell.strip())
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data
        elif self._heading is not None:
            self._heading += data


def _tables(index):
    parser = _Tables()
    parser.feed(index.read_text(encoding="utf-8"))
    return parser.tables


def test_trajectory_report_has_the_printed_table_plots_scene_and_command(tmp_path, capsys):
    out = tmp_path / "report"
    argv = ["trajectory", "--samples", "400", "--steps", "9", "--seed", "2", "--out", str(out),
            "--json", str(tmp_path / "t.json")]
    assert main(argv) == 0
    printed, status = capsys.readouterr()
    data = json.loads((tmp_path / "t.json").read_text())
    tables = _tables(out / "index.html")
    bands = tables["TCP position error along the trajectory (seed Fig. 18)"]
    assert bands[0][:2] == ["t [s]", "std dx [mm]"] and bands[0][4] == "1st-order std dx [mm]"
    # 9 steps: all shown. The Monte Carlo std of 400 as-built robots against the first-order std
    # (the error Jacobian and the budget's covariance, no sampling): two calculations of one figure,
    # apart by the sampling error of a std from 400 draws (3.5 %; 12 % is 3.4 of it; 3 % measured)
    assert len(bands) == 1 + 9
    for row in bands[1:]:
        sampled, first_order = [float(v) for v in row[1:4]], [float(v) for v in row[4:7]]
        assert min(first_order) > 1.0  # mm: the table1 preset on the tool-changer
        assert sampled == pytest.approx(first_order, rel=0.12)
        # the |dP| quantile above every axis' std, below the 97.5 % radius of a normal of these stds
        assert max(sampled) < float(row[7]) < 3.1 * np.linalg.norm(sampled)
    # one check that the outputs carry the same figures: the time axis and a printed std
    assert [float(row[0]) for row in bands[1:]] == pytest.approx(data["time_s"])
    assert f"{data['std_m'][-1][0] * 1e3:8.4f}" in printed
    page = (out / "index.html").read_text(encoding="utf-8")
    assert page.count("<img src=\"figure-") == 2 and 'iframe src="scene-1.html"' in page
    assert "tcr-accuracy trajectory --samples 400 --steps 9 --seed 2 --out" in page
    scene = (out / "scene-1.html").read_text(encoding="utf-8")
    assert "nominal TCP path" in scene and "quantile [mm] along the path" in scene
    assert f"report written to {out / 'index.html'}" in status


def test_tolerance_report_lists_the_allowed_spreads_of_the_json(tmp_path, capsys):
    out = tmp_path / "report"
    assert main([*SMALL["tolerance"], "--quiet", "--out", str(out), "--json", str(tmp_path / "t.json")]) == 0
    assert capsys.readouterr().err == ""  # --quiet: no status lines
    data = json.loads((tmp_path / "t.json").read_text())
    rows = _tables(out / "index.html")["Allowed spreads (standard deviations)"]
    assert rows[0] == ["source", "group", "std now", "std allowed", "unit"]
    # every spread scaled (no --groups) by the one factor: allowed / now is the factor in each row
    # (4 significant digits), and the factor is below 1 exactly when the preset's spreads miss the target
    ratios = [float(r[3]) / float(r[2]) for r in rows[1:] if float(r[2]) > 0]
    assert len(ratios) > 3 and ratios == pytest.approx([data["factor"]] * len(ratios), rel=2e-3)
    assert (data["factor"] < 1.0) == (data["nominal_probability"] < data["target_probability"])
    by_name = {r[0]: r for r in rows[1:]}
    for spread in data["spreads"]:
        key = "allowed_std_m" if "allowed_std_m" in spread else "allowed_std_rad"
        scale = 1e3 if key.endswith("_m") else 180.0 / 3.141592653589793
        assert float(by_name[spread["name"]][3]) == pytest.approx(spread[key] * scale, rel=1e-3)


def test_json_to_stdout_stays_pure_with_a_report(tmp_path, capsys):
    assert main([*SMALL["tolerance"], "--out", str(tmp_path / "r"), "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["factor"] > 0  # stdout is the JSON alone
    assert re.fullmatch(r"report written to \S+index\.html\n", err)


# ---------------------------------------------------------------------------------------
# Exit codes
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, message", [
    (["montecarlo", "--seed", "-1"], "--seed -1: want a seed, an integer >= 0"),
    (["sensitivity", "--seed", "x"], "--seed x: not a number"),
    (["trajectory", "--open"], "--open needs --serve"),
    (["montecarlo", "--json", "/nonexistent-folder/r.json"], "the folder /nonexistent-folder does not exist"),
    (["trajectory", "--view", "/nonexistent-folder/v.html"], "the folder /nonexistent-folder does not exist"),
    (["montecarlo", "--view-samples", "0"], "--view-samples 0"),
    (["simulate", "--seed", "-3", "--out", "x.csv"], "--seed -3: want a seed, an integer >= 0"),
])
def test_bad_output_options_exit_2_with_one_line(argv, message, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's usage errors (tcr_accuracy.cli.Parser: one line, exit 2)
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_report_folder_that_is_a_file_exits_2(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    # refused when the command line is read, before any work
    assert main([*SMALL["tolerance"], "--quiet", "--out", str(blocker)]) == 2
    assert f"--out {blocker}: exists and is not a folder" in capsys.readouterr().err
    assert blocker.read_text() == "x"


def test_an_impossible_allocation_is_an_analysis_failure_exit_1(capsys):
    # the link-length spreads alone leave a 0.95 quantile of |dP| of about 22 mm (drive errors
    # at their Table 2 spreads): no factor on the link lengths reaches 0.25 mm
    assert main(["tolerance", "--samples", "1000", "--groups", "link_length", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "analysis failed" in err and err.count("\n") == 1


@pytest.mark.parametrize("command", ["pose", "demo", "montecarlo", "sensitivity", "tolerance", "trajectory",
                                     "simulate", "view"])
def test_every_command_takes_quiet(command, capsys):
    from tcr_accuracy.cli import build_parser

    parser = build_parser()
    extra = ["--out", "x.csv"] if command == "simulate" else []
    assert parser.parse_args([command, "--quiet", *extra]).quiet is True
