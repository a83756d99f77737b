"""The calibration report: its first page against the JSON results it is made from and the campaign
file, its PDF (A4, the first page alone on page 1: title, pass/fail line, signature block), its
plots, and its width in Chromium, on screen and in print.

The figures on the first page are compared with the commands' JSON, converted to display units
here by hand (m -> mm, rad -> deg, ...), not through the report's code; the pass/fail verdict
with the limits compared here by hand. The PDF is read with pypdf (the test extra): Chromium
compresses its page streams. Needs Chromium as tests/test_browser.py does, and pypdf: without
either these tests FAIL, they do not skip.
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


#: The campaign file the fixture's report reads (every key the first page shows).
CAMPAIGN_YAML = """title: Calibration of the cutter changer, TBM S-1234
customer: Example Tunnelling Ltd.
robot:
  model: TC-6 tool-changer
  serial: TC-0042
instrument:
  name: API Radian laser tracker
  serial: R20-1234
  certificate: DAkkS D-K-15183-01-00 of 2026-03-02
temperature_c: [19.5, 21.0]
date: 2026-11-20
operator: J. Smith
limits_mm:
  max: 0.10
  ap: 0.25
prepared_by: J. Smith
checked_by: A. Jones
"""
LIMITS = {"max": 0.10, "ap": 0.25}
#: The limit given to diagnose --out (--limit-mm): below what the calibration reaches, so it fails
TIGHT_MM = 0.05


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """One small campaign of the tool-changer, run once: a diagnosis of examples/measured.csv with
    its as-built URDF (its report with a limit it misses), a 100-reading ISO 9283 test under four
    conditions evaluated with that diagnosis as --model, a second diagnosis (the first 100 rows),
    the comparison of the two, and the report of all three with the campaign file."""
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
            Path("campaign.yaml").write_text(CAMPAIGN_YAML)
            commands = [
                ["diagnose", "measured.csv", "--json", "d.json", "--as-built-urdf", "as_built.urdf", "--out", "rep",
                 "--limit-mm", str(TIGHT_MM), "--customer", "Example Tunnelling Ltd."],
                ["diagnose", "first100.csv", "--folds", "3", "--json", "d100.json"],
                ["iso9283", "plan", "--cube-centre-mm", "0", "1400", "300", "--cube-size-mm", "200", "--cycles", "5",
                 "--out", "plan.csv"],
                ["simulate", "--scenario", str(REPO / "examples" / "scenario_compliance.yaml"), "--poses", "plan.csv",
                 "--seed", "3", "--out", "iso.csv"],
                ["iso9283", "evaluate", "iso.csv", "--model", "d.json", "--json", "iso.json", "--out", "iso_rep"],
                ["compare", "d100.json", "d.json", "--n-poses", "200", "--json", "cmp.json", "--out", "cmp_rep"],
                ["report", "d.json", "iso.json", "cmp.json", "--out", "campaign", "--campaign", "campaign.yaml"],
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
    """Each page's text, its "page x of y" (in the page's margin, read first) checked and taken off."""
    pages = [" ".join(p.extract_text().split()).replace("ﬀ", "ff").replace("ﬁ", "fi").replace("ﬂ", "fl")
             for p in pypdf.PdfReader(path).pages]
    for k, text in enumerate(pages, start=1):
        assert text.startswith(f"page {k} of {len(pages)} "), text[:40]
    return [text.split(" ", 4)[4] for text in pages]


def _tables(index: Path) -> list:
    """Every <table> of a page as lists of cell texts (whitespace collapsed)."""
    from test_browser import _Tables

    page = _Tables()
    page.feed(index.read_text(encoding="utf-8"))
    return [[[" ".join(cell.split()) for cell in row] for row in table] for table in page.tables]


def _expected_verdict(figures: dict, limits: dict) -> str:
    """PASS / FAIL / INCOMPLETE of the figures {key: value after [mm]} against the limits, by hand."""
    if any(k in figures and figures[k] > v for k, v in limits.items()):
        return "FAIL"
    return "INCOMPLETE" if any(k not in figures for k in limits) else "PASS"


# ---------------------------------------------------------------------------------------
def test_first_page_states_robot_date_accuracy_against_the_limit_and_the_mechanisms(campaign):
    d = _json(campaign, "d.json")
    page = _first_page(campaign / "rep" / "index.html")
    text = page.joined
    assert "Calibration report: tool_changer" in text
    assert "6 joints (5 revolute, 1 prismatic: j4)" in text  # the tool-changer's telescopic joint
    assert DATE in text and "Example Tunnelling Ltd." in text
    assert "200 poses in 1 session (measured.csv)" in text and "5-fold cross-validation" in text
    assert (f"noise the data show (not the instrument's specification): {d['tracker_noise_mm']:.4f} mm per axis, "
            f"noise floor {d['noise_floor_mm']:.4f} mm") in text
    rows = {r[0]: r for r in page.rows if r}
    first, last = d["steps"][0], d["steps"][-1]
    for what, key in (("mean", "heldout_mean_mm"), ("RMS", "heldout_rms_mm"), ("max", "heldout_max_mm")):
        assert rows[f"TCP position error, held-out {what}"][1:3] == [f"{first[key]:.4f}", f"{last[key]:.4f}"]
    max_row = rows["TCP position error, held-out max"]
    assert max_row[4:] == [f"{TIGHT_MM:g}", "OUTSIDE" if last["heldout_max_mm"] > TIGHT_MM else "within", "mm"]
    assert 0 < float(max_row[3]) < last["heldout_max_mm"]  # its expanded uncertainty, k = 2
    assert last["heldout_rms_mm"] < 0.1 * first["heldout_rms_mm"]  # the calibration did something
    verdict = _expected_verdict({"max": last["heldout_max_mm"]}, {"max": TIGHT_MM})
    assert verdict == "FAIL"  # the limit is below what the calibration reaches: the line can fail
    assert "Result: FAIL" in text
    assert "Result: FAIL for the full model through the compensation filter (k-fold held-out)" in text
    assert f"max k-fold held-out ({d['n_measurements']} poses): {last['heldout_max_mm']:.4f} mm > {TIGHT_MM:g} mm" in text
    # what was found leads with the primary family, then each chosen effect's mechanism and check
    found = text[text.index("What was found"):text.index("What to do next")]
    family = next(f for f in d["families"] if f["family"] == d["primary_family"])
    assert found.startswith(f"What was found The gap is mostly {d['primary_family']} ({family['what']})")
    chosen = [m for m in d["mechanisms"] if m["effect"] != "frames"]
    assert {m["effect"] for m in chosen} == set(d["selected_effects"]) - {"frames"}
    for m in chosen:  # on the page, or named where the page says what it left out for room (the budget is there)
        if f"effect {m['effect']}" in found.split("Left out here for room", 1)[-1]:
            continue
        assert f"{m['effect']} ({m['family']};" in found and m["mechanism"] in found, m["effect"]
        assert not m["check"] or f"Check: {m['check']}." in found
    shown = [m for m in chosen if f"{m['effect']} ({m['family']};" in found]
    assert shown and found.index(f"{shown[0]['effect']} (") < found.index("What remains")
    # every fitted parameter is in the technical detail, in mm and deg
    fitted = next(t for t in _tables(campaign / "rep" / "index.html")
                  if t[0][:4] == ["parameter", "value", "standard error", "95 % interval"])
    cells = {row[0]: row for row in fitted[1:]}
    expected = list(_parameter_rows(d))
    assert len(expected) == 18  # 4 compliance, 11 geometry, 3 joint offsets
    for name, value, interval, unit in expected:
        assert (cells[name][1], cells[name][3], cells[name][4]) == (value, interval, unit), name
    assert not {row[4] for row in fitted[1:]} & {"m", "rad", "rad/Nm", "m/N"}  # no SI unit a person reads


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
    assert args.command == "plan-poses" and args.measurements == ["measured.csv"] and args.poses == 30
    assert "Prepared by" in page.joined and "Checked by" in page.joined


def test_pdf_is_a4_with_title_verdict_and_signatures_alone_on_page_1(campaign):
    d, iso = _json(campaign, "d.json"), _json(campaign, "iso.json")
    pdf = campaign / "campaign" / "report.pdf"
    reader = pypdf.PdfReader(pdf)
    # two independent counts: the parser's page tree and the page objects in the file's bytes
    objects = re.findall(rb"/Type\s*/Page(?![a-zA-Z])", pdf.read_bytes())
    assert len(reader.pages) == len(objects) >= 3
    for p in reader.pages:
        assert float(p.mediabox.width) == pytest.approx(A4_PT[0], abs=1) and \
            float(p.mediabox.height) == pytest.approx(A4_PT[1], abs=1)
    pages = _pdf_pages(pdf)
    first = pages[0]
    assert first.startswith("Calibration of the cutter changer, TBM S-1234")  # the campaign file's title
    for said in ("Example Tunnelling Ltd.", "TC-6 tool-changer, serial TC-0042", "API Radian laser tracker, serial "
                 "R20-1234; certificate DAkkS D-K-15183-01-00 of 2026-03-02", "19.5 to 21.0 degC",
                 "measured 2026-11-20", "J. Smith", "200 poses"):
        assert said in first, said
    assert f"{d['steps'][-1]['heldout_max_mm']:.4f}" in first
    ap_after = max(b["compensated"]["summary"]["ap_max_mm"] for b in iso["conditions"])
    verdict = _expected_verdict({"max": d["steps"][-1]["heldout_max_mm"], "ap": ap_after}, LIMITS)
    assert verdict == "PASS"
    assert ("Result: PASS for the full model through the compensation filter (k-fold held-out): the figure with a "
            "stated limit is within it") in first
    assert "Result: NOT JUDGED for the calibration URDF and the controller files: no export result given" in first
    assert ("Result: PASS for the full model, predicted for the ISO 9283 test (iso.csv): the figure with a stated "
            "limit is within it") in first
    assert "Prepared by Checked by J. Smith name, signature, date A. Jones name, signature, date" in first
    assert "Technical detail" not in first
    assert pages[1].startswith("Technical detail: Calibration of the cutter changer")  # the rest from page 2
    assert "software version" in pages[-1] and "tcr-accuracy report d.json iso.json cmp.json" in " ".join(pages[-2:])
    # the diagnosis' own report: its page 1 holds its title, its (failing) verdict and the lines to sign
    own = _pdf_pages(campaign / "rep" / "report.pdf")
    assert own[0].startswith("Calibration report: tool_changer") and "Result: FAIL" in own[0]
    assert "Prepared by Checked by" in own[0] and own[1].startswith("Technical detail")


def test_report_draws_its_plots_from_the_json_after_page_1(campaign):
    index = campaign / "campaign" / "index.html"
    page = index.read_text(encoding="utf-8")
    figures = re.findall(r'<img src="(figure-\d+\.png)" alt="([^"]*)"', page)
    captions = [caption for _, caption in figures]
    assert any(c.startswith("How far the gap shrinks (d.json)") for c in captions)
    assert any(c.startswith("Share of each family of effects") for c in captions)
    assert any(c.startswith("ISO 9283 pose accuracy AP_P and repeatability RP_l per pose (iso.json)") for c in captions)
    assert any(c.startswith("Change of each robot parameter") for c in captions)
    assert page.index("</section>") < page.index("<img")  # after the first page
    for name, _ in figures:
        assert (campaign / "campaign" / name).read_bytes().startswith(b"\x89PNG")
    reader = pypdf.PdfReader(campaign / "campaign" / "report.pdf")
    assert not reader.pages[0].images  # page 1 is text only
    assert sum(len(p.images) for p in reader.pages[1:]) >= len(figures)


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


def _probe(chromium, index: Path, width: int, print_rules: bool, tmp_path, script: str, pre_id: str):
    """What ``script`` writes into <pre id=pre_id> (JSON) when Chromium lays out ``index`` at ``width``
    px; with ``print_rules`` the page's @media print rules apply on screen (the printable width of A4)."""
    page = index.read_text(encoding="utf-8")
    if print_rules:
        page = page.replace("@media print", "@media all")
    probe = index.with_name(f"probe-{pre_id}-{width}.html")
    probe.write_text(page.replace("</body>", script + "</body>"), encoding="utf-8")
    done = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / f'profile-{pre_id}-{width}'}",
                           f"--window-size={width},1000", "--dump-dom", probe.as_uri()],
                          capture_output=True, text=True, timeout=180)
    probe.unlink()
    assert done.returncode == 0, done.stderr[-2000:]
    found = re.search(rf'<pre id="{pre_id}">(.*?)</pre>', done.stdout, flags=re.S)
    assert found, "the probe did not run"
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&").replace("&lt;", "<")
                      .replace("&gt;", ">"))


