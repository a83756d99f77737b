"""Stage 4's figures (``diagnosis/stages/attribute.py``) on stand-in engines whose held-out errors, fits and
columns are written here, each against a computation done here on raw numpy (issue 36): the family shares
and own shares with their bootstrap intervals re-made from the replicates' counts, the comparison with the
largest (the paired z and the signed-rank z written out), the shrink table's gains, the fitted motions'
standard errors by the delta method with a finite-difference gradient, the drift's reproduced share of a
signature by least squares, the values, spreads and pins handed to the mechanism reading, and the words of
a confounding and of a drift fitted on the measurement order. Each test names a planted change it was seen
to catch. (The earlier tests reached these only through whole diagnoses, too slow for a mutation run.)"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.diagnosis.confounding import Confounding
from tcr_accuracy.diagnosis.records import ErrorStats, Step
from tcr_accuracy.diagnosis.stages import attribute
from tcr_accuracy.diagnosis.uncertainty import PoseBootstrap
from tcr_accuracy.effects.mechanisms import MechanismReading

N = 30


def _rms(squares, n_parts=1):
    return math.sqrt(np.mean(squares) / n_parts)


def _replicates(boot, squares):
    w = boot.counts.astype(float)
    return np.sqrt(w @ squares / w.sum(axis=1) / boot.n_parts)


def _interval(boot, a, b):
    """(point, low, high) of rms(a) - rms(b) with its percentile interval, re-made from the counts."""
    spread = _replicates(boot, a) - _replicates(boot, b)
    low, high = np.quantile(spread, [0.025, 0.975])
    return _rms(a, boot.n_parts) - _rms(b, boot.n_parts), low, high


def _entry_z(before, after):
    """The larger of the paired mean's z and Wilcoxon's signed-rank z (normal approximation, ties averaged)."""
    d = before - after
    paired = d.mean() / (d.std(ddof=1) / math.sqrt(d.size))
    d = d[d != 0]
    n = d.size
    ranks = stats.rankdata(np.abs(d))
    _, t = np.unique(np.abs(d), return_counts=True)
    variance = n * (n + 1) * (2 * n + 1) / 24 - np.sum(t**3 - t) / 48
    return max(paired, (ranks[d > 0].sum() - n * (n + 1) / 4) / math.sqrt(variance))


class _Engine:
    """Held-out squared errors per model (tuple of effects in vocabulary order); each effect's family."""

    def __init__(self, squares, families):
        self.squares = squares
        self.bases = {e: SimpleNamespace(per_part=[SimpleNamespace(effect=SimpleNamespace(family=f))])
                      for e, f in families.items()}
        self.n_rows, self.parts = N, [None]
        self.calls = []

    def kept(self, effects):
        return {e: np.arange(2) for e in effects}

    def evaluate(self, effects, keep=None, exact=False):
        self.calls.append((tuple(effects), keep is not None))
        squares = self.squares[tuple(effects)]
        return {"heldout_squares": squares, "heldout_stats": ErrorStats(0.0, _rms(squares), 0.0, N)}


@pytest.fixture(scope="module")
def shares_case():
    rng = np.random.default_rng(17)
    final = rng.gamma(2.0, 1.0, N)
    squares = {("frames", "joint_offsets", "geometry", "compliance", "lateral_compliance"): final,
               ("frames", "compliance", "lateral_compliance"): final + rng.gamma(2.0, 1.5, N),  # without geometric
               ("frames", "joint_offsets", "geometry"): final + rng.gamma(2.0, 1.0, N),  # without gravity
               ("frames", "joint_offsets", "geometry", "compliance"): final,
               ("frames", "geometry", "compliance"): final + rng.gamma(2.0, 0.4, N),  # without joint_offsets
               ("frames", "joint_offsets", "compliance"): final + rng.gamma(2.0, 0.9, N),  # without geometry
               ("frames", "joint_offsets", "geometry"): final + rng.gamma(2.0, 1.0, N)}
    families = {"joint_offsets": "geometric", "geometry": "geometric", "compliance": "gravity",
                "lateral_compliance": "gravity"}
    boot = PoseBootstrap.draw(N, n_replicates=300, random_state=2)
    return squares, families, boot


