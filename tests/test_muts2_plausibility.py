"""Whether a fitted geometry is plausible (``diagnosis/plausibility.py``), second pass (issue 36): the standard
error of the TCP offset's distance from the given one where the parameter table lacks some of its errors,
written out here. Each test names a planted change it was seen to catch."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.plausibility import _tcp_check

MM = 1e-3


def test_an_offsets_error_missing_from_the_table_counts_as_none():
    """A fitted offset (31.3, -0.4, 1.2) mm, no turn, against a given (31, 0, 0) mm: apart by d = (0.3, -0.4, 1.2)
    mm, 1.3 mm; the table gives the x offset's error (0.02 mm), the z offset's as exactly 0, the y offset's not at
    all: the distance's error is |d_x| / |d| x 0.02 mm alone (first order), in the words to 2 digits. Seen failing
    on ``std_of.get(...) or 0.0`` turned to ``or -1.0`` and ``or 1.0`` (a missing error read as a metre)."""
    x = np.zeros(6)
    x[:3] = np.array([31.3, -0.4, 1.2]) * MM
    given = np.array([31.0, 0.0, 0.0]) * MM
    check = _tcp_check(x, SimpleNamespace(tool_slice=slice(0, 6)), {"frames.tool.dx": 0.02 * MM,
                                                                    "frames.tool.dz": 0.0},
                       "frames.tool", given, SimpleNamespace(tcp_offset=1.0 * MM), "tool0")
    assert check.value == pytest.approx(1.3 * MM, rel=1e-12)
    expected = 0.3 / 1.3 * 0.02 * MM
    assert check.std == pytest.approx(expected, rel=1e-12)
    assert f"1.3 mm apart (+- {expected / MM:.2g}), beyond the 1 mm" in check.text