def _widths(chromium, index: Path, width: int, print_rules: bool, tmp_path):
    """Every table's, <pre>'s and image's box as Chromium lays out ``index`` at ``width`` px."""
    return _probe(chromium, index, width, print_rules, tmp_path, _WIDTHS, "tcr-widths")


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


def test_iso9283_report_shows_the_largest_ap_and_rp_before_and_after_as_the_json(campaign):
    iso = _json(campaign, "iso.json")
    page = _first_page(campaign / "iso_rep" / "index.html")
    rows = {r[0]: r for r in page.rows if r}
    ap = next(r for k, r in rows.items() if k.startswith("ISO 9283 pose accuracy AP_P"))
    rp = next(r for k, r in rows.items() if k.startswith("ISO 9283 repeatability RP_l"))
    blocks = iso["conditions"]  # the largest over the poses of every test condition
    assert len(blocks) == 4 and "largest of 5 poses x 4 conditions" in ap[0] and "after: predicted" in ap[0]
    assert ap[1:3] == [f"{max(b['summary']['ap_max_mm'] for b in blocks):.4f}",
                       f"{max(b['compensated']['summary']['ap_max_mm'] for b in blocks):.4f}"]
    assert rp[1] == f"{max(b['summary']['rp_max_mm'] for b in blocks):.4f}"
    assert iso["compensated"]["summary"]["ap_max_mm"] < iso["summary"]["ap_max_mm"]  # the model helps
    assert "100 readings at 5 poses, 4 test conditions" in page.joined
    assert "What was found" in page.joined  # the --model diagnosis is on the page
    assert _pdf_pages(campaign / "iso_rep" / "report.pdf")[0].startswith("Calibration report: tool_changer")
    assert re.search(r'<img src="figure-\d+\.png" alt="ISO 9283 pose accuracy AP_P',
                     (campaign / "iso_rep" / "index.html").read_text())


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
    ap = max(b["summary"]["ap_max_mm"] for b in iso["conditions"])
    assert f"{d['steps'][-1]['heldout_rms_mm']:.4f}" in text and f"{ap:.4f}" in text
    assert "Since the earlier campaign (d100.json)" in text
    targets = {(campaign / "campaign" / href).resolve() for href in page.hrefs}
    for name in ("d.json", "iso.json", "cmp.json", "as_built.urdf", "as_built.effects.yaml"):
        assert (campaign / name).resolve() in targets, name
    pages = _pdf_pages(campaign / "campaign" / "report.pdf")
    assert "Prepared by Checked by" in pages[0] and pages[1].startswith("Technical detail")
    markdown = (campaign / "campaign" / "report.md").read_text(encoding="utf-8")
    assert markdown.startswith("# Calibration of the cutter changer, TBM S-1234") and "| Prepared by | Checked by |" in markdown