def test_family_shares_with_their_intervals_and_the_comparison_with_the_largest(shares_case):
    """Two families (geometric: joint offsets and geometry; gravity: compliance, with lateral compliance standing
    in for it): each share the rise of the held-out RMS without the family and its stand-ins, in the model
    joined by the stand-ins, with its percentile interval from the replicates' counts (re-made here); the
    smaller family against the largest: the difference of the two RMS, its interval, and the larger of the
    paired and the signed-rank z on the rows (written out here). Seen failing on the bootstrap table's
    difference read as ``table.difference("final", family)`` and on ``out.sort(key=lambda f: -f.share)``
    turned to ``f.share``."""
    squares, families, boot = shares_case
    engine = _Engine(squares, families)
    out = attribute.family_shares(engine, ["frames", "joint_offsets", "geometry", "compliance"],
                                  {"compliance": ("lateral_compliance", "compliance")}, boot, selection_z=2.0)
    final = squares[("frames", "joint_offsets", "geometry", "compliance", "lateral_compliance")]
    without = {"geometric": squares[("frames", "compliance", "lateral_compliance")],
               "gravity": squares[("frames", "joint_offsets", "geometry")]}
    assert [f.family for f in out] == ["geometric", "gravity"]
    assert out[0].effects == ("joint_offsets", "geometry") and out[1].effects == ("compliance",)
    assert out[0].stand_ins == () and out[1].stand_ins == ("lateral_compliance",)
    for f in out:
        value, low, high = _interval(boot, without[f.family], final)
        assert f.share == pytest.approx(value, rel=1e-12)
        assert f.interval == pytest.approx((low, high), rel=1e-12)
        assert f.heldout_without.rms == pytest.approx(_rms(without[f.family]), rel=1e-12)
    assert out[0].below_largest is None
    compared = out[1].below_largest
    value, low, high = _interval(boot, without["geometric"], without["gravity"])
    assert (compared.larger, compared.smaller, compared.threshold) == ("geometric", "gravity", 2.0)
    assert compared.difference == pytest.approx(value, rel=1e-12)
    assert compared.interval == pytest.approx((low, high), rel=1e-12)
    assert compared.z == pytest.approx(_entry_z(without["geometric"], without["gravity"]), rel=1e-12)
    assert compared.ranked == (compared.z > 2.0 and low > 0)
    # each family removed with the others held to their own parameters
    assert (("frames", "compliance", "lateral_compliance"), True) in engine.calls


def test_own_shares_and_the_largest_against_the_others(shares_case):
    """Each chosen effect's own share: the rise of the held-out RMS without it, the others held to their
    parameters, with its interval re-made from the counts; the largest (joint offsets less than geometry
    here) compared with each other one by the difference of the two and its interval, the z on the rows.
    Seen failing on ``rank_largest``'s ``ranked[1:]`` turned to ``ranked[2:]`` and its sort key's ``-(...)``
    removed."""
    squares, families, boot = shares_case
    engine = _Engine(squares, families)
    current = ["frames", "joint_offsets", "geometry", "compliance"]
    (table, own_squares), own = attribute._own_shares(engine, current, boot)
    final = squares[("frames", "joint_offsets", "geometry", "compliance")]
    without = {"joint_offsets": squares[("frames", "geometry", "compliance")],
               "geometry": squares[("frames", "joint_offsets", "compliance")],
               "compliance": squares[("frames", "joint_offsets", "geometry")]}
    assert set(own) == set(without)
    for e, sq in without.items():
        assert own[e] == pytest.approx(_interval(boot, sq, final), rel=1e-12)
    ranking = attribute.rank_largest(table, own_squares, ["joint_offsets", "geometry", "compliance"], "final", 3.0)
    largest = max(without, key=lambda e: _rms(without[e]))
    others = sorted((e for e in without if e != largest), key=lambda e: -_rms(without[e]))
    assert [(c.larger, c.smaller) for c in ranking] == [(largest, e) for e in others]
    for c, e in zip(ranking, others):
        value, low, high = _interval(boot, without[largest], without[e])
        assert (c.difference, *c.interval) == pytest.approx((value, low, high), rel=1e-12)
        assert c.z == pytest.approx(_entry_z(without[largest], without[e]), rel=1e-12)
    assert attribute.rank_largest(table, own_squares, ["geometry"], "final", 3.0) == []


