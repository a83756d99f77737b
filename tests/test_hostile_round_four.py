"""Reproductions of issue 37's hostile-input attack (round four), items 6-8, 10, 13-17 and its
minor ones: each failed on the code before its fix. Decoys only, in ``tmp_path``; the command
line runs in a child process (:func:`hostile.cli_process`): a bad input ends in exit code 2 and
ONE line on stderr naming the file and key, column or flag at fault, no traceback, nothing
written; a good one is answered right.
"""

import json
import shutil

import numpy as np
import pytest
from scipy import stats

from hostile import cli_process


def listing(folder) -> set:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def refused(folder, argv, *named) -> str:
    """Run ``argv`` in ``folder``: exit 2, one stderr line holding each of ``named``, nothing written."""
    before = listing(folder)
    result = cli_process(argv, cwd=folder)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    assert "Traceback" not in result.stderr and len(lines) == 1, result.stderr[-2000:]
    for text in named:
        assert text in lines[0], (text, lines[0])
    assert listing(folder) == before, sorted(listing(folder) - before)
    return lines[0]


def answered(folder, argv):
    """Run ``argv`` in ``folder``: exit 0 and no traceback; the completed process."""
    result = cli_process(argv, cwd=folder)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "Traceback" not in result.stderr
    return result


@pytest.fixture
def campaign(tmp_path, small_campaign):
    """tmp_path with the small campaign's measurements (m.csv) and diagnosis (d.json)."""
    csv, diagnosis = small_campaign
    shutil.copy(csv, tmp_path / "m.csv")
    shutil.copy(diagnosis, tmp_path / "d.json")
    return tmp_path


# ---------------------------------------------------------------------------------------
# 6. The report's text flags hold to the campaign file's bounds
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("flag, value, said", [
    ("--title", "Calibration \u202eevil", "holds the control character U+202E"),  # shown reversed
    ("--operator", "J. Smith\x1b[31m", "holds the control character U+001B"),  # a terminal escape in the page
    ("--customer", "x" * 5000, "5000 characters; at most 300"),
    ("--serial", "S-1\u2066", "holds the control character U+2066"),
    ("--certificate", "\x07", "holds the control character U+0007"),
])
def test_37_06_report_text_flags_are_held_as_the_campaign_file_is(campaign, flag, value, said):
    refused(campaign, ["report", "d.json", "--out", "rep", flag, value, "--quiet"], f"argument {flag}", said)
    key = {"--serial": "robot:\n  serial", "--certificate": "instrument:\n  certificate"}.get(flag, flag[2:])
    (campaign / "c.yaml").write_text(f"{key}: {json.dumps(value)}\n")  # the same text in a campaign file
    refused(campaign, ["report", "d.json", "--out", "rep", "--campaign", "c.yaml", "--quiet"], "c.yaml", said)


def test_37_06_the_flags_of_other_commands_reports_too(campaign):
    refused(campaign, ["diagnose", "m.csv", "--effects", "joint_offsets", "--out", "rep", "--title", "a\u202eb",
                       "--quiet"], "argument --title", "U+202E")


def test_37_06_plain_flags_still_reach_the_page(campaign):
    answered(campaign, ["report", "d.json", "--out", "rep", "--title", "Caf\u00e9  S-1234", "--operator", "J. Smith",
                        "--quiet"])
    assert "<h1>Caf\u00e9 S-1234</h1>" in (campaign / "rep" / "index.html").read_text(encoding="utf-8")


# ---------------------------------------------------------------------------------------
# 7. report.md shows what came from outside as text, as index.html does
# ---------------------------------------------------------------------------------------
HOSTILE_MARKDOWN = ("![x](https://evil.example/pixel.png) [click](javascript:alert(1)) <https://evil.example> "
                    "www.evil.example a@evil.example *em* ~~s~~ `c` | x")


def _gfm():
    from markdown_it import MarkdownIt

    renderer = MarkdownIt("gfm-like")
    renderer.linkify.set({"fuzzy_link": False})
    return renderer


