"""Both pose designs plan for an unloaded arm unless told otherwise, as ``plan-poses`` documents
(``--payload-kg``: the measurements' mean, else 0).

Compliance sags with the payload's torque, so a D-optimal design for it changes its gains with the
payload: the default's gains are those of ``payload_kg=0.0`` given explicitly, to the last bit, and
those of 1 kg differ (the comparison has teeth). The discriminating design's choices move only with
large payloads, so its default is read where it is handed on: the candidates' context is asked for
0 kg, 3000 candidates and the generator given. Seen failing on ``payload_kg: float = 0.0`` turned to
``1.0`` in ``plan_poses`` and in ``plan_discriminating_poses`` (planted by hand).
"""

import numpy as np
import pytest
from test_mutfit_design import _poses

from tcr_accuracy.diagnosis import design
from tcr_accuracy.diagnosis.design import candidate_configurations, plan_discriminating_poses, plan_poses
from tcr_accuracy.effects import make_effect
from tcr_accuracy.model.robot import load_robot


@pytest.fixture(scope="module")
def robot():
    return load_robot()


@pytest.fixture(scope="module")
def measured_and_candidates(robot):
    return _poses(robot, 5, 3), candidate_configurations(robot, 60, np.random.default_rng(4))


def test_a_compliance_design_is_for_no_payload_by_default(robot, measured_and_candidates):
    measured, candidates = measured_and_candidates
    default = plan_poses(robot, measured, ["compliance"], 3, candidates=candidates)
    unloaded = plan_poses(robot, measured, ["compliance"], 3, candidates=candidates, payload_kg=0.0)
    loaded = plan_poses(robot, measured, ["compliance"], 3, candidates=candidates, payload_kg=1.0)
    np.testing.assert_array_equal(default.gain_per_pose, unloaded.gain_per_pose)
    np.testing.assert_array_equal(default.q, unloaded.q)
    assert default.log_det_gain == unloaded.log_det_gain
    assert not np.allclose(loaded.gain_per_pose, unloaded.gain_per_pose, rtol=1e-5, atol=0.0)


def _rivals(robot):
    compliance = make_effect("compliance", robot)
    truth = ([make_effect("frames", robot), compliance], [np.zeros(9), np.full(compliance.n_params, 1e-6)])
    rival = ([make_effect("frames", robot), make_effect("joint_offsets", robot)], [np.zeros(9), np.zeros(robot.n_joints)])
    return truth, rival


@pytest.mark.parametrize("which", ["plan_poses", "plan_discriminating_poses"])
def test_each_design_asks_its_candidates_for_an_unloaded_arm(which, robot, measured_and_candidates, monkeypatch):
    measured, candidates = measured_and_candidates
    asked = []
    real = design._candidates_and_context

    def recording(robot_, k, candidates_, n_candidates, payload_kg, rng):
        asked.append((k, n_candidates, payload_kg, rng))
        return real(robot_, k, candidates_, n_candidates, payload_kg, rng)

    monkeypatch.setattr(design, "_candidates_and_context", recording)
    if which == "plan_poses":
        plan_poses(robot, measured, ["compliance"], 2, candidates=candidates)
    else:
        plan_discriminating_poses(robot, measured, [_rivals(robot)], 2, candidates=candidates)
    assert asked == [(2, 3000, 0.0, None)]