def test_the_shrink_table_gains_each_step_against_the_one_before(shares_case, monkeypatch):
    """The rungs frames -> + geometry -> + compliance (planted): each step after the first with its effects,
    parameter count, training RMS, held-out errors, the paired z against the step before (mean / (sd / sqrt n)
    with ddof 1) and its gain: the fall of the held-out RMS from the step before, with its percentile
    interval from the counts. Seen failing on ``table.difference(k - 1, k)`` turned to ``(k * 1, k)``."""
    _, _, boot = shares_case
    rng = np.random.default_rng(5)
    sq = [rng.gamma(2.0, 3.0, N)]
    sq.append(sq[0] * rng.uniform(0.3, 0.9, N))
    sq.append(sq[1] * rng.uniform(0.5, 1.05, N))
    names = [("frames",), ("frames", "geometry"), ("frames", "geometry", "compliance")]
    rungs = [(effects[-1], {"effects": list(effects), "n_parameters": 6 + 4 * k,
                            "train_stats": ErrorStats(0.0, 1e-4 * (3 - k), 0.0, N),
                            "heldout_stats": ErrorStats(0.0, _rms(s), 0.0, N), "heldout_squares": s})
             for k, (effects, s) in enumerate(zip(names, sq))]
    monkeypatch.setattr(attribute, "explanation_order", lambda engine, selected: rungs)
    first = Step("frames", ("frames",), 6, 3e-4, ErrorStats(0.0, _rms(sq[0]), 0.0, N), None)
    steps = attribute.explanation_ladder(None, ["geometry", "compliance"], first, boot)
    assert steps[0] is first and len(steps) == 3
    for k in (1, 2):
        step = steps[k]
        assert (step.effect, step.effects, step.n_parameters) == (names[k][-1], names[k], 6 + 4 * k)
        assert step.train_rms == pytest.approx(1e-4 * (3 - k)) and step.heldout.rms == pytest.approx(_rms(sq[k]))
        d = sq[k - 1] - sq[k]
        assert step.z_statistic == pytest.approx(d.mean() / (d.std(ddof=1) / math.sqrt(N)), rel=1e-12)
        assert step.gain == pytest.approx(_interval(boot, sq[k - 1], sq[k]), rel=1e-12)


def _gram_store(jac, spans):
    """The engine's Gram store: the total Gram matrix and the column layout's one method used here."""
    return SimpleNamespace(total=jac.T @ jac, layout=SimpleNamespace(
        indices=lambda effects, keep: np.concatenate([spans[e][keep[e]] for e in effects])))


def _motion_case():
    rng = np.random.default_rng(3)
    n_points = 60
    spans = {"frames": np.arange(6), "joint_offsets": np.arange(6, 9), "compliance": np.arange(9, 11)}
    jac = rng.standard_normal((3 * n_points, 11))
    jac[:, 9] += 0.8 * jac[:, 6]
    jac[:, 10] += 0.5 * jac[:, 0]
    phi = rng.normal(0.0, 1.0, 11)
    cost = 0.04 * (3 * n_points - 11)

    engine = SimpleNamespace(n_rows=n_points // 2, parts=[None, None],  # two measured frames of 30 rows: 60 points
                             grams=lambda: _gram_store(jac, spans),
                             evaluate=lambda effects: {"keep": {e: np.arange(spans[e].size) for e in spans},
                                                       "phi": phi, "cost": cost, "n_observations": 3 * n_points})
    return engine, jac, phi, spans, cost, n_points


