"""Cyclic joint errors of high order (strain-wave gears and encoders): a UR10 whose joints each
carry a periodic error of 15-28 cycles per revolution and a few hundred microradians, plus
small geometry errors, 0.02 mm of tracker noise and a reflector 0.38 m off the flange (0.25 m from
the last joint's axis: its cyclic error moves the reflector by about 2.5 x the noise).

The truth is written out here on Pinocchio directly (joint placements perturbed by
``pin.exp6``, the joints' cyclic errors added to the commanded angles, the reflector placed
by ``oMf.act``): the diagnosis sees only the positions.
"""

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.io.measurements import MeasurementSet
from tcr_accuracy.effects import make_effect, vocabulary
from tcr_accuracy.model.robot import load_robot

from conftest import random_joint_values

REFLECTOR = np.array([0.2, -0.15, 0.25])  # [m] in the flange frame
NOISE = 2e-5  # [m] per axis


def _cyclic_ur10(seed: int = 1, n: int = 800):
    robot = load_robot("ur10")
    rng = np.random.default_rng(seed)
    q = random_joint_values(robot, n, rng)
    orders = rng.integers(15, 26, size=6)
    amplitude = rng.uniform(150e-6, 300e-6, size=6)
    phase = rng.uniform(0, 2 * np.pi, 6)

    def truth(j, angle):  # [rad]
        return (amplitude[j] * np.sin(orders[j] * angle + phase[j])
                + 0.4 * amplitude[j] * np.cos((orders[j] + 3) * angle))

    real = q + np.stack([truth(j, q[:, j]) for j in range(6)], axis=1)
    position = reflector_positions(robot, real, rng) + NOISE * rng.standard_normal((n, 3))
    return robot, q, MeasurementSet(joint_names=list(robot.joint_names), q=q, position=position), truth


def reflector_positions(robot, real: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 3) the reflector [m] at the real joint angles (N, n) [rad] of the robot with every joint
    placement perturbed by a screw of 0.2 mm / 0.2 mrad (drawn from rng), on Pinocchio alone."""
    model = robot.model.copy()
    for j in range(1, model.njoints):
        model.jointPlacements[j] = model.jointPlacements[j] * pin.exp6(rng.normal(0.0, 2e-4, 6))
    data = model.createData()
    frame = model.getFrameId(robot.tool_frame)
    position = np.empty((len(real), 3))
    for i, row in enumerate(real):
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(row))
        position[i] = data.oMf[frame].act(REFLECTOR)
    return position


@pytest.mark.slow
def test_cyclic_errors_are_found_and_their_shapes_recovered():
    robot, q, observations, truth = _cyclic_ur10()
    d = GapDiagnosis(robot=robot, tracker_noise=NOISE, stability_replays=10).fit(observations).result_
    assert "cyclic" in d.selected_effects
    assert d.steps[-1].heldout.rms <= 1.2 * d.noise_floor
    effect = make_effect("cyclic", robot, **d.effect_options["cyclic"])
    fitted = d.effect_parameters["cyclic"]
    errors = {}
    for j, joint in enumerate(robot.joint_names):
        angles = np.sort(q[:, j])
        true = truth(j, angles)
        errors[joint] = np.sqrt(np.mean((effect.joint_function(fitted, joint, angles) - true) ** 2)) / \
            np.sqrt(np.mean(true**2))
    assert all(error < 0.2 for error in errors.values()), errors
    # every fitted coefficient inside its physical range, with a band for every joint's function
    table = d.parameter_table["cyclic"]
    assert all(table["range"][n][0] <= v <= table["range"][n][1] for n, v in table["values"].items())
    band = d.joint_function_bands["cyclic"]["shoulder_lift_joint"]
    inside = np.abs(band["value_rad"] - truth(1, band["angle_rad"])) <= 3 * band["std_rad"] + 2e-5
    assert inside.mean() > 0.9


@pytest.mark.slow
def test_without_cyclic_in_the_vocabulary_structure_remains():
    robot, _, observations, _ = _cyclic_ur10()
    effects = [e for e in vocabulary() if e != "cyclic"]
    d = GapDiagnosis(robot=robot, tracker_noise=NOISE, effects=effects, stability_replays=5).fit(observations).result_
    assert "cyclic" not in d.selected_effects
    assert d.structure_remains


@pytest.mark.parametrize("max_order", [3, 7, 30])
def test_the_series_holds_every_order_from_three_to_its_highest(max_order):
    """Orders 3..max_order inclusive, a sine and a cosine each, on every revolute joint: counted
    here by hand, and each term's joint offset against sin(n q) / cos(n q) written out (a series
    one order short fits a gear's tooth mesh frequency no more)."""
    robot = load_robot("ur5")
    effect = make_effect("cyclic", robot, max_order=max_order)
    expected = {f"cyclic.{joint}.{trig}{n}" for joint in robot.joint_names for n in range(3, max_order + 1)
                for trig in "ab"}
    assert set(effect.parameter_names()) == expected
    assert effect.n_params == 2 * (max_order - 2) * 6
    q = np.random.default_rng(3).uniform(-3, 3, (5, 6))
    names = effect.parameter_names()
    for name in (f"cyclic.wrist_1_joint.a{max_order}", f"cyclic.elbow_joint.b{max_order}", "cyclic.shoulder_pan_joint.a3"):
        params = np.zeros(effect.n_params)
        params[names.index(name)] = 2e-4
        joint, term = name.split(".")[1:]
        j, n = robot.joint_names.index(joint), int(term[1:])
        dq = effect.perturb(params, q, None).dq
        expected_dq = np.zeros_like(q)
        expected_dq[:, j] = 2e-4 * (np.sin(n * q[:, j]) if term[0] == "a" else np.cos(n * q[:, j]))
        np.testing.assert_allclose(dq, expected_dq, atol=1e-15)