def _rendered_links(markdown: str) -> tuple[list, list, str]:
    """(link targets, image sources, text) of ``markdown`` as GitHub renders it: markdown-it-py's
    gfm-like preset (an independent CommonMark renderer) with GFM's autolinks (``www.``,
    ``https://``, e-mail addresses; not a bare ``name.dz``, which GitHub leaves as text)."""
    import re

    page = _gfm().render(markdown)
    return re.findall(r'<a href="([^"]*)"', page), re.findall(r'<img src="([^"]*)"', page), page


def test_37_07_report_md_is_not_live_markdown(campaign):
    doc = json.loads((campaign / "d.json").read_text())
    doc["measurements"] = HOSTILE_MARKDOWN
    (campaign / "d.json").write_text(json.dumps(doc))
    (campaign / "c.yaml").write_text(f"title: {json.dumps(HOSTILE_MARKDOWN)}\n")
    answered(campaign, ["report", "d.json", "--out", "rep", "--campaign", "c.yaml", "--quiet"])
    links, images, page = _rendered_links((campaign / "rep" / "report.md").read_text(encoding="utf-8"))
    assert images and all(":" not in src and not src.startswith("/") for src in images), images  # our plots only
    assert all(":" not in href and not href.startswith("/") for href in links), links  # our files only
    assert "![x](https://evil.example/pixel.png) [click](javascript:alert(1))" in page  # shown as text
    assert "&lt;https://evil.example&gt;" in page and "*em* ~~s~~ `c` | x" in page


def test_37_07_markdown_text_round_trips_as_text():
    """Any text, through the escaping and a CommonMark renderer, is the same text again."""
    import html

    from markdown_it import MarkdownIt

    from tcr_accuracy.view import markdown_text as md

    renderer = MarkdownIt("gfm-like")  # with every bare domain a link too: the strictest reading
    samples = [HOSTILE_MARKDOWN, "1. item", "- item", "# heading", "===", "---", "2) x", "+ y", "-0.0354 mm",
               "joint_offsets and _em_ and __b__", "[r]: https://x.example", "a \\* b", "\\", "3.11.2", "> q"]
    for sample in samples:
        rendered = renderer.render(md.line(sample))
        assert rendered.startswith("<p>") and rendered.endswith("</p>\n"), (sample, rendered)
        assert html.unescape(rendered[3:-5]) == sample, (sample, rendered)


# ---------------------------------------------------------------------------------------
# 8. One limit per figure
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("limits", [["max=0.05", "max=0.2"], ["0.05", "max=0.2"], ["ap=0.1", "ap=0.1"]])
def test_37_08_a_figure_limited_twice_is_refused(campaign, limits):
    figure = limits[-1].split("=")[0]
    argv = ["report", "d.json", "--out", "rep", "--quiet"]
    for limit in limits:
        argv += ["--limit-mm", limit]
    refused(campaign, argv, "--limit-mm", f"{figure} is limited twice")


# ---------------------------------------------------------------------------------------
# 10. Importance sampling: a probability, and the right one
# ---------------------------------------------------------------------------------------
def _telescope_budget(robot, distribution: str, **spread):
    """A budget of one source, the telescopic joint's drive error [m]: it moves the TCP along
    the joint's axis by exactly its value, so |dP| = |value| (linear, exactly)."""
    from tcr_accuracy.model.errors import ErrorBudget, ErrorModel, ErrorSource

    em = ErrorModel(robot)
    direction = np.zeros(em.size)
    direction[em.index("j4.drive")] = 1.0
    return ErrorBudget(em, [ErrorSource("j4 drive", "drive", direction, "m", distribution, **spread)])


