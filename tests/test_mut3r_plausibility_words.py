"""The TCP offset check's standard error in its words (``diagnosis/plausibility.py``), third pass of issue 36: a
figure on the edge of the two digits it is printed to, so that a millimetre read a thousandth too large or too
small prints otherwise. Each test names a planted change it was seen to catch."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.plausibility import _tcp_check

MM = 1e-3


@pytest.mark.parametrize(("sigma_mm", "printed"), [(0.9951, "1"), (0.9949, "0.99")])
def test_the_offsets_standard_error_is_said_to_two_digits_in_mm(sigma_mm, printed):
    """A tool offset fitted 2 mm from the given one along x alone (no turn: the twist's translation is the
    offset): the distance's standard error is the x error itself, 0.9951 mm printed "1" and 0.9949 mm "0.99".
    Seen failing on the words' ``std * 1e3`` turned to ``* 999.0`` (0.9941: "0.99") and to ``* 1001.0``
    (0.9959: "1")."""
    offset = np.array([30.0, 1.0, -2.0]) * MM
    given = offset - np.array([2.0, 0.0, 0.0]) * MM
    x = np.concatenate([offset, np.zeros(3)])
    check = _tcp_check(x, SimpleNamespace(tool_slice=slice(0, 6)), {"tcp.dx": sigma_mm * MM, "tcp.dy": 0.5 * MM},
                       "tcp", given, SimpleNamespace(tcp_offset=1e-3), "tool0")
    assert check.std == pytest.approx(sigma_mm * MM, rel=1e-12)
    assert f": 2 mm apart (+- {printed}), beyond the 1 mm plausible" in check.text
