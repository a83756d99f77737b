"""``diagnosis/stages/candidates.py``: effects of one parameter, and of none, on arms of one joint (issue 36,
third pass; the bundled robots give every effect several parameters). Each test names planted changes it was
seen to catch."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from tcr_accuracy.diagnosis.bases import Part
from tcr_accuracy.diagnosis.stages.candidates import build_bases
from tcr_accuracy.io.measurement_set import MeasurementSet

from small_arms import one_joint_arm


def _parts(robot):
    """12 poses over the joint's travel, measured where Pinocchio puts the TCP (in the base frame)."""
    q = np.linspace(-0.9, 0.9, 12)[:, None]
    data = robot.model.createData()
    position = np.empty((12, 3))
    for i, row in enumerate(q):
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(row))
        position[i] = data.oMf[robot.tool_frame_id].translation
    measured = MeasurementSet(joint_names=robot.joint_names, q=q, position=position)
    return [Part(robot, q, position, measured.context, "tool")], frozenset()


def test_an_effect_of_one_parameter_is_built_and_one_of_none_is_left_untried_saying_why():
    """On a one-joint revolute arm the joint offset, the compliance and the encoder scale have one parameter each
    and are built (one column each); on a one-joint prismatic arm the cyclic gear error has none and is left
    untried, saying its joints are all prismatic. Seen failing on ``if effect.n_params == 0`` turned to ``== 1``
    (a measuring sample's survivor, seed 4201: budget spent) and to ``== -1`` (planted by hand)."""
    parts, measured = _parts(one_joint_arm("revolute"))
    bases, rejected, _ = build_bases(parts, ["joint_offsets", "compliance", "encoder_scale"], measured, [])
    assert sorted(bases) == ["compliance", "encoder_scale", "joint_offsets"] and rejected == []
    assert [len(bases[e].names) for e in ("joint_offsets", "compliance", "encoder_scale")] == [1, 1, 1]
    parts, measured = _parts(one_joint_arm("prismatic"))
    bases, rejected, _ = build_bases(parts, ["cyclic"], measured, [])
    assert bases == {}
    assert [(c.effect, c.tried, c.why) for c in rejected] == [
        ("cyclic", False, "not testable on these data: cyclic has no parameter on one_joint_prismatic: its joints "
                          "are all prismatic, and it acts on revolute ones")]