def test_report_refuses_what_is_not_a_result_of_ours_in_one_line_and_writes_nothing(tmp_path, capsys):
    (tmp_path / "other.json").write_text('{"robot": "tool_changer", "samples": 3}')
    (tmp_path / "list.json").write_text("[1, 2]")
    (tmp_path / "m.csv").write_text("j1_deg,x_mm\n1,2\n")
    for name, said in (("other.json", "other.json: not a diagnosis, ISO 9283 evaluation, comparison or export result"),
                       ("list.json", "list.json: not a diagnosis, ISO 9283 evaluation, comparison or export result"),
                       ("m.csv", "m.csv: not JSON")):
        code, out, err = run_command(["report", str(tmp_path / name), "--out", str(tmp_path / "r")], capsys)
        assert code == 2 and out == ""
        assert len(err.strip().splitlines()) == 1 and said in err, err
        assert not (tmp_path / "r").exists()


def test_results_of_two_robots_are_refused(campaign, tmp_path, capsys):
    other = _json(campaign, "iso.json")
    other.update(robot="ur5", robot_source="ur5", tool_frame="tool0")  # a pose test of a UR5, consistent in itself
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


def test_next_steps_name_what_to_check_on_the_robot(campaign, monkeypatch):
    """A diagnosis that cannot tell two effects apart and holds a parameter on its physical bound:
    the page says to measure the poses that separate them and what to check (room for all of it:
    what is left out of a full page is tested below)."""
    from tcr_accuracy.view import calibration_report
    from tcr_accuracy.view.calibration_report import Campaign, RobotFacts, first_page

    monkeypatch.setattr(calibration_report, "FIRST_PAGE_LINES", 1000)

    d = _json(campaign, "d.json")
    d["ambiguous"] = [{"effects": ["compliance", "lateral_compliance"], "members": []}]
    d["physical"]["compliance"]["pinned"] = [{"parameter": "compliance.j5", "bound": "lower"}]
    d["outside_physics"] = [{"effect": "backlash", "description": "backlash fits only with a negative gap",
                             "heldout_rms_mm": 0.03, "heldout_rms_bounded_mm": 0.0369}]
    html_fragment, markdown = first_page(Campaign(RobotFacts.from_documents([("d.json", d)]), [("d.json", d)]),
                                         "2023-11-14 22:13:20 UTC")
    assert ("Measure the 30 poses `tcr-accuracy plan-poses measured.csv -k 30 --out next_poses.csv` chooses to "
            "tell joints giving way under gravity from what fits as well, into next_poses_measured.csv; then run "
            "`tcr-accuracy diagnose measured.csv next_poses_measured.csv`.") in markdown  # effects in words
    assert "{compliance" not in markdown
    assert ("check on the robot which of these it is: joints giving way under gravity or joints tilting under "
            "gravity") in markdown
    assert "Check compliance.j5 on the robot: the fit holds it on its physical bound (lower)" in markdown
    assert "Check backlash on the robot: the data fit it only outside physics" in markdown
    assert "backlash fits only with a negative gap" in markdown  # what remains
    assert "1 prismatic: j4" in markdown  # the joints recorded in the diagnosis (its residual per joint)


