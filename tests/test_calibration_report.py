"""The calibration report: its first page against the JSON results it is made from, its PDF
(A4, the first page alone on page 1) and its width in Chromium, on screen and in print.

The figures on the first page are compared with the commands' JSON, converted to display units
here by hand (m -> mm, rad -> deg, ...), not through the report's code. The PDF is read with
pypdf (the test extra): Chromium compresses its page streams. Needs Chromium as
tests/test_browser.py does, and pypdf: without either these tests FAIL, they do not skip.
"""

import json
import math
import os
import re
import shlex
import shutil
import sys
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pypdf  # the test extra (pip install '.[test]'): without it this file fails to import, it does not skip
import pytest

from conftest import REPO, run_command

EPOCH = "1700000000"  # SOURCE_DATE_EPOCH of every run here: 2023-11-14 22:13:20 UTC
DATE = "2023-11-14"
#: SI unit -> (display unit, factor), written out here (the report uses tcr_accuracy.units)
DISPLAY = {"m": ("mm", 1e3), "rad": ("deg", 180.0 / math.pi), "rad/Nm": ("deg/kNm", 180.0 / math.pi * 1e3),
           "m/N": ("mm/kN", 1e6), "1/K": ("ppm/K", 1e6), "1": ("ppm", 1e6)}
#: A4 in PostScript points, and its printable width in CSS px at 96 per inch (the report's
#: @page margins are 12 mm left and right)
A4_PT = (595.28, 841.89)
PRINT_WIDTH_PX = round((210 - 2 * 12) / 25.4 * 96)
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--hide-scrollbars", "--virtual-time-budget=4000"]