@pytest.mark.parametrize("mean, std, threshold", [
    (0.0, 2e-5, 1e-4),  # 5 spreads out: 5.7e-7
    (1.4e-4, 2e-5, 1.5e-4),  # a bias near the tolerance: 0.31
    (3e-4, 1e-6, 1.5e-4),  # a bias beyond it, 150 spreads: 1 (importance sampling said 0.95 and 8e-156)
])
def test_37_10_tail_estimates_against_the_closed_form(tool_changer, mean, std, threshold):
    """Gaussian input, linear limit state: P(|d| > T) = Phi((-T - mu) / s) + Phi((mu - T) / s)."""
    from tcr_accuracy.analysis.reliability import first_order, gaussian_exceedance, importance_exceedance

    budget = _telescope_budget(tool_changer, "normal", mean=mean, std=std)
    q = tool_changer.working_pose
    exact = stats.norm.cdf((-threshold - mean) / std) + stats.norm.sf((threshold - mean) / std)
    fo = first_order(budget, q)
    assert gaussian_exceedance(fo.mean[:3], fo.covariance[:3, :3], threshold) == pytest.approx(exact, rel=1e-6)
    est = importance_exceedance(budget, q, threshold, 20_000, np.random.default_rng(5))
    assert 0.0 <= est.ci95[0] <= est.probability <= est.ci95[1] <= 1.0
    assert abs(est.probability - exact) <= 4 * est.standard_error + 1e-12 * exact, (est, exact)
    assert est.standard_error <= 0.1 * exact


@pytest.mark.parametrize("threshold", [1.2e-4, 1.6e-4])
@pytest.mark.parametrize("inflation", [None, 3.0])
def test_37_10_importance_sampling_agrees_with_plain_sampling_on_a_biased_budget(tool_changer, threshold, inflation):
    """Every drive biased by a uniform error (the kind of budget that gave 1.093): the plain Monte
    Carlo count and importance sampling agree within their standard errors, with the proposal's
    own spread or one three times wider (the weights, not the proposal, make the estimate)."""
    from dataclasses import replace

    from tcr_accuracy.analysis.montecarlo import run_monte_carlo
    from tcr_accuracy.analysis.reliability import importance_exceedance
    from tcr_accuracy.model.errors import ErrorBudget, ErrorModel, drive_source

    em = ErrorModel(tool_changer)
    sources = [replace(drive_source(tool_changer, j, em, 0.0), distribution="uniform", low=2e-5, high=6e-5)
               for j in range(tool_changer.n_joints)]
    budget = ErrorBudget(em, sources)
    q, n = tool_changer.working_pose, 20_000
    plain = run_monte_carlo(budget, q, n, 3, position_tolerances=(threshold,))
    p_plain = 1.0 - plain.inside_position[0] / n
    assert 0.05 < p_plain < 0.95  # both apply
    est = importance_exceedance(budget, q, threshold, n, np.random.default_rng(3), inflation=inflation)
    assert 0.0 <= est.probability <= 1.0
    se = np.hypot(est.standard_error, np.sqrt(p_plain * (1 - p_plain) / n))
    assert abs(est.probability - p_plain) < 4 * se, (est, p_plain)


def test_37_10_first_order_tail_of_a_narrow_far_gaussian_is_the_noncentral_chi_square():
    """A spread 1 um at 5 mm from the tolerance's centre (the first-order column said 2.3e-96
    beside Monte Carlo's 1.000): |d|^2 / s^2 is noncentral chi-square (scipy)."""
    from tcr_accuracy.analysis.reliability import gaussian_exceedance

    for k in (2, 3):
        mean = np.zeros(k)
        mean[0] = 5e-3
        for threshold in (1e-4, 4.99e-3, 5.004e-3):
            exact = stats.ncx2.sf((threshold / 1e-6) ** 2, k, (5e-3 / 1e-6) ** 2)
            assert gaussian_exceedance(mean, 1e-12 * np.eye(k), threshold) == pytest.approx(exact, rel=1e-6)


# ---------------------------------------------------------------------------------------
# 15. A diagnosis holding clearance parameters
# ---------------------------------------------------------------------------------------
@pytest.fixture
def with_clearance(campaign):
    """campaign with dc.json: d.json holding clearance spreads (10 um, 10 um, 10 urad) too."""
    doc = json.loads((campaign / "d.json").read_text())
    spreads = {"clearance.axial": 1e-5, "clearance.radial": 1e-5, "clearance.tilt": 1e-5}
    doc["effect_parameters"]["clearance"] = dict(spreads)
    doc["parameters"]["clearance"] = dict(spreads)
    doc["parameter_units"]["clearance"] = {"clearance.axial": "m", "clearance.radial": "m", "clearance.tilt": "rad"}
    doc["parameter_std"]["clearance"] = {k: 1e-6 for k in spreads}
    doc["parameter_interval_95"]["clearance"] = {k: [8e-6, 1.2e-5] for k in spreads}
    (campaign / "dc.json").write_text(json.dumps(doc))
    return campaign