@pytest.mark.parametrize("text, said", [
    ("customer: X\nserial: 12\n", "campaign.yaml: unknown key 'serial' (keys: title, customer"),
    ("robot:\n  serial_no: 12\n", "campaign.yaml: unknown key robot.serial_no (keys of robot: model, serial)"),
    ("limits_mm:\n  max: -0.1\n", "campaign.yaml: limits_mm.max: -0.1: want a limit in mm, a number > 0"),
    ("limits_mm:\n  accuracy: 0.1\n", "campaign.yaml: unknown key limits_mm.accuracy (keys of limits_mm: mean, rms, "
                                       "max, ap, rp)"),
    ("temperature_c: [22, 19]\n", "campaign.yaml: temperature_c: [22, 19]: want low <= high"),
    ("temperature_c: 20\n", "campaign.yaml: temperature_c: 20: want two numbers [degC]"),
    ("customer: [a, b]\n", "campaign.yaml: customer: expected text, got a list"),
    ("customer: 'x\n", "campaign.yaml: not valid YAML"),
])
def test_a_bad_campaign_file_is_one_line_naming_the_key_and_nothing_is_written(campaign, tmp_path, capsys, text,
                                                                                  said):
    (tmp_path / "campaign.yaml").write_text(text)
    code, out, err = run_command(["report", str(campaign / "d.json"), "--out", str(tmp_path / "r"), "--campaign",
                                  str(tmp_path / "campaign.yaml")], capsys)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and said in err, err
    assert not (tmp_path / "r").exists()


