"""The effect classes are the only registry: a new effect plugs in without touching anything else."""

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
    unregister,
    vocabulary,
)
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.analysis.simulate import dominant_candidates, outside_vocabulary, simulate_measurements


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


# defining the class registered it; the tests below plug it in only where they need it
unregister("elbow_droop")


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


def test_a_new_effect_is_simulated_and_diagnosed_without_touching_anything_else(tool_changer):
    assert "elbow_droop" not in vocabulary()
    with plugged_in(ElbowDroop):
        assert "elbow_droop" in vocabulary() and "elbow_droop" in dominant_candidates()
        # the hidden truth: 0.25 deg of droop, next to the usual tracker frame and geometry
        scenario = {"effects": {"frames": {"base_mm": {"dx": 20, "dy": -15}, "base_mrad": {"rz": 4}},
                                "geometry": {"spread_mm": 0.05, "spread_mrad": 0.05},
                                "elbow_droop": {"amplitude_deg": 0.25}},
                    "context": {"directions": "none"}}
        mset, truth = simulate_measurements(tool_changer, scenario, 200, np.random.default_rng(3))
        assert truth["effects"]["elbow_droop"]["parameters"]["elbow_droop.amplitude"] == pytest.approx(
            math.radians(0.25))
        result = diagnose(tool_changer, mset, effects=["geometry", "joint_offsets", "elbow_droop"], folds=4)
    assert "elbow_droop" not in vocabulary()  # unplugged again
    assert result.primary_effect == "elbow_droop"
    fitted = result.parameters["elbow_droop"]["elbow_droop.amplitude"]
    assert fitted == pytest.approx(math.radians(0.25), rel=0.05)
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