def test_37_15_export_of_a_diagnosis_with_clearance(with_clearance):
    """Play is scatter, not bias: the as-built model is the mean robot, the same as without it."""
    answered(with_clearance, ["export", "d.json", "--to", "plain", "--quiet"])
    answered(with_clearance, ["export", "dc.json", "--to", "play", "--quiet"])
    plain, play = (json.loads((with_clearance / n / "accuracy.json").read_text()) for n in ("plain", "play"))
    assert play["accuracy"] == plain["accuracy"]
    origins = [[line for line in (with_clearance / n / "as_built.urdf").read_text().splitlines() if "<origin" in line]
               for n in ("plain", "play")]
    assert origins[0] and origins[0] == origins[1]


def _pose_test(campaign) -> str:
    """iso.csv: 5 poses of m.csv, each measured in 3 cycles (1 um apart); its name."""
    import csv

    rows = list(csv.DictReader((campaign / "m.csv").read_text().splitlines()))[:5]
    head = [c for c in rows[0] if c.endswith(("_deg", "_mm")) and c not in ("x_mm", "y_mm", "z_mm")]
    lines = [",".join(head + ["x_mm", "y_mm", "z_mm", "pose_id", "cycle"])]
    for cycle in (1, 2, 3):
        for pose, row in enumerate(rows, start=1):
            xyz = [f"{float(row[c]) + 1e-3 * cycle:.6f}" for c in ("x_mm", "y_mm", "z_mm")]
            lines.append(",".join([row[c] for c in head] + xyz + [str(pose), str(cycle)]))
    (campaign / "iso.csv").write_text("\n".join(lines) + "\n")
    return "iso.csv"


def test_37_15_compare_and_iso_model_with_clearance(with_clearance):
    result = answered(with_clearance, ["compare", "d.json", "dc.json", "--quiet"])
    assert "clearance" in result.stdout
    answered(with_clearance, ["iso9283", "evaluate", _pose_test(with_clearance), "--model", "dc.json", "--quiet"])


# ---------------------------------------------------------------------------------------
# 13. Effect options of a scenario hold to the bounds of a diagnosis JSON's and an as-built YAML's
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("effect, options, said", [
    ("cyclic", "{max_order: 1000000}", "effects.cyclic.options.max_order: 1000000 is greater than the maximum of 200"),
    ("angle_table", "{intervals: 1001}", "effects.angle_table.options.intervals: 1001 is greater than the maximum"),
    ("transmission", "{harmonics: [1000]}", "effects.transmission.options.harmonics[0]: 1000 is greater"),
    ("compliance", "{link_mass_factors: [1, 2]}", "effects.compliance.options: link_mass_factors: 2 values for the 6"),
    ("cyclic", "[3]", "effects.cyclic.options: a mapping"),
])
def test_37_13_scenario_effect_options_are_bounded(tmp_path, effect, options, said):
    """cyclic's max_order 1000000 built 3.5 GB of parameters, then ran out of memory."""
    (tmp_path / "s.yaml").write_text(f"effects:\n  {effect}:\n    options: {options}\n")
    refused(tmp_path, ["simulate", "--scenario", "s.yaml", "--n", "5", "--out", "m.csv", "--quiet"], "s.yaml", said)


def test_37_13_options_within_the_bounds_still_simulate(tmp_path):
    (tmp_path / "s.yaml").write_text("effects:\n  cyclic:\n    options: {max_order: 5}\n")
    answered(tmp_path, ["simulate", "--scenario", "s.yaml", "--n", "5", "--out", "m.csv", "--quiet"])
    assert len((tmp_path / "m.csv").read_text().splitlines()) == 6


#: The keys an as-built model file must start with (docs/as-built-format.md)
AS_BUILT_HEAD = "format: tcr-accuracy as-built model 2\nrobot_source: tool_changer\ntool_frame: tool\n"