def test_motion_sizes_and_the_delta_methods_standard_error_with_a_finite_difference_gradient():
    """On a linear model written here (6 frame columns, 3 of joint offsets, 2 of compliance over two measured
    frames of 30 rows): each group's size the RMS per point of its columns times its parameters less their
    least-squares fit by the frames' columns; the standard error of the difference of two sizes sqrt(g^T C g)
    with g the difference's gradient by central finite differences and C = cost / (3N - p) (J^T J)^-1; a group
    of the frames alone has size 0. Seen failing on ``fit["n_observations"] - index.size`` turned to ``+``
    (6 % on the standard error, within the earlier test's 10 %), on ``engine.n_rows * len(engine.parts)``
    turned to ``/`` and on the gradient's ``sv[mask] / (n_rows * ...)`` turned to ``* n_rows``."""
    engine, jac, phi, spans, cost, n_points = _motion_case()
    groups = {"joint_offsets": ["joint_offsets"], "compliance": ["compliance"],
              "both": ["joint_offsets", "compliance", "frames"], "frames alone": ["frames"]}
    sizes = attribute.motion_sizes(engine, ["frames", "joint_offsets", "compliance"], groups)
    frames = jac[:, spans["frames"]]

    def size(p, members):
        cols = np.concatenate([spans[e] for e in members if e != "frames"] or [np.zeros(0, int)])
        motion = jac[:, cols] @ p[cols]
        left = motion - frames @ np.linalg.lstsq(frames, motion, rcond=None)[0]
        return math.sqrt(np.sum(left**2) / n_points)

    def gradient(members):
        out = np.zeros(11)
        for i in range(11):
            step = np.zeros(11)
            step[i] = 1e-6
            out[i] = (size(phi + step, members) - size(phi - step, members)) / 2e-6
        return out

    covariance = cost / (3 * n_points - 11) * np.linalg.inv(jac.T @ jac)
    for name, members in groups.items():
        assert sizes.size[name] == pytest.approx(size(phi, members), rel=1e-9, abs=1e-15)
    assert sizes.size["frames alone"] == 0.0
    np.testing.assert_allclose(sizes.covariance, covariance, rtol=1e-8, atol=1e-14)
    for a, b in (("joint_offsets", "compliance"), ("both", "compliance")):
        g = gradient(groups[a]) - gradient(groups[b])
        difference, se = sizes.difference(a, b)
        assert difference == pytest.approx(size(phi, groups[a]) - size(phi, groups[b]), rel=1e-9)
        assert se == pytest.approx(math.sqrt(g @ covariance @ g), rel=1e-6)
        np.testing.assert_allclose(sizes.gradient[a] - sizes.gradient[b], g, rtol=1e-5, atol=1e-8)


