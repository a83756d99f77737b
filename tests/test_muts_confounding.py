"""The share of an effect's signature a drift reproduces (``diagnosis/confounding.py``) against least squares
written out here (issue 36): on columns of any scale (small ones included), at any scale of the signature, and
0 for a signature the frames make whole. Each test names a planted change it was seen to catch."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.confounding import reproduced_share


def _by_hand(signature, drift, frames):
    s = signature.ravel()
    f = frames.reshape(s.size, -1)
    both = np.concatenate([frames, drift], axis=2).reshape(s.size, -1)

    def left(a):
        return s - a @ np.linalg.lstsq(a, s, rcond=None)[0]

    return 1.0 - np.sum(left(both) ** 2) / np.sum(left(f) ** 2)


def test_the_share_a_drift_reproduces_by_least_squares_on_columns_of_any_scale():
    """Frames' and drift's columns of norms about 1e-3 (and one column of zeros, dropped), a signature of
    millimetres part drift, part frames, part neither: 1 - |s - P_{F,D} s|^2 / |s - P_F s|^2 by numpy's least
    squares; the same for the signature times 1e-9 (the floor under which a signature counts as the frames'
    is relative); 0 for a signature the frames make whole. Seen failing on ``norms > 0`` turned to ``norms >
    1``, on ``1e-12 * max(...)`` turned to ``1.000000000001`` and on ``max(float(s @ s), 1e-300)`` turned to
    ``1.0``."""
    rng = np.random.default_rng(2)
    n = 30
    frames = rng.normal(size=(n, 3, 6)) * 1e-3
    drift = rng.normal(size=(n, 3, 3)) * 1e-3
    drift[:, :, 2] = 0.0
    signature = (np.einsum("nrk,k->nr", drift[:, :, :2], [0.6, -0.4]) + np.einsum("nrk,k->nr", frames, rng.normal(size=6))
                 + rng.normal(size=(n, 3)) * 4e-4)
    expected = _by_hand(signature, drift[:, :, :2], frames)
    assert 0.2 < expected < 0.9
    assert reproduced_share(signature, drift, frames) == pytest.approx(expected, rel=1e-9)
    assert reproduced_share(signature * 1e-9, drift, frames) == pytest.approx(expected, rel=1e-6)
    whole = np.einsum("nrk,k->nr", frames, [1.0, 2.0, 0.0, -1.0, 0.5, 3.0])
    assert reproduced_share(whole, drift, frames) == 0.0


def test_a_direction_two_frame_columns_resolve_only_to_1e_13_is_not_a_frame_change():
    """Two frame columns equal but for 1e-13 of their size in a direction u, and a signature along u and a
    drift column: the frames do not make u (the near-duplicate column counts for nothing: the share is as
    without it, by numpy's least squares), so the drift reproduces its part of it. Seen failing on
    ``rcond=1e-10`` turned to ``-0.9999999999`` (machine precision: the 1e-13 resolved) and to
    ``1.0000000001``."""
    rng = np.random.default_rng(5)
    n = 20
    frames = rng.normal(size=(n, 3, 3))
    column = frames[:, :, 0].ravel()
    u = rng.normal(size=3 * n)
    u -= column * (column @ u) / (column @ column)
    frames[:, :, 1] = (column + 1e-13 * np.linalg.norm(column) * u / np.linalg.norm(u)).reshape(n, 3)
    drift = (u.reshape(n, 3) + 0.5 * rng.normal(size=(n, 3)))[:, :, None]
    signature = u.reshape(n, 3) + 0.3 * frames[:, :, 2]
    expected = _by_hand(signature, drift, frames[:, :, [0, 2]])
    assert 0.2 < expected < 0.95
    assert reproduced_share(signature, drift, frames) == pytest.approx(expected, rel=1e-6)