def test_37_13_as_built_file_options_hold_to_the_same_bounds(tmp_path):
    """The as-built YAML took integers up to 1000 (cyclic's max_order 1000: 12,000 parameters); the
    bound of a diagnosis JSON (200) holds there too, and a wrong count of link mass factors is
    named with its file and key (it said "link mass factors: need 6 values >= 0")."""
    from tcr_accuracy import load_as_built
    from tcr_accuracy.exceptions import InputError

    for options, said in (("cyclic: {max_order: 1000}", "options.cyclic.max_order: 1000 is greater than the maximum"),
                          ("compliance: {link_mass_factors: [1, 1]}", "link_mass_factors: 2 values for the 6")):
        effect = options.split(":")[0]
        (tmp_path / "a.yaml").write_text(f"{AS_BUILT_HEAD}effects:\n  {effect}: {{}}\noptions:\n  {options}\n")
        with pytest.raises(InputError, match="a.yaml") as caught:
            load_as_built(tmp_path / "a.yaml")
        assert said in str(caught.value) and len(str(caught.value).splitlines()) == 1, caught.value


# ---------------------------------------------------------------------------------------
# 14. import: the memory of the cells, and the columns, counted before reading
# ---------------------------------------------------------------------------------------
def test_37_14_import_of_a_one_row_file_of_many_cells_is_refused_before_reading(tmp_path):
    """A 32 MB one-row export of one-character cells (320 MB took 3.6 GB and failed): 0.38 GB for
    its text, and 16 million cells, each a slot in a list, beyond 0.5 GB."""
    with open(tmp_path / "t.txt", "w") as f:
        f.write("X;Y;Z\n1;2;3" + ";1" * 16_000_000 + "\n")
    refused(tmp_path, ["import", "t.txt", "--out", "o.csv", "--max-memory-gb", "0.5", "--quiet"],
            "importing t.txt (2 rows, 16000006 cells)", "more than the 0.5 GB allowed")


def test_37_14_import_of_a_header_of_too_many_columns(tmp_path):
    """200,000 columns named like a measurement CSV's passed through one by one, each looked up in
    the header again: a 2.9 MB file ran for more than 10 minutes."""
    n = 200_000
    header = "X;Y;Z;" + ";".join(f"a{i}_mm" for i in range(n))
    (tmp_path / "t.txt").write_text(header + "\n1;2;3;" + ";".join(["1.5"] * n) + "\n")
    refused(tmp_path, ["import", "t.txt", "--out", "o.csv", "--quiet"], "t.txt: row 1: 200003 cells",
            "at most 10000 columns")


@pytest.mark.parametrize("name, text, said", [
    ("r.json", "[" + "{}," * 2_000_000 + "{}]", "its JSON (2000002 objects and lists)"),  # ~25 bytes a byte
    ("s.yaml", "a: [" + "{}," * 200_000 + "{}]\n", "its YAML"),  # ~330 bytes a byte
], ids=["json", "yaml"])
def test_37_14_json_and_yaml_readers_estimate_their_objects(tmp_path, name, text, said):
    (tmp_path / name).write_text(text)
    argv = (["report", name, "--out", "rep"] if name.endswith(".json") else
            ["simulate", "--scenario", name, "--n", "3", "--out", "m.csv"])
    refused(tmp_path, [*argv, "--max-memory-gb", "0.1", "--quiet"], name, said, "more than the 0.1 GB allowed")


# ---------------------------------------------------------------------------------------
# 16. An integer too large for a number, in any settings file
# ---------------------------------------------------------------------------------------
BIG = "1" * 5000