def test_the_drift_reproduces_a_share_of_each_chosen_effects_signature_by_least_squares():
    """A chosen encoder scale (two of its three parameters kept, after six frame parameters) whose signature is
    its columns times its fitted values (scaled back to SI); the share of it beyond the frames that the frames
    and a drift's two columns reproduce, 1 - |s - P_{F,D} s|^2 / |s - P_F s|^2 (least squares written here);
    a confounding variable of no chosen effect keeps no share. Seen failing on ``offset += kept.size`` turned to
    ``kept.size + 1``, on ``final["phi"] * final["scale"]`` turned to ``/`` and on the drift's TCP rows
    ``[:, :3]`` turned to ``[:, :4]``."""
    rng = np.random.default_rng(9)
    n = 25
    g_frames, g_scale, g_drift = rng.normal(size=(n, 6, 6)), rng.normal(size=(n, 6, 3)), rng.normal(size=(n, 6, 2))
    g_scale[:, :3, 0] += 0.7 * g_drift[:, :3, 0]
    scale = np.array([1.0] * 6 + [1e-3, 2e-3])
    theta = np.concatenate([rng.normal(size=6), [2e-4, -3e-4]])

    def basis(g, size):
        return SimpleNamespace(names=[f"p{i}" for i in range(size)], index=[np.arange(size)],
                               per_part=[SimpleNamespace(g=g)])

    engine = SimpleNamespace(bases={"frames": basis(g_frames, 6), "encoder_scale": basis(g_scale, 3),
                                    "drift": basis(g_drift, 2)},
                             evaluate=lambda effects, exact=False: {
                                 "phi": theta / scale, "scale": scale,
                                 "keep": {"frames": np.arange(6), "encoder_scale": np.array([0, 2])}})
    confounding = [Confounding("joint j1", "measurement order", 0.97, ("encoder_scale",)),
                   Confounding("temperature_c", "time_s", 0.95, ("thermal",))]
    out = attribute.judged_on_signatures(None, SimpleNamespace(engine=engine), ["frames", "encoder_scale"],
                                         confounding)
    full = np.array([2e-4, 0.0, -3e-4])
    s = np.einsum("nrk,k->nr", g_scale[:, :3], full).ravel()
    frames = g_frames[:, :3].reshape(3 * n, 6)
    both = np.concatenate([g_frames[:, :3], g_drift[:, :3]], axis=2).reshape(3 * n, 8)

    def left(a):
        return s - a @ np.linalg.lstsq(a, s, rcond=None)[0]

    expected = 1.0 - np.sum(left(both) ** 2) / np.sum(left(frames) ** 2)
    assert 0.05 < expected < 0.95
    assert out[0].reproduced == {"encoder_scale": pytest.approx(expected, rel=1e-9)}
    assert out[1].reproduced == {} and out[1].variable == "temperature_c"


def test_each_chosen_effects_values_spreads_and_pins_are_handed_to_its_mechanism_reading(monkeypatch):
    """Two chosen effects after the frames: each one's kept values and standard errors (scaled back to SI) at
    their places among its parameters, the others 0 and infinitely uncertain, pinned where held at a finite
    bound, its TCP motion per unit of each parameter the RMS over the poses of the columns' position rows
    (written here). Seen failing on the spreads' ``np.full(..., np.inf)`` read as zeros, on ``final["phi_std"] *
    final["scale"]`` turned to ``/`` and on the motion's ``slice(0, 3)`` turned to ``slice(0, 4)``."""
    rng = np.random.default_rng(4)
    n = 12
    g = {"frames": rng.normal(size=(n, 6, 2)), "compliance": rng.normal(size=(n, 6, 3)),
         "backlash": rng.normal(size=(n, 6, 2))}
    keep = {"frames": np.arange(2), "compliance": np.array([0, 2]), "backlash": np.array([1])}
    scale = np.array([1.0, 1.0, 1e-6, 2e-6, 1e-4])
    theta = np.array([0.1, 0.2, 3e-6, -4e-6, 5e-4])
    std = np.array([0.01, 0.01, 1e-7, 2e-7, 3e-5])
    at_bound = np.array([False, False, True, True, False])
    lower = np.array([-1.0, -1.0, 0.0, -np.inf, -1.0]) / scale
    effects = {e: SimpleNamespace(name=e) for e in g}
    engine = SimpleNamespace(
        bases={e: SimpleNamespace(names=[f"{e}.{i}" for i in range(g[e].shape[2])], index=[np.arange(g[e].shape[2])],
                                  per_part=[SimpleNamespace(g=g[e], effect=effects[e])]) for e in g},
        evaluate=lambda chosen, exact=False: {"phi": theta / scale, "scale": scale, "phi_std": std / scale,
                                              "keep": keep, "at_bound": at_bound, "lower": lower})
    calls = []
    monkeypatch.setattr(attribute, "read_mechanism", lambda *args: calls.append(args) or len(calls))
    assert attribute.fitted_mechanisms(engine, ["frames", "compliance", "backlash"]) == [1, 2, 3]
    expected = {"frames": ([0.1, 0.2], [0.01, 0.01], [False, False]),
                "compliance": ([3e-6, 0.0, -4e-6], [1e-7, np.inf, 2e-7], [True, False, False]),
                "backlash": ([0.0, 5e-4], [np.inf, 3e-5], [False, False])}
    for (effect, values, spread, names, motion, pinned), name in zip(calls, ["frames", "compliance", "backlash"]):
        assert effect is effects[name] and names == [f"{name}.{i}" for i in range(g[name].shape[2])]
        np.testing.assert_allclose(values, expected[name][0], rtol=1e-12)
        np.testing.assert_allclose(spread, expected[name][1], rtol=1e-12)
        np.testing.assert_array_equal(pinned, expected[name][2])
        np.testing.assert_allclose(motion, np.sqrt(np.sum(g[name][:, :3] ** 2, axis=(0, 1)) / n), rtol=1e-12)