@pytest.fixture(scope="module")
def chromium():
    path = os.environ.get("TCR_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        pytest.fail("headless Chromium is needed: apt-get install -y chromium (or set TCR_CHROMIUM)", pytrace=False)
    return path


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """One small campaign of the tool-changer, run once: a diagnosis of examples/measured.csv with
    its as-built URDF, a 25-reading ISO 9283 test evaluated with that diagnosis as --model, a
    second diagnosis (the first 100 rows) and the comparison of the two."""
    folder = tmp_path_factory.mktemp("campaign")
    cwd = os.getcwd()
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SOURCE_DATE_EPOCH", EPOCH)
        os.chdir(folder)
        try:
            shutil.copy(REPO / "examples" / "measured.csv", "measured.csv")
            lines = Path("measured.csv").read_text().splitlines()
            header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
            Path("first100.csv").write_text("\n".join(lines[header:header + 101]) + "\n")
            commands = [
                ["diagnose", "measured.csv", "--json", "d.json", "--as-built-urdf", "as_built.urdf", "--out", "rep"],
                ["diagnose", "first100.csv", "--folds", "3", "--json", "d100.json"],
                ["iso9283", "plan", "--cube-centre-mm", "0", "1400", "300", "--cube-size-mm", "200", "--cycles", "5",
                 "--out", "plan.csv"],
                ["simulate", "--scenario", str(REPO / "examples" / "scenario_compliance.yaml"), "--poses", "plan.csv",
                 "--seed", "3", "--out", "iso.csv"],
                ["iso9283", "evaluate", "iso.csv", "--model", "d.json", "--json", "iso.json", "--out", "iso_rep"],
                ["compare", "d100.json", "d.json", "--n-poses", "200", "--json", "cmp.json", "--out", "cmp_rep"],
                ["report", "d.json", "iso.json", "cmp.json", "--out", "campaign"],
            ]
            for argv in commands:
                done = _cli(argv)
                assert done.returncode == 0, f"{argv}: {done.stderr}"
        finally:
            os.chdir(cwd)
    return folder


def _cli(argv, env=None):
    environment = {**os.environ, "PYTHONPATH": str(REPO / "src"), "MPLBACKEND": "Agg", **(env or {})}
    return subprocess.run([sys.executable, "-m", "tcr_accuracy", *argv, "--quiet"], capture_output=True, text=True,
                          timeout=600, env=environment)


def _json(folder, name):
    return json.loads((folder / name).read_text(encoding="utf-8"))


class _FirstPage(HTMLParser):
    """The text of the first page's <section> and its tables' rows (lists of cell texts)."""

    def __init__(self):
        super().__init__()
        self.inside, self.text, self.rows, self.hrefs, self._cell = False, [], [], [], None

    def handle_starttag(self, tag, attrs):
        if tag == "section" and ("class", "first-page") in attrs:
            self.inside = True
        if not self.inside:
            return
        if tag == "tr":
            self.rows.append([])
        elif tag in ("td", "th"):
            self._cell = ""
        elif tag == "a":
            self.hrefs.append(dict(attrs)["href"])

    def handle_endtag(self, tag):
        if tag == "section":
            self.inside = False
        elif tag in ("td", "th") and self._cell is not None and self.inside:
            self.rows[-1].append(" ".join(self._cell.split()))
            self._cell = None

    def handle_data(self, data):
        if self.inside:
            self.text.append(data)
            if self._cell is not None:
                self._cell += data


def _first_page(index: Path) -> _FirstPage:
    page = _FirstPage()
    page.feed(index.read_text(encoding="utf-8"))
    page.joined = " ".join(" ".join(page.text).split())
    return page


def _parameter_rows(d):
    """(name, value, interval, unit) of every selected effect's parameters, from the JSON."""
    for effect in d["selected_effects"]:
        if effect == "frames":
            continue
        for name, value in d["parameters"][effect].items():
            unit, factor = DISPLAY[d["parameter_units"][effect][name]]
            low, high = d["parameter_interval_95"][effect][name]
            yield name, f"{value * factor:+.4g}", f"{low * factor:+.4g} to {high * factor:+.4g}", unit


def _pdf_pages(path: Path) -> list:
    return [" ".join(p.extract_text().split()) for p in pypdf.PdfReader(path).pages]


# ---------------------------------------------------------------------------------------
def test_first_page_states_robot_date_data_accuracy_and_every_selected_parameter(campaign):
    d = _json(campaign, "d.json")
    page = _first_page(campaign / "rep" / "index.html")
    text = page.joined
    assert "Calibration report: tool_changer" in text
    assert "j1 (revolute)" in text and "j4 (prismatic)" in text  # the tool-changer's telescopic joint
    assert DATE in text
    assert "200 measured poses in 1 session (measured.csv), 5-fold" in text
    assert f"tracker noise {d['tracker_noise_mm']:.4f} mm per axis, noise floor {d['noise_floor_mm']:.4f} mm" in text
    rows = {r[0]: r for r in page.rows if r}
    first, last = d["steps"][0], d["steps"][-1]
    for what, key in (("mean", "heldout_mean_mm"), ("RMS", "heldout_rms_mm"), ("max", "heldout_max_mm")):
        assert rows[f"TCP position error, held-out {what}"][1:] == [f"{first[key]:.4f}", f"{last[key]:.4f}", "mm"]
    assert last["heldout_rms_mm"] < 0.1 * first["heldout_rms_mm"]  # the calibration did something
    expected = list(_parameter_rows(d))
    assert len(expected) == 18  # all on the page: 4 compliance, 11 geometry, 3 joint offsets
    for name, value, interval, unit in expected:
        row = rows[name]
        assert (row[1], row[3], row[5]) == (value, interval, unit), name
    for effect in ("compliance", "geometry", "joint_offsets"):  # the selection's stability, per effect
        assert f"{effect}: held-out RMS" in text and "chosen in 100% of 50 replays" in text


def test_first_page_links_every_written_file_and_its_next_step_command_parses(campaign):
    from tcr_accuracy.cli import build_parser

    page = _first_page(campaign / "rep" / "index.html")
    targets = {(campaign / "rep" / href).resolve() for href in page.hrefs}
    for name in ("d.json", "as_built.urdf", "as_built.effects.yaml"):
        assert (campaign / name).resolve() in targets, name
        assert (campaign / name).is_file()
    assert 'printed (A4): <a href="report.pdf">' in (campaign / "rep" / "index.html").read_text()
    assert (campaign / "rep" / "report.pdf").read_bytes().startswith(b"%PDF")
    command = re.search(r"(tcr-accuracy plan-poses [^<(]*?next_poses\.csv)", page.joined).group(1)
    args = build_parser().parse_args(shlex.split(command)[1:])
    assert args.command == "plan-poses" and args.measurements == "measured.csv" and args.poses == 30
    assert "Prepared by" in page.joined and "Checked by" in page.joined


def test_pdf_is_a4_with_the_first_page_alone_on_page_1(campaign):
    d = _json(campaign, "d.json")
    pdf = campaign / "rep" / "report.pdf"
    reader = pypdf.PdfReader(pdf)
    # two independent counts: the parser's page tree and the page objects in the file's bytes
    objects = re.findall(rb"/Type\s*/Page(?![a-zA-Z])", pdf.read_bytes())
    assert len(reader.pages) == len(objects) >= 3
    for p in reader.pages:
        assert float(p.mediabox.width) == pytest.approx(A4_PT[0], abs=1) and \
            float(p.mediabox.height) == pytest.approx(A4_PT[1], abs=1)
    pages = _pdf_pages(pdf)
    first = pages[0]
    assert first.startswith("Calibration report: tool_changer")
    assert DATE in first and "200 measured poses" in first
    assert f"{d['steps'][-1]['heldout_max_mm']:.4f}" in first
    for name, value, interval, unit in _parameter_rows(d):
        assert f"{name} {value} " in first.replace("ﬀ", "ff").replace("ﬁ", "fi"), name
    assert "Prepared by Checked by" in first  # the signature block ends page 1 ...
    assert "Technical detail" not in first
    assert pages[1].startswith("Technical detail: Sim-to-real gap diagnosis")  # ... and the rest starts on page 2
    assert "software version" in pages[-1] and "tcr-accuracy diagnose measured.csv" in " ".join(pages[-2:])


_WIDTHS = """<script>
(function () {
  var page = document.documentElement.clientWidth, out = [];
  document.querySelectorAll("table, pre, img, iframe, .first-page").forEach(function (el) {
    var r = el.getBoundingClientRect();
    out.push({what: el.tagName + "." + el.className, right: r.right, left: r.left,
              scroll: el.scrollWidth, client: el.clientWidth});
  });
  var pre = document.createElement("pre");
  pre.id = "tcr-widths";
  pre.textContent = JSON.stringify({page: page, items: out});
  document.body.appendChild(pre);
})();
</script>
"""


def _widths(chromium, index: Path, width: int, print_rules: bool, tmp_path):
    """Every table's, <pre>'s and image's box as Chromium lays out ``index`` at ``width`` px; with
    ``print_rules`` the page's @media print rules apply on screen (the printable width of A4)."""
    page = index.read_text(encoding="utf-8")
    if print_rules:
        page = page.replace("@media print", "@media all")
    probe = index.with_name(f"probe-{width}.html")
    probe.write_text(page.replace("</body>", _WIDTHS + "</body>"), encoding="utf-8")
    done = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / f'profile-{width}'}",
                           f"--window-size={width},1000", "--dump-dom", probe.as_uri()],
                          capture_output=True, text=True, timeout=180)
    probe.unlink()
    assert done.returncode == 0, done.stderr[-2000:]
    found = re.search(r'<pre id="tcr-widths">(.*?)</pre>', done.stdout, flags=re.S)
    assert found, "the probe did not run"
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))


