"""What stage 4 and the pose bootstrap read of the FIRST measured frame when a row carries several (issue 36,
third pass): each chosen effect's mechanism read from the first frame's columns, parameters and effect; the
drift's reproduced share of the first frame's signature; the family and the time axis of the first frame's
effect; the first frame's sessions for the bootstrap. The earlier stand-ins had one measured frame, where
``per_part[0]`` and ``per_part[-1]`` are the same: here the second frame's columns, parameters and effects
differ from the first's, and every figure is written out here from the first's. Each test names a planted change
it was seen to catch."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.confounding import Confounding
from tcr_accuracy.diagnosis.stages import attribute
from tcr_accuracy.diagnosis.uncertainty import bootstrap_for
from tcr_accuracy.effects.mechanisms import MechanismReading

N = 14


def _two_frame_basis(rng, names, index, family="gravity", time_axes=(None, None)):
    """A basis over two measured frames: its parameter names (both frames'), which of them each frame has
    (``index``), each frame's (N, 6, k) columns and its own effect object."""
    return SimpleNamespace(names=names, index=[np.asarray(i) for i in index],
                           per_part=[SimpleNamespace(g=rng.normal(size=(N, 6, len(i))),
                                                     effect=SimpleNamespace(family=family, time_axis=axis,
                                                                            frame=p))
                                     for p, (i, axis) in enumerate(zip(index, time_axes))])


def test_each_mechanism_is_read_on_the_first_measured_frames_columns_parameters_and_effect(monkeypatch):
    """Compliance over two measured frames: three parameters shared, one of the second frame only (its index
    [0, 1, 3] against the first's [0, 1, 2]). The reading of the mechanism gets the first frame's effect, its
    parameters' values and names, and its columns' TCP motion (RMS over the poses of the position rows, written
    out here). Seen failing on ``basis.per_part[0].g`` turned to ``per_part[-1]`` (the third measuring sample's
    survivor), on ``basis.per_part[0].effect`` and on ``basis.index[0]`` turned to ``[-1]`` and ``[1]``."""
    rng = np.random.default_rng(31)
    basis = _two_frame_basis(rng, ["c.a", "c.b", "c.tool", "c.ball"], ([0, 1, 2], [0, 1, 3]))
    theta = np.array([1e-6, -2e-6, 3e-6, 4e-6])
    engine = SimpleNamespace(bases={"compliance": basis}, evaluate=lambda chosen, exact=False: {
        "phi": theta * 1e6, "scale": np.full(4, 1e-6), "phi_std": np.full(4, 0.1), "keep": {"compliance": np.arange(4)},
        "at_bound": np.zeros(4, dtype=bool), "lower": np.full(4, -np.inf)})
    calls = []
    monkeypatch.setattr(attribute, "read_mechanism", lambda *args: calls.append(args) or "read")
    assert attribute.fitted_mechanisms(engine, ["compliance"]) == ["read"]
    effect, values, spread, names, motion, pinned = calls[0]
    first = basis.per_part[0]
    assert effect is first.effect and names == ["c.a", "c.b", "c.tool"]
    np.testing.assert_allclose(values, [1e-6, -2e-6, 3e-6], rtol=1e-12)
    np.testing.assert_allclose(spread, [1e-7] * 3, rtol=1e-12)
    np.testing.assert_allclose(motion, np.sqrt(np.sum(first.g[:, :3] ** 2, axis=(0, 1)) / N), rtol=1e-12)


def test_the_drift_reproduces_a_share_of_the_first_measured_frames_signature():
    """An encoder scale, the frames and a drift over two measured frames, each frame's columns its own: the
    share of the encoder scale's first-frame signature (its first-frame columns times its fitted values, the
    kept ones at their places) the first frame's drift and frames reproduce, 1 - |s - P_{F,D} s|^2 / |s - P_F
    s|^2 by numpy's least squares. Seen failing on the signature's ``basis.per_part[0]`` and ``basis.index[0]``,
    the frames' ``per_part[0]`` and the drift's ``per_part[0]`` each turned to ``[-1]``, and on the rows'
    ``g[0:...]`` turned to ``g[1:...]``."""
    rng = np.random.default_rng(32)
    frames = _two_frame_basis(rng, [f"f{i}" for i in range(4)], ([0, 1, 2], [0, 1, 3]))
    scale = _two_frame_basis(rng, ["s0", "s1", "s2"], ([0, 1], [1, 2]))
    drift = _two_frame_basis(rng, ["d0", "d1"], ([0, 1], [0, 1]))
    scale.per_part[0].g[:, :3, 0] += 0.8 * drift.per_part[0].g[:, :3, 0]
    theta = np.array([0.1, 0.2, -0.1, 0.3, 2e-4, -3e-4])
    engine = SimpleNamespace(bases={"frames": frames, "encoder_scale": scale, "drift": drift},
                             evaluate=lambda effects, exact=False: {
                                 "phi": theta, "scale": np.ones(6),
                                 "keep": {"frames": np.arange(4), "encoder_scale": np.array([0, 2])}})
    confounding = [Confounding("joint j1", "measurement order", 0.97, ("encoder_scale",))]
    (out,) = attribute.judged_on_signatures(None, SimpleNamespace(engine=engine), ["frames", "encoder_scale"],
                                            confounding)
    full = np.array([2e-4, 0.0, -3e-4])
    s = np.einsum("nrk,k->nr", scale.per_part[0].g[:, :3], full[[0, 1]]).ravel()
    f = frames.per_part[0].g[:, :3].reshape(3 * N, -1)
    both = np.concatenate([frames.per_part[0].g[:, :3], drift.per_part[0].g[:, :3]], axis=2).reshape(3 * N, -1)

    def left(a):
        return s - a @ np.linalg.lstsq(a, s, rcond=None)[0]

    expected = 1.0 - np.sum(left(both) ** 2) / np.sum(left(f) ** 2)
    assert 0.05 < expected < 0.95
    assert out.reproduced == {"encoder_scale": pytest.approx(expected, rel=1e-9)}


def test_the_family_and_the_time_axis_are_the_first_measured_frames_effects():
    """An effect whose two frames' effect objects disagree (a stand-in): its family and whether it was fitted on
    the measurement order are read from the first frame's. Seen failing on ``_family``'s and
    ``_with_assumptions``' ``per_part[0]`` turned to ``[-1]``."""
    rng = np.random.default_rng(33)
    basis = _two_frame_basis(rng, ["d0"], ([0], [0]), time_axes=("order", "time_s"))
    basis.per_part[1].effect.family = "time"
    engine = SimpleNamespace(bases={"drift": basis})
    assert attribute._family(engine, "drift") == "gravity"
    reading = MechanismReading("drift", "time", "a drift", (), True, True, "", ())
    assumed = attribute._with_assumptions(reading, engine, None).assumed
    assert len(assumed) == 1 and assumed[0].startswith("fitted on the measurement order: the rows carry no time_s")


def test_the_pose_bootstrap_draws_within_the_first_measured_frames_sessions():
    """Two measured frames whose contexts carry different session labels (a stand-in): the bootstrap draws the
    poses within the first frame's two sessions (each replicate keeps 5 and 9 poses there), and counts a row's
    squared error over both frames. Seen failing on ``engine.parts[0]`` turned to ``parts[-1]``."""
    first = SimpleNamespace(context=SimpleNamespace(session=np.repeat([0, 1], [5, 9])))
    second = SimpleNamespace(context=SimpleNamespace(session=np.repeat([0, 1], [9, 5])))
    boot = bootstrap_for(SimpleNamespace(n_rows=N, parts=[first, second]), 3)
    assert boot.n_parts == 2 and "within each of the 2 sessions" in boot.method
    np.testing.assert_array_equal(boot.counts[:, :5].sum(axis=1), 5)
    np.testing.assert_array_equal(boot.counts[:, 5:].sum(axis=1), 9)


def test_the_fixed_point_step_takes_the_first_measured_frames_effects(monkeypatch):
    """The fixed-point check hands the deflections' motion the first frame's effect objects (with the options
    they were fitted with), not the second's. Seen failing on ``bases[e].per_part[0].effect`` turned to
    ``[-1]``."""
    from tcr_accuracy.diagnosis import attribution

    seen = []
    monkeypatch.setattr(attribution, "fixed_point_motion", lambda robot, effects, values, q, context:
                        seen.append(effects) or np.zeros((3, 3)))
    bases = {e: SimpleNamespace(per_part=[SimpleNamespace(effect=f"{e} of the first frame"),
                                          SimpleNamespace(effect=f"{e} of the second frame")])
             for e in ("compliance", "backlash")}
    attribution.fixed_point_check(SimpleNamespace(robot=None, q=None, context=None), bases,
                                  {"compliance": np.zeros(2), "backlash": np.zeros(1)}, 1e-4)
    assert seen == [["compliance of the first frame", "backlash of the first frame"]]


def test_joint_function_bands_are_those_of_the_first_measured_frames_effect():
    """A joint function (harmonics of each joint's angle) whose first frame's effect has the joint basis and
    whose second's (a stand-in) has none: the bands are the first's, the basis times the parameters. Seen
    failing on ``bases[e].per_part[0].effect`` turned to ``[-1]``."""
    from test_mut_diag_uncertainty import _HarmonicEffect

    from tcr_accuracy.diagnosis.uncertainty import joint_function_bands

    q = np.array([[-0.5, 1.0], [0.3, 2.0], [1.2, 1.5]])
    theta = np.array([1e-4, -2e-4, 5e-5, 3e-5])
    result = {"phi": theta, "scale": np.ones(4), "phi_std": np.full(4, 1e-5),
              "names": ["j1_s", "j1_c", "j2_s", "j2_c"]}
    bases = {"cyclic": SimpleNamespace(per_part=[SimpleNamespace(effect=_HarmonicEffect()),
                                                 SimpleNamespace(effect=object())])}
    bands = joint_function_bands(result, bases, ["cyclic"], q)
    angles = np.linspace(1.0, 2.0, 361)
    np.testing.assert_allclose(bands["cyclic"]["j2"]["value_rad"], 5e-5 * np.sin(angles) + 3e-5 * np.cos(angles),
                               rtol=1e-12)