def _reading(effect, parameters, mechanism="an encoder's scale"):
    return MechanismReading(effect, "geometric", mechanism, (), True, True, "", tuple(parameters))


def test_a_reading_confounded_with_a_drift_names_the_variable_that_follows_the_order():
    """An encoder scale read on joint j2: confounded by j2 following the measurement order (the drift
    reproducing 95 % of it), not by j3 (no parameter of it), nor by a variable of another effect, nor where the
    drift reproduces only 50 %; the words append the confounding's reason. Seen failing on
    ``p["parameter"].split(".")[1]`` turned to ``[2]`` and on the words' ``+`` dropped."""
    reading = _reading("encoder_scale", [{"parameter": "encoder_scale.j2.scale"}])
    order = Confounding("joint j2", "measurement order", 0.97, ("encoder_scale",), {"encoder_scale": 0.95})
    others = [Confounding("joint j3", "time_s", 0.99, ("encoder_scale",), {"encoder_scale": 0.99}),
              Confounding("temperature_c", "time_s", 0.95, ("thermal",)),
              Confounding("joint j2", "time_s", 0.93, ("encoder_scale",), {"encoder_scale": 0.5})]
    out = attribute._with_confounding(reading, [order] + others)
    why = order.to_dict()["why"]
    assert out.confounded == (why,)
    assert out.mechanism == f"an encoder's scale; or a drift in time, which the data cannot tell it from: {why}"
    assert attribute._with_confounding(reading, others) is reading


def test_a_drift_fitted_on_the_measurement_order_says_so():
    """A drift on the measurement order: assumed "fitted on the measurement order", the reason the rows' time_s
    (none, or one that does not vary); a drift on time_s and other effects unchanged. Seen failing on the
    assumed tuple's ``reading.assumed + (...)`` turned to ``(...)`` alone."""
    def engine(axis):
        return SimpleNamespace(bases={"drift": SimpleNamespace(per_part=[SimpleNamespace(
            effect=SimpleNamespace(time_axis=axis))])})

    reading = MechanismReading("drift", "drift", "a drift", (), True, True, "", (), (), ("before",))
    none = attribute._with_assumptions(reading, engine("order"), None)
    assert none.assumed[0] == "before" and len(none.assumed) == 2
    assert none.assumed[1].startswith("fitted on the measurement order: the rows carry no time_s column, so")
    flat = attribute._with_assumptions(reading, engine("order"), np.zeros(4))
    assert "a time_s column that does not vary (or has gaps)" in flat.assumed[1]
    assert attribute._with_assumptions(reading, engine("time_s"), None) is reading