def test_limits_and_campaign_flags_are_checked_before_any_work(tmp_path, capsys):
    csv = REPO / "examples" / "measured.csv"
    for argv, said in ((["diagnose", str(csv), "--limit-mm", "0.1"], "--limit-mm: fills the report's first page; "
                                                                       "give --out DIR"),
                       (["diagnose", str(csv), "--customer", "X", "--json", str(tmp_path / "d.json")], "--customer:"),
                       (["report", "d.json", "--out", str(tmp_path / "r"), "--limit-mm", "0"], "--limit-mm 0: want"),
                       (["report", "d.json", "--out", str(tmp_path / "r"), "--limit-mm", "ab=1"], "--limit-mm ab=1: "
                                                                                               "want FIGURE=MM")):
        code, out, err = run_command(argv, capsys)
        assert code == 2 and len(err.strip().splitlines()) == 1 and said in err, (argv, err)
    assert not list(tmp_path.iterdir())


def test_flags_override_the_campaign_file_and_a_limit_without_its_figure_is_not_a_pass(campaign, tmp_path):
    """--customer over the file's customer; a limit on AP with no pose test in the results: INCOMPLETE."""
    from tcr_accuracy.io.campaign import read_campaign
    from tcr_accuracy.view.calibration_report import Campaign, RobotFacts, first_page

    d = _json(campaign, "d.json")
    (tmp_path / "c.yaml").write_text(CAMPAIGN_YAML)
    facts = read_campaign(tmp_path / "c.yaml").updated(customer="Other Ltd.", limits_mm={"max": 1.0})
    assert facts.limits_mm == {"max": 1.0, "ap": 0.25} and facts.customer == "Other Ltd."
    _, markdown = first_page(Campaign(RobotFacts.from_documents([("d.json", d)]), [("d.json", d)], facts=facts),
                             "2023-11-14 22:13:20 UTC")
    assert "**Customer**: Other Ltd." in markdown
    assert _expected_verdict({"max": d["steps"][-1]["heldout_max_mm"]}, facts.limits_mm) == "INCOMPLETE"
    assert ("**Result: PASS for the full model through the compensation filter (k-fold held-out)**: the figure "
            "with a stated limit is within it") in markdown
    assert ("**Result: INCOMPLETE**: no figure in these results for the limit on ISO 9283 pose accuracy AP_P, the "
            "largest pose (0.25 mm)") in markdown


