"""Reproductions of a fresh hostile-input attack on the command line (issue 29, "Done when":
a fresh attack of the same breadth, newest surface first). Each test aims at decoys in
``tmp_path`` and runs the installed command in a subprocess with a timeout: a bad input ends in
exit code 2 and ONE line on stderr naming the file and the key, row or argument at fault, no
traceback, and no file left beside the decoys.
"""

import json
import os
import shutil
import subprocess
import sys

import pytest

TIMEOUT = 300


def run_cli(args, cwd):
    """(exit code, stdout, stderr) of ``python -m tcr_accuracy ARGS`` in ``cwd``."""
    proc = subprocess.run([sys.executable, "-m", "tcr_accuracy", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=TIMEOUT, env=dict(os.environ))
    return proc.returncode, proc.stdout, proc.stderr


def listing(folder) -> set:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def assert_refused(folder, args, *named):
    """Run ``args`` in ``folder``: exit 2, one stderr line naming each of ``named``, nothing new."""
    before = listing(folder)
    code, _, err = run_cli(args, folder)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, (code, err)
    assert "Traceback" not in err and len(lines) == 1, err
    for text in named:
        assert text in lines[0], (text, lines[0])
    assert listing(folder) == before, sorted(listing(folder) - before)
    return lines[0]


@pytest.fixture
def campaign_folder(tmp_path, small_campaign):
    """tmp_path with a copy of the small campaign's diagnosis JSON (d.json) and measurements (m.csv)."""
    csv, diagnosis = small_campaign
    shutil.copy(csv, tmp_path / "m.csv")
    shutil.copy(diagnosis, tmp_path / "d.json")
    return tmp_path


# ---------------------------------------------------------------------------------------
# The campaign file (report --campaign): what YAML tags make of a text value
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("line, named", [
    ("title: !!binary aGVsbG8=\n", "title: expected text, got a bytes"),  # printed b'hello' on the first page
    ("customer: !!set {a, b}\n", "customer: expected text, got a set"),  # printed {'a', 'b'}
    ('operator: "J. Smith\\u0000"\n', "operator: holds the control character U+0000"),  # a NUL in the HTML
    ('title: "\\u202eevil"\n', "title: holds the control character U+202E"),  # text shown reversed
    ("date: 2026-13-45\n", "date: 2026-13-45 is not a day of the calendar"),  # printed as the day measured
])
def test_campaign_text_values_are_text(campaign_folder, line, named):
    (campaign_folder / "c.yaml").write_text(line)
    assert_refused(campaign_folder, ["report", "d.json", "--out", "rep", "--campaign", "c.yaml", "--quiet"],
                   "c.yaml", named)


def test_campaign_plain_text_still_read(campaign_folder):
    """What a campaign file holds in the README's example still reads (the refusals above are narrow)."""
    from tcr_accuracy.io.campaign import read_campaign

    (campaign_folder / "c.yaml").write_text("title: Caf\u00e9 \u200c S-1234\ndate: 2024-02-29\noperator: 12\n"
                                            "robot:\n  serial: 2018-301234\n")
    facts = read_campaign(campaign_folder / "c.yaml")
    assert (facts.title, facts.date, facts.operator, facts.robot_serial) == \
        ("Caf\u00e9 \u200c S-1234", "2024-02-29", "12", "2018-301234")


# ---------------------------------------------------------------------------------------
# export: measurements that are not the ones the diagnosis was fitted to
# ---------------------------------------------------------------------------------------
def test_export_refuses_measurements_of_another_fit(campaign_folder):
    """The diagnosis says it was fitted to 24 rows; export refitted the URDF to a 12-row file and
    printed its error as 'on the measured poses' without a word."""
    rows = (campaign_folder / "m.csv").read_text().splitlines()
    (campaign_folder / "half.csv").write_text("\n".join(rows[:13]) + "\n")  # the header and 12 of the 24 rows
    assert_refused(campaign_folder, ["export", "d.json", "--to", "out", "--measurements", "half.csv", "--quiet"],
                   "half.csv", "12 measurement rows", "fitted to 24")


def test_export_with_the_fitted_measurements_still_runs(campaign_folder):
    code, out, err = run_cli(["export", "d.json", "--to", "out", "--measurements", "m.csv", "--quiet"], campaign_folder)
    assert code == 0, err
    assert (campaign_folder / "out" / "as_built.urdf").is_file()


# ---------------------------------------------------------------------------------------
# Output names the system refuses, and '-' where a folder is named
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("option, value", [
    ("--to", "x" * 300),  # one name beyond the 255 bytes of a file name: "unexpected error: OSError"
    ("--to", "a/" * 3000),  # a path beyond the system's 4096 bytes
    ("--to", "-"),  # left out of the outputs as stdout is: "unexpected error: RuntimeError"
], ids=["name-300-bytes", "path-6000-bytes", "dash"])
def test_export_output_folder_names(campaign_folder, option, value):
    assert_refused(campaign_folder, ["export", "d.json", option, value, "--quiet"], f"argument {option}")


def test_long_output_file_name(campaign_folder):
    assert_refused(campaign_folder, ["diagnose", "m.csv", "--effects", "joint_offsets", "--json", "y" * 300 + ".json",
                                     "--quiet"], "argument --json", "refuses this name")


def test_a_folder_named_dash_is_written_as_dot_slash_dash(campaign_folder):
    code, _, err = run_cli(["export", "d.json", "--to", "./-", "--quiet"], campaign_folder)
    assert code == 0, err
    assert (campaign_folder / "-" / "as_built.urdf").is_file()


# ---------------------------------------------------------------------------------------
# diagnose --instrument-mpe beyond any instrument
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("a_um, b_um_per_m, named", [
    ("1e300", "1e300", "--instrument-mpe 1e300"),  # "unexpected error: LinAlgError: Eigenvalues did not converge"
    ("1e-300", "0", "--instrument-mpe 1e-300 0: want A <= 10000 um"),  # "LinAlgError: Singular matrix"
    ("0", "5000", "--instrument-mpe 0 5000: want A <= 10000 um and B <= 1000 um/m"),  # 5 mm/m: no instrument's
])
def test_instrument_mpe_beyond_any_instrument(campaign_folder, a_um, b_um_per_m, named):
    assert_refused(campaign_folder, ["diagnose", "m.csv", "--effects", "joint_offsets", "--instrument-mpe", a_um,
                                     b_um_per_m, "--quiet"], named)


def test_instrument_mpe_bounds_in_the_library():
    """The library refuses what the command line does (InputError, not a LinAlgError later)."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.frames.instrument import instrument_from

    with pytest.raises(InputError, match="instrument_mpe"):
        instrument_from(mpe=(1e300, 0.0))
    with pytest.raises(InputError, match="instrument_radial_mpe"):
        instrument_from(mpe=(15e-6, 6e-6), radial_mpe=(0.0, 1e-300))
    laser_tracker = instrument_from(mpe=(15e-6, 6e-6))  # API Radian's: a + b x distance, as given
    assert laser_tracker.transverse == (15e-6, 6e-6)


# ---------------------------------------------------------------------------------------
# diagnose: one measurement file given twice, as two spellings or as a copy
# ---------------------------------------------------------------------------------------
def test_diagnose_same_file_twice_spelt_differently(campaign_folder):
    """m.csv and ./m.csv: 'unexpected error: ZeroDivisionError' (every pose its own exact repeat,
    noise floor 0)."""
    assert_refused(campaign_folder, ["diagnose", "m.csv", "./m.csv", "--effects", "joint_offsets", "--quiet"],
                   "./m.csv is given twice")


def test_diagnose_copied_measurements_are_not_repeats(campaign_folder):
    shutil.copy(campaign_folder / "m.csv", campaign_folder / "copy.csv")
    assert_refused(campaign_folder, ["diagnose", "m.csv", "copy.csv", "--effects", "joint_offsets", "--quiet"],
                   "copy.csv", "rows of m.csv", "one session, not two")


# ---------------------------------------------------------------------------------------
# report: control characters in a result's text
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, code", [("m\u0000.csv", "U+0000"), ("\u202em.csv", "U+202E")])
def test_report_refuses_control_characters_in_a_result(campaign_folder, text, code):
    """A NUL in a diagnosis' file name went into index.html and report.md as it was."""
    doc = json.loads((campaign_folder / "d.json").read_text())
    doc["measurements"] = text
    (campaign_folder / "d.json").write_text(json.dumps(doc))
    assert_refused(campaign_folder, ["report", "d.json", "--out", "rep", "--quiet"], "d.json", "$.measurements",
                   f"control character {code}")


def test_report_of_a_result_as_written_still_runs(campaign_folder):
    code, _, err = run_cli(["report", "d.json", "--out", "rep", "--quiet"], campaign_folder)
    assert code == 0, err
    assert (campaign_folder / "rep" / "index.html").is_file() and (campaign_folder / "rep" / "report.md").is_file()


def test_report_refuses_an_iso_result_without_its_robot(campaign_folder):
    """An ISO 9283 result with its 'robot' key removed passed the one-robot check of the report
    (the figures of any robot shown under this one's name)."""
    iso = {"measurements": "iso.csv", "robot_source": "ur10", "tool_frame": "tool", "n_readings": 15, "frame": "fit",
           "poses": [{"pose_id": 1, "n": 3, "ap_mm": 0.1, "ap_x_mm": 0.1, "ap_y_mm": 0.0, "ap_z_mm": 0.0,
                      "rp_mm": 0.02}],
           "summary": {"ap_max_mm": 0.1, "rp_max_mm": 0.02}}
    (campaign_folder / "iso.json").write_text(json.dumps(iso))
    assert_refused(campaign_folder, ["report", "d.json", "iso.json", "--out", "rep", "--quiet"], "iso.json",
                   "'robot' is missing")


# ---------------------------------------------------------------------------------------
# CSV: a cell over the csv module's field limit (131072 characters)
# ---------------------------------------------------------------------------------------
BIG_CELL = "1" * 200_000


def _with_big_cell(rows: list, row: int) -> str:
    """The lines ``rows`` with the first cell of line ``row`` (0: the header) replaced by BIG_CELL."""
    lines = list(rows)
    lines[row] = BIG_CELL + lines[row][lines[row].index(","):]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("command", [
    ["diagnose", "big.csv", "--effects", "joint_offsets"],
    ["iso9283", "evaluate", "big.csv"],
    ["predict", "--train", "m.csv", "--query", "big.csv", "--method", "idw-joint"],
    ["export", "d.json", "--to", "out", "--targets", "big.csv"],
], ids=["diagnose", "iso9283", "predict-query", "export-targets"])
def test_csv_cell_over_the_field_limit(campaign_folder, command):
    """'unexpected error: Error: field larger than field limit (131072)' in every CSV reader."""
    rows = (campaign_folder / "m.csv").read_text().splitlines()
    (campaign_folder / "big.csv").write_text(_with_big_cell(rows, 5))
    assert_refused(campaign_folder, [*command, "--quiet"], "big.csv: row 6", "field limit")


def test_tracker_export_cell_over_the_field_limit(tmp_path):
    (tmp_path / "t.txt").write_text("Point ID;Time;X [mm];Y [mm];Z [mm]\nP1;10:15:00,000;1,0;2,0;3,0\n"
                                    f"P2;10:15:04,000;{BIG_CELL};2,0;3,0\n")
    assert_refused(tmp_path, ["import", "t.txt", "--out", "o.csv", "--quiet"], "t.txt: row 3", "field limit")


def test_trajectory_cell_over_the_field_limit(tmp_path):
    (tmp_path / "tr.csv").write_text(f"j1_deg,j2_deg\n{BIG_CELL},0\n")
    assert_refused(tmp_path, ["trajectory", "--file", "tr.csv", "--quiet"], "tr.csv", "field limit")