def _attribute(monkeypatch, ranked_families, ranked_own, gravity_moves=5e-4):
    """Stage 4 on stand-ins: families geometric (joint offsets, geometry) above gravity (compliance), ranked
    apart or not; own shares of the three effects, the largest (geometry) ranked above the others or not;
    equal motions (no reversal). Returns the attribution and what the stand-ins were handed."""
    from tcr_accuracy.diagnosis.attribution import ShareComparison

    seen = {}
    families = {"joint_offsets": "geometric", "geometry": "geometric", "compliance": "gravity"}
    engine = SimpleNamespace(bases={e: SimpleNamespace(per_part=[SimpleNamespace(effect=SimpleNamespace(family=f))])
                                    for e, f in families.items()})
    stats = ErrorStats(0.0, 1e-4, 0.0, N)
    below = ShareComparison("geometric", "gravity", 1e-4, (5e-5 if ranked_families else -1e-5, 2e-4), 4.0, 3.0)
    table = [attribute.FamilyShare("geometric", ("joint_offsets", "geometry"), 3e-4, (2e-4, 4e-4), stats),
             attribute.FamilyShare("gravity", ("compliance",), 2e-4, (1e-4, 3e-4), stats, (), below)]
    monkeypatch.setattr(attribute, "confounded_variables", lambda *args: [])
    monkeypatch.setattr(attribute, "judged_on_signatures", lambda registered, candidates, current, c: c)
    monkeypatch.setattr(attribute, "fitted_mechanisms", lambda engine, current: [
        MechanismReading(e, families[e], "m", (), True, True, "", ()) for e in current if e != "frames"])
    monkeypatch.setattr(attribute, "bootstrap_for", lambda engine, rng: seen.setdefault("boot", rng.random()) and
                        SimpleNamespace(method="the bootstrap"))
    monkeypatch.setattr(attribute, "_family_table", lambda *args: table)
    monkeypatch.setattr(attribute, "motion_sizes", lambda engine, current, groups: seen.setdefault("groups", groups)
                        and attribute.MotionSizes({k: gravity_moves if k == "family gravity" else 5e-4
                                                   for k in groups}, {k: np.zeros(2) for k in groups}, np.eye(2)))
    monkeypatch.setattr(attribute, "_own_shares", lambda *args: (("table", "squares"), {
        "joint_offsets": (1e-4, 0.0, 2e-4), "geometry": (3e-4, 2e-4, 4e-4), "compliance": (2e-4, 1e-4, 3e-4)}))

    def rank(table_, squares, members, final, z):
        seen["members"] = members
        low = 1e-5 if ranked_own else -1e-5
        return [ShareComparison("geometry", other, 1e-4, (low, 3e-4), 5.0, z) for other in members if other != "geometry"]

    monkeypatch.setattr(attribute, "rank_largest", rank)
    monkeypatch.setattr(attribute, "explanation_ladder", lambda *args: ["steps"])
    monkeypatch.setattr(attribute, "selection_frequency", lambda *args, **kw: seen.setdefault("replays", (
        args[4], args[5].random(), kw["late"])) and {"frequency": {}})
    registered = SimpleNamespace(robot=SimpleNamespace(joint_names=["a", "b"]),
                                 measurements=SimpleNamespace(q=np.zeros((N, 2)), time_s=None, payload_kg=None,
                                                              temperature_c=None, direction=None),
                                 parts=[SimpleNamespace(context=None)])
    selection = SimpleNamespace(selected=["frames", "joint_offsets", "geometry", "compliance"], groups={},
                                forward_steps=[None], testable=["joint_offsets", "geometry", "compliance", "drift"],
                                late=["drift", "thermal"])
    out = attribute.attribute_effects(registered, SimpleNamespace(engine=engine), selection, selection_z=3.0,
                                      min_relative_gain=0.05, stability_replays=40, seed=123)
    return out, seen