@pytest.mark.parametrize("report", ["rep", "iso_rep", "cmp_rep", "campaign"])
def test_no_table_or_printed_text_is_wider_than_the_page(chromium, campaign, tmp_path, report):
    index = campaign / report / "index.html"
    for width, print_rules in ((1280, False), (PRINT_WIDTH_PX, True)):
        laid = _widths(chromium, index, width, print_rules, tmp_path)
        assert laid["page"] == width
        tables = [i for i in laid["items"] if i["what"].startswith("TABLE")]
        assert len(tables) >= 5
        for item in laid["items"]:
            assert item["left"] >= 0 and item["right"] <= laid["page"] + 0.5, (width, item["what"], item)
            assert item["scroll"] <= item["client"] + 1, (width, item)  # nothing hidden in a scroll box
    # and in the PDF Chromium printed: no glyph starts beyond the right margin
    for p in pypdf.PdfReader(campaign / report / "report.pdf").pages:
        xs = []

        def visit(text, cm, tm, font, size):
            if text.strip():
                xs.append(cm[0] * tm[4] + cm[2] * tm[5] + cm[4])

        p.extract_text(visitor_text=visit)
        assert xs and max(xs) < float(p.mediabox.width) - 12 / 25.4 * 72 + 1


def test_iso9283_report_shows_ap_and_rp_before_and_after_as_the_json(campaign):
    iso = _json(campaign, "iso.json")
    page = _first_page(campaign / "iso_rep" / "index.html")
    rows = {r[0]: r for r in page.rows if r}
    ap = next(r for k, r in rows.items() if k.startswith("ISO 9283 pose accuracy AP_P"))
    rp = next(r for k, r in rows.items() if k.startswith("ISO 9283 repeatability RP_l"))
    assert ap[1:] == [f"{iso['summary']['ap_max_mm']:.4f}",
                      f"{iso['compensated']['summary']['ap_max_mm']:.4f} (predicted)", "mm"]
    assert rp[1] == f"{iso['summary']['rp_max_mm']:.4f}"
    assert iso["compensated"]["summary"]["ap_max_mm"] < iso["summary"]["ap_max_mm"]  # the model helps
    assert "25 readings at 5 poses" in page.joined
    assert "Effects found" in page.joined  # the --model diagnosis is on the page
    assert _pdf_pages(campaign / "iso_rep" / "report.pdf")[0].startswith("Calibration report: tool_changer")