@pytest.mark.parametrize("name, text, argv, said", [
    ("c.yaml", f"limits_mm:\n  max: {BIG}\n", ["report", "d.json", "--out", "rep", "--campaign", "c.yaml"],
     "c.yaml: limits_mm.max: an integer of 5000 digits"),
    ("c.toml", f"[limits_mm]\nmax = {BIG}\n", ["report", "d.json", "--out", "rep", "--campaign", "c.toml"],
     "c.toml: line 2: limits_mm.max: an integer of 5000 digits"),
    ("c4.yaml", f"limits_mm:\n  max: {'1' * 400}\n", ["report", "d.json", "--out", "rep", "--campaign", "c4.yaml"],
     "c4.yaml: limits_mm.max: an integer of 400 digits"),  # "OverflowError: int too large to convert to float"
    ("s.yaml", f"noise_mm: {BIG}\n", ["simulate", "--scenario", "s.yaml", "--n", "3", "--out", "o.csv"],
     "s.yaml: noise_mm: an integer of 5000 digits"),
    ("b.toml", f'[groups.drive]\ndistribution = "normal"\nstd_mm = {BIG}\n',
     ["montecarlo", "--config", "b.toml", "--samples", "10"], "b.toml: line 3: groups.drive.std_mm"),
    ("b.yaml", f"groups:\n  drive:\n    std_mm: [1, {BIG}]\n",
     ["montecarlo", "--config", "b.yaml", "--samples", "10"], "b.yaml: groups.drive.std_mm[1]"),
])
def test_37_16_huge_integers_are_refused_naming_file_and_key(campaign, name, text, argv, said):
    (campaign / name).write_text(text)
    refused(campaign, [*argv, "--quiet"], said, "beyond the range of a number")


def test_37_16_load_as_built_and_json_name_the_key(tmp_path):
    from tcr_accuracy import load_as_built
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.input_files import parse_json

    (tmp_path / "a.yaml").write_text(f"{AS_BUILT_HEAD}effects:\n  joint_offsets: {{joint_offsets.j2: {BIG}}}\n")
    with pytest.raises(InputError, match=r"a.yaml: effects.joint_offsets.joint_offsets.j2: an integer of 5000"):
        load_as_built(tmp_path / "a.yaml")
    with pytest.raises(InputError, match=r"d.json: \$.steps\[1\].n: an integer of 400 digits"):
        parse_json('{"steps": [{"n": 1}, {"n": %s}]}' % ("9" * 400), "d.json")
    assert parse_json('{"n": %s}' % ("9" * 300), "d.json")["n"] == int("9" * 300)  # within a float's range


# ---------------------------------------------------------------------------------------
# 17. A robot of prismatic joints only
# ---------------------------------------------------------------------------------------
def _gantry(folder) -> str:
    """An x-y-z gantry of three prismatic joints (10 kg links), its TCP 0.1 m below the last."""
    from hostile import INERTIAL

    links = "".join(f'<link name="l{i}">{INERTIAL}</link>' for i in (1, 2, 3))
    joints = "".join(f'<joint name="j{i}" type="prismatic"><parent link="{p}"/><child link="l{i}"/>'
                     f'<origin xyz="0 0 0.2"/><axis xyz="{a}"/><limit lower="0" upper="1" effort="100" velocity="1"/>'
                     "</joint>" for i, p, a in ((1, "base", "1 0 0"), (2, "l1", "0 1 0"), (3, "l2", "0 0 1")))
    (folder / "gantry.urdf").write_text(f'<robot name="gantry"><link name="base"/>{links}{joints}<link name="tool"/>'
                                        '<joint name="jt" type="fixed"><parent link="l3"/><child link="tool"/>'
                                        '<origin xyz="0 0 -0.1"/></joint></robot>')
    return "gantry.urdf"


def test_37_17_diagnose_a_robot_of_prismatic_joints_only(tmp_path):
    """The default effects: 'ValueError: cannot reshape array of size 0' (an effect of revolute
    joints had no parameter); now it is left untried, saying why, and the rest is diagnosed."""
    robot = _gantry(tmp_path)
    answered(tmp_path, ["simulate", "--robot", robot, "--tool", "tool", "--n", "30", "--random", "--seed", "1",
                        "--out", "g.csv", "--quiet"])
    result = answered(tmp_path, ["diagnose", "g.csv", "--robot", robot, "--tool", "tool", "--quiet"])
    assert "transmission has no parameter on gantry: its joints are all prismatic" in result.stdout
    assert "Answer:" in result.stdout


# ---------------------------------------------------------------------------------------
# Minor ones
# ---------------------------------------------------------------------------------------
def test_37_minor_plan_poses_takes_quiet(campaign):
    """'unrecognized arguments: --quiet' (the README promises it on every command)."""
    answered(campaign, ["plan-poses", "m.csv", "--effects", "joint_offsets", "-k", "3", "--n-candidates", "50",
                        "--out", "next.csv", "--quiet"])
    rows = [line for line in (campaign / "next.csv").read_text().splitlines() if not line.startswith("#")]
    assert len(rows) == 4  # the header and the 3 poses


