"""What follows the measurement order (``diagnosis/confounding.py``), against scipy (issue 36): which joint
angles, temperatures and payloads correlate with the order or the clock beyond 0.9 in size (Pearson's r
by ``scipy.stats.pearsonr``, the clock that correlates most), and how a confounding is said, in percent
of a signature the drift reproduces, with its verdict at 90 %. Each test names a planted change it was
seen to catch."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.diagnosis.confounding import CONFOUNDED_SHARE, Confounding, confounded_variables
from tcr_accuracy.model.context import MeasurementContext


def _campaign(n=60, seed=43):
    """Rows in order 0 .. n-1 timed 90 s apart with a jitter; joint 0 swept with the order, joint 1 against
    the clock's square (r about -0.97), joint 2 at random, joint 3 half order half noise (r below 0.9);
    the temperature warming with the clock, the payload at random."""
    rng = np.random.default_rng(seed)
    order = np.arange(n, dtype=float)
    time_s = 90.0 * order + rng.normal(0.0, 200.0, n)
    q = np.stack([0.05 * order + rng.normal(0.0, 0.05, n), -(time_s / 1e3) ** 2 + rng.normal(0.0, 2.0, n),
                  rng.uniform(-2, 2, n), 0.02 * order + rng.normal(0.0, 0.3, n)], axis=1)
    temperature = 20.0 + 5.0 * (1.0 - np.exp(-time_s / 2000.0)) + rng.normal(0.0, 0.2, n)
    payload = rng.choice([0.0, 5.0], n)
    context = MeasurementContext(payload, temperature, np.zeros((n, 4)), time_s=time_s, order=order)
    return q, context


def test_variables_following_the_order_or_the_clock_by_scipys_pearson_r():
    """Each variable's r with the order and with time_s by scipy.stats.pearsonr: those whose larger |r| exceeds
    0.9 are listed with that clock and r, each with the effects it confounds (a joint: encoder_scale; the
    temperature: thermal); the temperature and payload only where measured; a constant clock is none.
    Seen failing on ``FOLLOWS = 0.9`` turned to ``1.9`` and ``np.ptp(context.time_s) > 0`` turned to
    ``> 1`` (a clock of one second's span left out)."""
    q, context = _campaign()
    names = ["a", "b", "c", "d"]
    got = {c.variable: c for c in confounded_variables(names, q, context, {"temperature_c", "payload_kg"})}
    variables = {f"joint {n}": (q[:, j], ("encoder_scale",)) for j, n in enumerate(names)}
    variables["temperature_c"] = (context.temperature_c, ("thermal",))
    variables["payload_kg"] = (context.payload_kg, ("compliance", "lateral_compliance"))
    expected = {}
    for label, (values, effects) in variables.items():
        rs = {clock: stats.pearsonr(values, axis)[0] for clock, axis in
              (("measurement order", context.order), ("time_s", context.time_s))}
        clock = max(rs, key=lambda c: abs(rs[c]))
        if abs(rs[clock]) > 0.9:
            expected[label] = (clock, rs[clock], effects)
    assert set(expected) == {"joint a", "joint b", "temperature_c"}  # the campaign as built
    assert set(got) == set(expected)
    for label, (clock, r, effects) in expected.items():
        assert (got[label].clock, got[label].effects) == (clock, effects)
        assert got[label].r == pytest.approx(r, rel=1e-9)
    assert got["joint b"].r < 0
    # the temperature and the payload only where the rows carry them
    assert {c.variable for c in confounded_variables(names, q, context, set())} == {"joint a", "joint b"}
    # a clock whose span is one second still counts (nothing rounds it away); a constant one does not
    short = MeasurementContext(context.payload_kg, context.temperature_c, context.direction,
                               time_s=context.order / 59.0, order=None)
    assert {c.clock for c in confounded_variables(names, q, short, set())} == {"time_s"}
    still = MeasurementContext(context.payload_kg, context.temperature_c, context.direction,
                               time_s=np.full(60, 5.0), order=None)
    assert confounded_variables(names, q, still, set()) == []


def test_a_confounding_said_in_percent_of_the_signature_the_drift_reproduces():
    """Drift reproducing 93.4 % of encoder_scale's signature (at least 90 %): confounded, said as "93 %" and
    "confounded from 90 %"; 89.6 %: told apart and named; an effect without a share measured: it may be;
    r with its sign to two decimals. Seen failing on ``CONFOUNDED_SHARE = 0.9`` turned to ``1.9``,
    ``100 * share`` to ``101 * share`` and ``100 * CONFOUNDED_SHARE`` to ``101 * ...``."""
    c = Confounding("joint a", "measurement order", 0.9734, ("encoder_scale", "thermal"),
                    {"encoder_scale": 0.934, "thermal": 0.896})
    assert CONFOUNDED_SHARE == 0.9
    assert c.confounds("encoder_scale") and not c.confounds("thermal") and not c.confounds("compliance")
    assert c.judged("encoder_scale") == ("drift reproduces 93 % of encoder_scale's signature on these poses "
                                         "(confounded from 90 %): cannot be told from it")
    assert c.judged("thermal").startswith("drift reproduces 90 % of thermal's signature") and \
        c.judged("thermal").endswith(": told apart, named")
    doc = c.to_dict()
    assert doc["confounded_effects"] == ["encoder_scale"] and doc["drift_reproduces"] == {
        "encoder_scale": 0.934, "thermal": 0.896} and doc["confounded_from"] == 0.9
    assert doc["why"].startswith("joint a follows the measurement order (r = +0.97): drift reproduces 93 %")
    unmeasured = Confounding("temperature_c", "time_s", -0.951, ("thermal",))
    assert unmeasured.confounds("thermal")
    assert unmeasured.to_dict()["why"] == ("temperature_c follows the time_s (r = -0.95): an error growing with it "
                                           "(thermal) cannot be told from a drift in time")
    assert unmeasured.to_dict()["confounded_effects"] == ["thermal"] and "drift_reproduces" not in unmeasured.to_dict()
