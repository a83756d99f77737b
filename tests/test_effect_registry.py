"""The registered effect classes are the vocabulary: a new effect plugs in by registering its class, without touching anything else."""

import dataclasses
import math
import re

import numpy as np
import pytest

from tcr_accuracy.diagnosis.diagnose import diagnose
from tcr_accuracy.effects import (
    Effect,
    EffectJacobian,
    FitPolicy,
    LinearEffect,
    SimulationRules,
    effect_class,
    effect_classes,
    make_effect,
    plugged_in,
    register,
    vocabulary,
)
from tcr_accuracy.effects import base as effect_base, fit_policy, simulation_rules
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.analysis.simulate import dominant_candidates, outside_vocabulary, simulate_measurements
from tcr_accuracy.io.measurements import parse_measurements

from hidden_robot import DEG, HiddenRobot, geometric_errors, hidden_free, in_tracker, measurement_csv, noisy, \
    random_poses, tracker_frame


@dataclasses.dataclass(frozen=True)
class ElbowDroopDraws(SimulationRules):
    """A dominant droop of 0.2-0.4 deg."""

    def dominant_spec(self, effect, rng):
        return {"amplitude_deg": float(rng.uniform(0.2, 0.4))}


class ElbowDroop(LinearEffect):
    """A toy effect no built-in effect expresses: joint 3 turns by ``p * cos(q1 - q2)``.

    It mixes two other joints' angles into one joint, so neither joint offsets nor
    transmission (harmonics of a joint's own angle) nor compliance reproduce it.
    """

    name = "elbow_droop"
    summary = "toy: elbow turned by cos(q1 - q2)"
    fit_policy = FitPolicy(order=65.0)
    simulation = ElbowDroopDraws(dominant_place=6)

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
    orders = [c.fit_policy.order for c in classes.values()]
    assert orders == sorted(orders)
    assert vocabulary()[0] == "frames"  # frames first: every other effect is fitted on top of it
    assert {n for n, c in classes.items() if c.geometric} == {"frames", "joint_offsets", "geometry"}
    assert {n for n, c in classes.items() if c.stochastic} == {"clearance"}
    assert {n for n, c in classes.items() if c.fit_policy.requires_context} == {"thermal"}
    assert {n for n, c in classes.items() if c.fit_policy.last_resort} == {"cyclic", "angle_table"}
    assert set(outside_vocabulary()) == {"unmodelled", "link_bending"}
    assert not set(outside_vocabulary()) & set(vocabulary())
    for name, cls in effect_classes(vocabulary_only=False).items():
        assert cls.summary, f"{name} has no summary for reports"


# The names the old Effect base carried for fitting and drawing, written out here (not read from
# the code under test): none may come back onto an effect class.
OLD_POLICY_NAMES = ("order", "in_vocabulary", "last_resort", "requires_context", "options_for_data",
                    "penalty_weights", "analytic_jacobian")
OLD_DRAW_NAMES = ("dominant_candidate", "dominant_spec", "finish_dominant", "beyond_physics")


def test_every_effect_keeps_its_policy_and_its_draws_beside_its_physics():
    """Each registered effect has one FitPolicy and one SimulationRules object; the Effect base and
    the effect classes carry none of the old policy or drawing names; the draw order of the
    dominant effects is the one the blind benchmark's seeds were drawn with."""
    classes = effect_classes(vocabulary_only=False)
    assert len(classes) == 15
    for name, cls in classes.items():
        assert isinstance(cls.fit_policy, FitPolicy), name
        assert isinstance(cls.simulation, SimulationRules), name
        for klass in cls.__mro__:
            declared = set(vars(klass)) & set(OLD_POLICY_NAMES + OLD_DRAW_NAMES)
            assert declared <= ({"analytic_jacobian"} if klass is Effect else set()), (name, klass, declared)
    assert dominant_candidates() == ("compliance", "backlash", "thermal", "transmission", "encoder_scale")
    assert [n for n, c in classes.items() if not c.fit_policy.in_vocabulary] == ["unmodelled", "link_bending"]


def _table_rows(module) -> list[str]:
    """The first column of the ``====`` tables of a module's docstring (the names it documents)."""
    rows, inside = [], 0
    for line in module.__doc__.splitlines():
        if line.startswith("===="):
            inside += 1
        elif inside % 3 == 2 and line.startswith("``"):
            rows.append(re.match(r"``(\w+)``", line).group(1))
    return rows


def test_the_three_tables_name_what_their_homes_hold():
    """The docstring tables of base, fit_policy and simulation_rules list exactly the physics
    attributes of Effect, the fields and hooks of FitPolicy and those of SimulationRules."""
    hooks = lambda cls: {n for n, v in vars(cls).items() if callable(v) and not n.startswith("_")}  # noqa: E731
    assert sorted(_table_rows(fit_policy)) == sorted({f.name for f in dataclasses.fields(FitPolicy)} | hooks(FitPolicy))
    assert sorted(_table_rows(simulation_rules)) == sorted({f.name for f in dataclasses.fields(SimulationRules)}
                                                           | hooks(SimulationRules))
    physics = set(Effect.__annotations__) - {"fit_policy", "simulation"}
    assert sorted(_table_rows(effect_base)) == sorted(physics)


@pytest.mark.parametrize("old_way, words", [
    ({"order": 65.0}, r"declares 'order' on the class; it belongs in its fit_policy"),
    ({"last_resort": True}, r"declares 'last_resort' on the class; it belongs in its fit_policy"),
    ({"options_for_data": classmethod(lambda cls, robot, q, context: {})}, r"'options_for_data'.*fit_policy"),
    ({"dominant_candidate": 6}, r"'dominant_candidate' on the class; it belongs in its simulation"),
    ({"beyond_physics": lambda self, params, rng: -params}, r"'beyond_physics' on the class; .* simulation"),
    ({"analytic_jacobian": False}, r"'analytic_jacobian'; it is read from whether the class writes its own"),
    ({"fit_policy": {"order": 65.0}}, r"fit_policy must be a FitPolicy instance"),
    ({"simulation": ElbowDroopDraws}, r"simulation must be a SimulationRules instance"),
])
def test_register_refuses_policy_or_draws_declared_the_old_way(old_way, words):
    """An effect class that mixes a policy value or a drawing hook into its physics (as every
    effect did before fit_policy and simulation had their homes), or whose homes hold something
    else, is refused with one line naming the effect and where the attribute belongs; so is a
    subclass of such a class. Nothing is registered."""
    mixed = type("MixedDroop", (ElbowDroop,), {"name": "mixed_droop", **old_way})
    with pytest.raises(TypeError, match=r"effect 'mixed_droop' \(.*MixedDroop\): .*" + words):
        register(mixed)
    heir = type("HeirDroop", (mixed,), {"name": "heir_droop"})
    with pytest.raises(TypeError, match=r"effect 'heir_droop'.*MixedDroop declares|effect 'heir_droop'.*must be"):
        register(heir)
    assert "mixed_droop" not in effect_classes(vocabulary_only=False)
    assert "heir_droop" not in effect_classes(vocabulary_only=False)


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