@pytest.mark.parametrize("argv, said", [
    (["iso9283", "plan", "--conditions", "-10/50", "--out", "p.csv"], "--conditions '-10/50': want LOAD/SPEED"),
    (["pose", "--q", "-1e-3", "0", "0", "0", "0", "0", "--quiet"], None),  # a value, not an unknown option
])
def test_37_minor_a_value_with_a_minus_sign_is_a_value(tmp_path, argv, said):
    """'--conditions -10/50' was read as an option ('expected at least one argument')."""
    if said is None:
        assert "j1 = -0.001 deg" in answered(tmp_path, argv).stdout
    else:
        refused(tmp_path, argv, said)


def test_37_minor_messages_name_file_and_key():
    """'list is not a list' said of a list of 1001 items; it now says what is wrong with it."""
    from tcr_accuracy.effects.file_values import effect_options
    from tcr_accuracy.exceptions import InputError

    with pytest.raises(InputError, match=r"^a.yaml: options.transmission.harmonics: 1001 items; at most 1000$"):
        effect_options("transmission", {"harmonics": [1] * 1001}, "a.yaml: options.transmission")


def test_37_minor_export_table_columns_stay_apart_past_100_mm():
    """Each column as wide as its widest figure: 'mean / RMS / max' of 123.4567 / 234.5678 / 1345.6789
    mm ran into the next column's."""
    from tcr_accuracy.view.as_built_summary import accuracy_lines

    records = [{"form": "full model", "file": "as_built.yaml", "on": "k-fold held-out", "mean_mm": 123.4567,
                "rms_mm": 234.5678, "max_mm": 1345.6789, "data": "d.json", "n": 24},
               {"form": "full model", "file": "as_built.yaml", "on": "measured", "mean_mm": 101.2, "rms_mm": 222.3,
                "max_mm": 333.4, "data": "m.csv", "n": 24}]
    row = accuracy_lines(records)[2]
    cells = [c for c in row.split("  ") if c.strip()]  # columns are two spaces apart or more
    assert [c.strip() for c in cells] == ["full model (as_built.yaml)", "123.4567 / 234.5678 / 1345.6789",
                                          "101.2000 / 222.3000 / 333.4000"]


# ---------------------------------------------------------------------------------------
# Found by the fresh attack
# ---------------------------------------------------------------------------------------
def test_37_attack_predict_query_of_training_poses_is_not_held_out(campaign):
    """--query with the training poses printed 'held-out error ... mean 0.0000 mm' (an in-sample fit)."""
    rows = (campaign / "m.csv").read_text().splitlines()
    (campaign / "q.csv").write_text("\n".join([rows[0], rows[7]]) + "\n")  # one training pose, measured
    refused(campaign, ["predict", "--train", "m.csv", "--query", "q.csv", "--method", "idw-joint", "--quiet"],
            "--query q.csv: row 2 (1 of 1 measured rows) is a pose of --train m.csv", "in-sample, not held out")


@pytest.mark.parametrize("argv, flag", [
    (["plan-poses", "m.csv", "--effects", "joint_offsets", "--out", "-"], "argument --out"),
    (["view", "--html", "-"], "argument --view/--html"),
    (["import", "t.txt", "--out", "-"], "argument --out"),
])
def test_37_attack_dash_is_no_file_where_stdout_is_not_written(campaign, argv, flag):
    """'-' was written as a file named '-', then stopped as a write outside the outputs: exit 1,
    'unexpected error: RuntimeError' (import named '-' as the file with missing columns)."""
    refused(campaign, [*argv, "--quiet"], flag, "'-' names standard output, which this option does not write")


def test_a_stabilisation_band_below_a_nanometre_is_refused(tmp_path):
    # 1e-320 mm is a subnormal float: a band no instrument resolves, refused before any file is read
    (tmp_path / "meas.csv").write_text("decoy\n")
    line = refused(tmp_path, ["iso9283", "evaluate", "meas.csv", "--band-mm", "1e-320"], "--band-mm", ">= 1e-06 mm")
    assert "1e-320" in line