_LINE_BREAKS = """<script>
(function () {
  // every place a table cell's text wraps inside a word: the character before the break (within one
  // text node: <br> and <wbr> end one, and a break there is a line's end or after a separator)
  var out = [];
  document.querySelectorAll("td, th").forEach(function (cell) {
    var walker = document.createTreeWalker(cell, NodeFilter.SHOW_TEXT), node, prev, prevTop;
    while ((node = walker.nextNode())) {
      prev = null; prevTop = null;
      for (var i = 0; i < node.length; i++) {
        var range = document.createRange();
        range.setStart(node, i); range.setEnd(node, i + 1);
        var rects = range.getClientRects();
        if (!rects.length) { continue; }
        var top = rects[0].top, ch = node.data[i];
        if (prevTop !== null && top > prevTop + 2 && ch.trim() && prev && prev.trim()) {
          out.push({before: prev, after: ch, cell: cell.textContent.slice(0, 80)});
        }
        prev = ch; prevTop = top;
      }
    }
  });
  var pre = document.createElement("pre");
  pre.id = "tcr-breaks";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
})();
</script>
"""


@pytest.mark.parametrize("report", ["rep", "campaign"])
def test_names_in_tables_wrap_at_their_separators_never_mid_word(chromium, campaign, tmp_path, report):
    """At A4's printable width (the print rules on screen) and at 700 px, every line break inside a
    word of a table cell follows a separator (. _ / : ,) or a hyphen: "shoulder_pan_join/t.a1" is
    what this forbids."""
    index = campaign / report / "index.html"
    for width, print_rules in ((PRINT_WIDTH_PX, True), (700, False)):
        breaks = _probe(chromium, index, width, print_rules, tmp_path, _LINE_BREAKS, "tcr-breaks")
        mid_word = [b for b in breaks if b["before"] not in "._/\\:,-"]
        assert not mid_word, (width, mid_word[:5])