def test_compare_report_lists_the_significant_changes_of_the_json(campaign):
    cmp = _json(campaign, "cmp.json")
    page = _first_page(campaign / "cmp_rep" / "index.html")
    rows = {r[0]: r for r in page.rows if r}
    significant = [c for c in cmp["changes"] if c["significant"]]
    assert [c["parameter"] for c in significant] == cmp["significant"]
    for c in significant:
        unit, factor = DISPLAY[c["unit"]]
        assert rows[c["parameter"]][3].startswith(f"{c['change'] * factor:+.4g} +- ")
        assert rows[c["parameter"]][5] == unit
    tcp = cmp["tcp_effect"]["significant_changes"]
    assert f"mean {tcp['mean_mm']:.4f} mm, max {tcp['max_mm']:.4f} mm" in page.joined
    assert f"{len(significant)} of {len(cmp['changes'])} robot parameters changed" in page.joined


def test_report_command_gathers_the_campaign_and_links_its_files(campaign):
    d, iso = _json(campaign, "d.json"), _json(campaign, "iso.json")
    page = _first_page(campaign / "campaign" / "index.html")
    text = page.joined
    assert f"{d['steps'][-1]['heldout_rms_mm']:.4f}" in text and f"{iso['summary']['ap_max_mm']:.4f}" in text
    assert "Changes since the earlier campaign (d100.json)" in text
    targets = {(campaign / "campaign" / href).resolve() for href in page.hrefs}
    for name in ("d.json", "iso.json", "cmp.json", "as_built.urdf", "as_built.effects.yaml"):
        assert (campaign / name).resolve() in targets, name
    pages = _pdf_pages(campaign / "campaign" / "report.pdf")
    assert "Prepared by Checked by" in pages[0] and pages[1].startswith("Technical detail")
    markdown = (campaign / "campaign" / "report.md").read_text(encoding="utf-8")
    assert markdown.startswith("# Calibration report: tool_changer") and "| Prepared by | Checked by |" in markdown


