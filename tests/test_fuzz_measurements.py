"""Fuzzing the measurement CSV reader: whatever the bytes, the result is either a valid
MeasurementSet (finite SI arrays of consistent shapes) or one InputError line naming the
source. Never another exception, never a NaN."""

import importlib.resources
import warnings

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from tcr_accuracy.exceptions import InputError
from tcr_accuracy.io.measurements import MeasurementWarning, parse_measurements
from tcr_accuracy.model.robot import JointLimitWarning, load_robot

ROBOT = load_robot()
VALID = (importlib.resources.files("tcr_accuracy") / "data" / "tool_changer_cutter.csv").read_text()
VALID_LINES = VALID.splitlines()[:12]

FUZZ = settings(max_examples=100, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])


def assert_reads_or_refuses_in_one_line(text: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeasurementWarning)
        warnings.simplefilter("ignore", JointLimitWarning)
        try:
            mset = parse_measurements(text, ROBOT, source="fuzz.csv")
        except InputError as exc:
            message = str(exc)
            assert message.startswith("fuzz.csv") and "\n" not in message, message
            return
    n = mset.q.shape[0]
    assert n >= 1 and mset.q.shape == (n, ROBOT.n_joints) and mset.position.shape == (n, 3)
    assert np.all(np.isfinite(mset.q)) and np.all(np.isfinite(mset.position))
    for extra in (mset.payload_kg, mset.temperature_c, mset.direction, mset.quaternion):
        assert extra is None or (extra.shape[0] == n and np.all(np.isfinite(extra)))


def test_the_valid_head_of_the_demo_file_reads():
    assert_reads_or_refuses_in_one_line("\n".join(VALID_LINES))


@FUZZ
@given(st.text(max_size=400))
def test_arbitrary_text(text):
    assert_reads_or_refuses_in_one_line(text)


@FUZZ
@given(row=st.integers(1, len(VALID_LINES) - 1), col=st.integers(0, 16),
       cell=st.one_of(st.sampled_from(["nan", "inf", "-inf", "", " ", "1e400", "0x10", "1,5", "--1", "+1", "NaN",
                                       "1e-400", '"3"', "\u2212" + "1", "1.0.0", "true"]),
                      st.text(max_size=8), st.floats(allow_nan=True, allow_infinity=True).map(repr)))
def test_one_cell_replaced(row, col, cell):
    lines = list(VALID_LINES)
    cells = lines[row].split(",")
    cells[col % len(cells)] = cell
    lines[row] = ",".join(cells)
    assert_reads_or_refuses_in_one_line("\n".join(lines))


@FUZZ
@given(st.lists(st.integers(0, len(VALID_LINES[0].split(",")) - 1), min_size=1, max_size=4, unique=True),
       st.booleans())
def test_columns_dropped_or_header_mangled(drop, mangle):
    header = VALID_LINES[0].split(",")
    rows = [line.split(",") for line in VALID_LINES]
    keep = [c for c in range(len(header)) if c not in drop]
    out = [[r[c] for c in keep] for r in rows]
    if mangle:
        out[0] = [h.upper() for h in out[0]]
    assert_reads_or_refuses_in_one_line("\n".join(",".join(r) for r in out))


@FUZZ
@given(st.binary(max_size=300))
def test_random_bytes_decoded_leniently(blob):
    assert_reads_or_refuses_in_one_line(blob.decode("utf-8", errors="replace"))
