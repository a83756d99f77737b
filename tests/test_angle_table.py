"""Joint errors that follow a joint's absolute angle over +-360 deg (cable wind-up, a multi-turn
encoder): a UR10 whose joints each carry a smooth bump and a wind-up curve of a few hundred
microradians that differ at q and q + 2 pi, plus small geometry errors, 0.02 mm of tracker noise
and a reflector 0.38 m off the flange.

The truth is written out on Pinocchio directly (the joints' errors added to the commanded angles
here, joint placements perturbed by ``pin.exp6`` and the reflector placed by ``oMf.act`` in the
cyclic test's ``reflector_positions``): the diagnosis sees only the positions. What the fitted
table must be orthogonal to is integrated here with numpy's trapezoid rule, not read from the effect.
"""

import json

import numpy as np
import pytest

import tcr_accuracy as tcr
from tcr_accuracy.cli.writers import write_measurements
from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.effects import make_effect, vocabulary
from tcr_accuracy.io.measurements import MeasurementSet
from tcr_accuracy.model.robot import load_robot

from test_cyclic import _cyclic_ur10, reflector_positions, NOISE as CYCLIC_NOISE
from test_export import _quiet

NOISE = 2e-5  # [m] per axis
N_TRAIN, N_CHECK = 1200, 200


def _absolute_angle_ur10(seed: int = 3):
    """Training measurements (noisy), check poses with their true positions, the truth per joint."""
    robot = load_robot("ur10")
    rng = np.random.default_rng(seed)
    lower, upper = robot.joint_bounds()
    assert np.sum(np.isclose(upper, 2 * np.pi)) == 5  # every UR joint turns +-360 deg, the elbow +-180
    q = rng.uniform(lower, upper, (N_TRAIN + N_CHECK, 6))
    centre, width = rng.uniform(-4.0, 4.0, 6), rng.uniform(0.5, 1.0, 6)
    amplitude = rng.uniform(150e-6, 300e-6, 6)

    def truth(j, angle):  # [rad]: a bump and a wind-up, neither periodic in 2 pi
        return amplitude[j] * (np.exp(-((angle - centre[j]) / width[j]) ** 2)
                               + 0.8 * np.tanh((angle + centre[j]) / 1.2))

    real = q + np.stack([truth(j, q[:, j]) for j in range(6)], axis=1)
    position = reflector_positions(robot, real, rng)
    noisy = position[:N_TRAIN] + NOISE * rng.standard_normal((N_TRAIN, 3))
    train = MeasurementSet(joint_names=list(robot.joint_names), q=q[:N_TRAIN], position=noisy)
    return robot, train, q[N_TRAIN:], position[N_TRAIN:], truth


@pytest.fixture(scope="module")
def campaign():
    robot, train, check_q, check_position, truth = _absolute_angle_ur10()
    with_table = GapDiagnosis(robot=robot, tracker_noise=NOISE, stability_replays=2).fit(train).result_
    without = [e for e in vocabulary() if e != "angle_table"]
    cyclic_only = GapDiagnosis(robot=robot, tracker_noise=NOISE, effects=without,
                               stability_replays=2).fit(train).result_
    return {"robot": robot, "train": train, "check_q": check_q, "check_position": check_position,
            "truth": truth, "with": with_table, "without": cyclic_only}


@pytest.mark.slow
def test_errors_of_the_absolute_angle_are_named_angle_table_and_beat_cyclic(campaign):
    with_table, without = campaign["with"], campaign["without"]
    cyclic = without.candidates["cyclic"]  # the Fourier series tried on the same data, on top of what was chosen
    assert cyclic["tried"]
    print(f"held-out RMS [mm]: with angle_table {with_table.steps[-1].heldout.rms * 1e3:.4f} "
          f"({with_table.selected_effects}); without it {without.steps[-1].heldout.rms * 1e3:.4f} "
          f"({without.selected_effects}), cyclic added {cyclic['heldout_rms_mm_with_frames']:.4f}; "
          f"noise floor {with_table.noise_floor * 1e3:.4f}")
    assert "angle_table" in with_table.selected_effects
    assert with_table.steps[-1].heldout.rms <= 1.5 * with_table.noise_floor
    # the truth is smooth over +-360 deg (a bump 30-60 deg wide and a wind-up): read as such, first
    reading = next(m for m in with_table.mechanisms if m["effect"] == "angle_table")
    assert reading["mechanism_keys"][0] == "cable_windup"
    # a Fourier series of q mod 2 pi cannot hold an error that differs at q and q + 2 pi
    best_without = min(without.steps[-1].heldout.rms * 1e3, cyclic["heldout_rms_mm_with_frames"])
    assert with_table.steps[-1].heldout.rms * 1e3 < 0.7 * best_without