def test_the_primary_family_and_effect_where_the_rows_rank_them_apart_and_where_they_do_not(monkeypatch):
    """Families ranked apart: the primary family is the largest (geometric) and the primary effect is sought
    among its members only; its largest own share (geometry) ranked above joint offsets: the primary effect,
    alone in its group. Not ranked apart: no primary family (every member a candidate), and geometry tied with
    those it is not ranked above: no primary effect, the group in the vocabulary's order. The bootstrap is
    seeded [seed, 3] and the replays [seed, 2] with their count and the late effects testable. Seen failing on
    ``len(top_families) == 1`` turned to ``== 2``, on ``top_families[0]`` turned to ``[1]``, on ``tied[0]``
    turned to ``[1]``, on ``default_rng([seed, 3])`` turned to ``[seed, 4]`` and ``[seed, 2]`` to ``[seed,
    3]``."""
    out, seen = _attribute(monkeypatch, ranked_families=True, ranked_own=True)
    assert out.primary_family == "geometric" and seen["members"] == ["joint_offsets", "geometry"]
    assert out.primary_effect == "geometry" and out.primary_group == ("geometry",)
    assert out.primary_tied == ("geometry",) and out.steps == ("steps",) and out.interval_method == "the bootstrap"
    assert seen["boot"] == np.random.default_rng([123, 3]).random()
    assert seen["replays"] == (40, np.random.default_rng([123, 2]).random(), ["drift"])
    assert set(seen["groups"]) == {"joint_offsets", "geometry", "compliance", "family geometric", "family gravity"}
    out, seen = _attribute(monkeypatch, ranked_families=False, ranked_own=False)
    assert out.primary_family is None and seen["members"] == ["joint_offsets", "geometry", "compliance"]
    assert out.primary_effect is None and out.primary_tied == ("geometry", "joint_offsets", "compliance")
    assert out.primary_group == ("joint_offsets", "geometry", "compliance")


def test_a_family_whose_fitted_motion_is_larger_keeps_the_primary_family_unnamed(monkeypatch):
    """Families ranked apart by their held-out shares, but the gravity family's fitted motion (0.9 mm) larger
    than the geometric family's (0.5 mm) beyond doubt: no primary family, and a note naming both motions.
    Seen failing on ``_FAMILY + primary_family`` in the note's call turned to ``*``."""
    out, _ = _attribute(monkeypatch, ranked_families=True, ranked_own=True, gravity_moves=9e-4)
    assert out.primary_family is None
    assert any(n.startswith("the family with the largest held-out share, geometric, moves the TCP by 0.5 mm RMS "
                            "beyond the frames, less than gravity 0.9 mm") for n in out.notes)


def test_motion_sizes_of_a_model_without_frames_take_nothing_out():
    """A model of joint offsets and compliance alone (no frame columns): each size the RMS per point of its
    columns times its parameters, nothing fitted out. Seen failing on ``spans.get("frames", np.zeros(0, ...))``
    turned to ``np.zeros(1, ...)``."""
    rng = np.random.default_rng(8)
    jac = rng.standard_normal((60, 5))
    phi = rng.normal(size=5)
    spans = {"joint_offsets": np.arange(3), "compliance": np.arange(3, 5)}

    engine = SimpleNamespace(n_rows=20, parts=[None], grams=lambda: _gram_store(jac, spans),
                             evaluate=lambda effects: {"keep": {e: np.arange(spans[e].size) for e in spans},
                                                       "phi": phi, "cost": 1.0, "n_observations": 60})
    sizes = attribute.motion_sizes(engine, ["joint_offsets", "compliance"], {e: [e] for e in spans})
    for e, cols in spans.items():
        assert sizes.size[e] == pytest.approx(math.sqrt(np.sum((jac[:, cols] @ phi[cols]) ** 2) / 20), rel=1e-9)