def test_a_crowded_first_page_leaves_out_what_does_not_fit_and_keeps_the_lines_to_sign(campaign, tmp_path):
    """Eight chosen effects, ambiguous groups, parameters on their bounds, twelve significant changes and
    a pose test under four conditions: page 1 still ends with the signature block, and says what it
    left out."""
    d, iso, cmp = _json(campaign, "d.json"), _json(campaign, "iso.json"), _json(campaign, "cmp.json")
    template = next(m for m in d["mechanisms"] if m["effect"] == "geometry")
    extra = ["lateral_compliance", "backlash", "thermal", "transmission", "encoder_scale"]
    for e in extra:
        d["mechanisms"].append({**template, "effect": e, "family": "other"})
        d["steps"].append({**d["steps"][-1], "effect": e, "effects": [*d["steps"][-1]["effects"], e]})
    d["selected_effects"] += extra
    d["ambiguous"] = [{"effects": ["compliance", "lateral_compliance"], "members": []},
                      {"effects": ["transmission", "encoder_scale"], "members": []}]
    d["physical"]["geometry"]["pinned"] = [{"parameter": name, "bound": "upper"}
                                           for name in list(d["parameters"]["geometry"])[:5]]
    for ch in cmp["changes"][:12]:  # each change 9 of its standard errors (the file's figures agree)
        ch["significant"], ch["z"], ch["std_error"] = True, 9.0, abs(ch["new"] - ch["old"]) / 9.0
    cmp["significant"] = [ch["parameter"] for ch in cmp["changes"][:12]]
    for name, doc in (("d.json", d), ("iso.json", iso), ("cmp.json", cmp)):
        (tmp_path / name).write_text(json.dumps(doc))
    done = _cli(["report", *(str(tmp_path / n) for n in ("d.json", "iso.json", "cmp.json")), "--out",
                 str(tmp_path / "r"), "--campaign", str(campaign / "campaign.yaml")])
    assert done.returncode == 0, done.stderr
    first = _pdf_pages(tmp_path / "r" / "report.pdf")[0]
    assert first.startswith("Calibration of the cutter changer") and "Result: " in first
    assert "Prepared by Checked by" in first and "Technical detail" not in first
    assert "Left out here for room, in the technical detail:" in first
    assert "compliance (gravity;" in first and "geometry (geometric;" in first  # the two largest stay