@pytest.mark.slow
def test_the_fitted_table_holds_nothing_of_offsets_scale_or_transmission(campaign):
    """Each joint's fitted table, integrated over its travel against 1, q and the first two harmonics,
    is orthogonal to them; and it is the truth less its own projection on them."""
    robot, d, truth = campaign["robot"], campaign["with"], campaign["truth"]
    options = d.effect_options["angle_table"]
    effect = make_effect("angle_table", robot, **options)
    fitted = d.effect_parameters["angle_table"]
    for j, joint in enumerate(robot.joint_names):
        angles = np.linspace(options["lower"][j], options["upper"][j], 20001)
        table = effect.joint_function(fitted, joint, angles)
        forbidden = np.stack([np.ones_like(angles), angles, np.sin(angles), np.cos(angles), np.sin(2 * angles),
                              np.cos(2 * angles)], axis=1)

        def inner(a, b):
            return np.trapezoid(a * b, angles)

        for column in forbidden.T:
            cosine = inner(table, column) / np.sqrt(inner(table, table) * inner(column, column))
            assert abs(cosine) < 1e-4, (joint, cosine)
        # the truth's part off those six functions (least squares here) is what the table should hold
        true = truth(j, angles)
        rest = true - forbidden @ np.linalg.lstsq(forbidden, true, rcond=None)[0]
        assert np.sqrt(np.mean((table - rest) ** 2)) < 0.25 * np.sqrt(np.mean(rest**2)), joint


@pytest.mark.slow
def test_a_high_order_fourier_truth_stays_cyclic():
    """The cyclic test's UR10 (15-28 cycles per revolution over +-180 deg): measured, the diagnosis
    names cyclic and leaves the tables out (a table with the knots these poses support cannot follow
    20 cycles per revolution, and where both could, cyclic comes first)."""
    robot, _, observations, _ = _cyclic_ur10()
    d = GapDiagnosis(robot=robot, tracker_noise=CYCLIC_NOISE, stability_replays=2).fit(observations).result_
    assert "cyclic" in d.selected_effects
    assert "angle_table" not in d.selected_effects


@pytest.mark.slow
def test_an_exported_table_predicts_the_hidden_truth(campaign, tmp_path):
    """diagnose -> JSON -> export -> as_built.yaml -> load_as_built: the model read back keeps each
    table's knots (its options) and predicts the unseen check poses' true positions within the noise,
    where the same model without its tables misses them by several times that."""
    robot, train = campaign["robot"], campaign["train"]
    write_measurements(tmp_path / "train.csv", robot, train)
    effects = "joint_offsets,geometry,encoder_scale,transmission,angle_table"
    _quiet(["diagnose", str(tmp_path / "train.csv"), "--robot", "ur10", "--effects", effects, "--noise-mm", "0.02",
            "--json", str(tmp_path / "d.json")])
    written = json.loads((tmp_path / "d.json").read_text())
    assert "angle_table" in written["selected_effects"]
    _quiet(["export", str(tmp_path / "d.json"), "--to", str(tmp_path / "out")])
    model = tcr.load_as_built(tmp_path / "out" / "as_built.yaml")
    assert model.options["angle_table"] == written["effect_options"]["angle_table"]
    check_q, check_position = campaign["check_q"], campaign["check_position"]
    tracker = model.trackerMbase

    def miss_of(m):  # [m] at each check pose, the model's point in the tracker's frame
        points = m.tcp_poses(check_q).position @ tracker[:3, :3].T + tracker[:3, 3]
        return np.linalg.norm(points - check_position, axis=1)

    miss = miss_of(model)
    zeroed = {**model.parameters, "angle_table": {n: 0.0 for n in model.parameters["angle_table"]}}
    plain_miss = miss_of(tcr.AsBuiltModel(model.robot, zeroed, model.robot_source, tracker, model.options))
    print(f"check poses, RMS miss [mm]: with tables {np.sqrt(np.mean(miss**2)) * 1e3:.4f}, "
          f"tables zeroed {np.sqrt(np.mean(plain_miss**2)) * 1e3:.4f}")
    assert np.sqrt(np.mean(miss**2)) < 1.5 * np.sqrt(3) * NOISE
    assert np.sqrt(np.mean(plain_miss**2)) > 3 * np.sqrt(np.mean(miss**2))


@pytest.mark.parametrize("travel_deg, key", [(720.0, "cable_windup"), (82.0, "gear_encoder_cyclic")])
def test_the_smoothest_mode_reads_by_how_often_it_turns_over_within_a_revolution(travel_deg, key):
    """Over two turns the smoothest function orthogonal to 1, q and the first two harmonics
    changes sign about twice (half a cycle a turn: a smooth error over the travel); over 82 deg
    (a UR5 campaign's shoulder) even that one oscillates more than 3 times a turn, where gear
    and encoder errors live."""
    from tcr_accuracy.effects.mechanisms import read_mechanism

    robot = load_robot("ur10")
    half = np.radians(travel_deg) / 2
    effect = make_effect("angle_table", robot, intervals=32, lower=[-half] * 6, upper=[half] * 6)
    values = np.zeros(effect.n_params)
    values[0] = 1e-4  # the first joint's smoothest mode, 100 urad RMS
    std = np.full(effect.n_params, 1e-6)
    assert read_mechanism(effect, values, std).keys == (key,)
