"""The registered effect classes are the vocabulary: a new effect plugs in by registering its class, without touching anything else."""

import math

import numpy as np
import pytest

from tcr_accuracy.diagnosis.diagnose import diagnose
from tcr_accuracy.effects import (
    EffectJacobian,
    LinearEffect,
    effect_class,
    effect_classes,
    make_effect,
    plugged_in,
    register,
    vocabulary,
)
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.analysis.simulate import dominant_candidates, outside_vocabulary, simulate_measurements
from tcr_accuracy.io.measurements import parse_measurements

from hidden_robot import DEG, HiddenRobot, geometric_errors, hidden_free, in_tracker, measurement_csv, noisy, \
    random_poses, tracker_frame


class ElbowDroop(LinearEffect):
    """A toy effect no built-in effect expresses: joint 3 turns by ``p * cos(q1 - q2)``.

    It mixes two other joints' angles into one joint, so neither joint offsets nor
    transmission (harmonics of a joint's own angle) nor compliance reproduce it.
    """

    name = "elbow_droop"
    order = 65.0
    summary = "toy: elbow turned by cos(q1 - q2)"
    dominant_candidate = 6

    def __init__(self, robot, *, joint: int = 2) -> None:
        super().__init__(robot)
        self.joint = joint

    def parameter_names(self):
        return ["elbow_droop.amplitude"]

    def parameter_units(self):
        return ["rad"]

    def parameter_scales(self):
        return np.array([math.radians(0.02)])

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(q)
        ddq = np.zeros((q.shape[0], self.robot.n_joints, 1))
        ddq[:, self.joint, 0] = np.cos(q[:, 0] - q[:, 1])
        return EffectJacobian(dq=ddq)

    def dominant_spec(self, rng):
        return {"amplitude_deg": float(rng.uniform(0.2, 0.4))}


def test_an_effect_joins_the_vocabulary_only_when_registered_and_never_under_a_taken_name():
    """Defining a class registers nothing (the package lists its effects); registering a second
    class under a built-in's name is refused; an abstract class or one without a name of its own is no effect."""
    assert "elbow_droop" not in vocabulary()
    with plugged_in(ElbowDroop):
        assert "elbow_droop" in vocabulary() and effect_class("elbow_droop") is ElbowDroop
    assert "elbow_droop" not in vocabulary()

    class Impostor(ElbowDroop):
        name = "compliance"

    with pytest.raises(TypeError, match="effect name 'compliance' is taken by"):
        register(Impostor)
    with pytest.raises(TypeError, match="not a concrete Effect class"):
        register(LinearEffect)
    assert effect_class("compliance") is not Impostor


def test_the_vocabulary_is_read_from_the_classes():
    classes = effect_classes()
    assert tuple(classes) == vocabulary()
    orders = [c.order for c in classes.values()]
    assert orders == sorted(orders)
    assert vocabulary()[0] == "frames"  # frames first: every other effect is fitted on top of it
    assert {n for n, c in classes.items() if c.geometric} == {"frames", "joint_offsets", "geometry"}
    assert {n for n, c in classes.items() if c.stochastic} == {"clearance"}
    assert {n for n, c in classes.items() if c.requires_context} == {"thermal"}
    assert set(outside_vocabulary()) == {"unmodelled", "link_bending"}
    assert not set(outside_vocabulary()) & set(vocabulary())
    for name, cls in effect_classes(vocabulary_only=False).items():
        assert cls.summary, f"{name} has no summary for reports"


def _droop_truth(robot, amplitude_rad, n, seed):
    """The hidden truth of the droop test on Pinocchio alone (tests/hidden_robot.py, no effect
    class): joint 3 at ``q3 + amplitude * cos(q1 - q2)``, joint placement errors of 0.05 mm /
    0.05 mrad, the tracker 2.5 m away, 0.02 mm noise per axis. Returns the measurement CSV text."""
    rng = np.random.default_rng(seed)
    q = random_poses(robot, n, rng)
    _, placements = geometric_errors(robot, rng, offset_deg=0.0, offset_mm=0.0, placement_mm=0.05,
                                     placement_deg=0.05e-3 / DEG)
    real = q.copy()
    real[:, 2] += amplitude_rad * np.cos(q[:, 0] - q[:, 1])
    tcp = robot.tool_frame
    positions = HiddenRobot(robot, placements).positions(real, [tcp])[tcp]
    measured = noisy(rng, in_tracker(tracker_frame(rng, 2.5), positions), 2e-5)
    return measurement_csv(robot, q, {tcp: measured}, {}, per_frame=False)


def test_a_new_effect_is_simulated_and_diagnosed_without_touching_anything_else(tool_changer):
    assert "elbow_droop" not in vocabulary()
    amplitude = math.radians(0.25)
    q = random_poses(tool_changer, 20, np.random.default_rng(4))
    with plugged_in(ElbowDroop):
        assert "elbow_droop" in vocabulary() and "elbow_droop" in dominant_candidates()
        # simulated: the droop alone moves the TCP as Pinocchio does with joint 3 turned by hand
        scenario = {"effects": {"elbow_droop": {"amplitude_deg": 0.25}}, "context": {"directions": "none"}}
        mset, truth = simulate_measurements(tool_changer, scenario, 0, np.random.default_rng(3), noise_m=0.0, q=q)
        assert truth["effects"]["elbow_droop"]["parameters"]["elbow_droop.amplitude"] == pytest.approx(amplitude)
        turned = q.copy()
        turned[:, 2] += amplitude * np.cos(q[:, 0] - q[:, 1])
        by_hand = hidden_free(tool_changer).positions(turned, [tool_changer.tool_frame])[tool_changer.tool_frame]
        np.testing.assert_allclose(mset.position, by_hand, atol=1e-9)
        # diagnosed: on data written without the effect classes, next to a tracker frame and geometry
        data = parse_measurements(_droop_truth(tool_changer, amplitude, 200, seed=3), tool_changer)
        result = diagnose(tool_changer, data, effects=["geometry", "joint_offsets", "elbow_droop"], folds=4)
    assert "elbow_droop" not in vocabulary()  # unplugged again
    assert result.primary_effect == "elbow_droop"
    fitted = result.parameters["elbow_droop"]["elbow_droop.amplitude"]
    assert fitted == pytest.approx(amplitude, rel=0.05)
    assert result.steps[-1].heldout.rms < 2.0 * result.noise_floor


def test_options_are_explicit_keywords(tool_changer):
    thermal = make_effect("thermal", tool_changer, per_link=True)
    assert thermal.options == {"per_link": True} and thermal.n_params > 1
    with pytest.raises(InputError, match="unknown option.*per_links.*options: per_link"):
        make_effect("thermal", tool_changer, per_links=True)
    with pytest.raises(InputError, match="unknown effect 'complience'"):
        effect_class("complience")
    with pytest.raises(InputError, match="options"):
        simulate_measurements(tool_changer, {"effects": {"compliance": {"options": {"link_mass_spred": 0.1}}}},
                              10, np.random.default_rng(0))