def test_report_refuses_what_is_not_a_result_of_ours_in_one_line_and_writes_nothing(tmp_path, capsys):
    (tmp_path / "other.json").write_text('{"robot": "tool_changer", "samples": 3}')
    (tmp_path / "list.json").write_text("[1, 2]")
    (tmp_path / "m.csv").write_text("j1_deg,x_mm\n1,2\n")
    for name, said in (("other.json", "other.json: not a result of tcr-accuracy diagnose"),
                       ("list.json", "list.json: not a result of tcr-accuracy diagnose"),
                       ("m.csv", "m.csv: not JSON")):
        code, out, err = run_command(["report", str(tmp_path / name), "--out", str(tmp_path / "r")], capsys)
        assert code == 2 and out == ""
        assert len(err.strip().splitlines()) == 1 and said in err, err
        assert not (tmp_path / "r").exists()


def test_results_of_two_robots_are_refused(campaign, tmp_path, capsys):
    other = _json(campaign, "iso.json")
    other["robot"] = "ur5"
    (tmp_path / "ur5_iso.json").write_text(json.dumps(other))
    code, _, err = run_command(["report", str(campaign / "d.json"), str(tmp_path / "ur5_iso.json"), "--out",
                                str(tmp_path / "r")], capsys)
    assert code == 2 and "results of different robots" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r").exists()


def test_without_chromium_the_html_is_written_and_one_line_says_there_is_no_pdf(campaign, tmp_path):
    done = _cli(["report", str(campaign / "d.json"), "--out", str(tmp_path / "r")],
                env={"TCR_CHROMIUM": str(tmp_path / "no-chromium")})
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "r" / "index.html").is_file() and not (tmp_path / "r" / "report.pdf").exists()
    done = subprocess.run([sys.executable, "-m", "tcr_accuracy", "report", str(campaign / "d.json"), "--out",
                           str(tmp_path / "r2")], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(REPO / "src"), "TCR_CHROMIUM": str(tmp_path / "none")})
    lines = [line for line in done.stderr.splitlines() if "PDF" in line]
    assert len(lines) == 1 and lines[0].startswith("PDF not written: no Chromium found"), done.stderr
    assert "report.pdf" not in (tmp_path / "r2" / "index.html").read_text()


def test_next_steps_name_what_to_check_on_the_robot(campaign):
    """A diagnosis that cannot tell two effects apart and holds a parameter on its physical bound:
    the page says to measure the poses that separate them and what to check."""
    from tcr_accuracy.view.calibration_report import Campaign, RobotFacts, first_page

    d = _json(campaign, "d.json")
    d["ambiguous"] = [{"effects": ["compliance", "lateral_compliance"], "members": []}]
    d["physical"]["compliance"]["pinned"] = [{"parameter": "compliance.j5", "bound": "lower"}]
    d["outside_physics"] = [{"effect": "backlash", "description": "backlash fits only with a negative gap",
                             "heldout_rms_mm": 0.03, "heldout_rms_bounded_mm": 0.0369}]
    html_fragment, markdown = first_page(Campaign(RobotFacts.from_documents([("d.json", d)]), [("d.json", d)]),
                                         "2023-11-14 22:13:20 UTC")
    assert "to tell apart what these measurements cannot: {compliance, lateral_compliance}" in markdown
    assert "`tcr-accuracy plan-poses measured.csv -k 30 --out next_poses.csv`" in markdown
    assert "Check on the robot which of compliance, lateral_compliance it is" in markdown
    assert "Check compliance.j5 on the robot: the fit holds it on its physical bound (lower)" in markdown
    assert "Check backlash on the robot: the data fit it only outside physics" in markdown
    assert "backlash fits only with a negative gap" in markdown  # what remains
    assert "j4 (prismatic)" in markdown  # the joints recorded in the diagnosis (its residual per joint)
