"""An effect the every-step-helps check names but the leave-one-out table has no row for is listed
among the eliminations with z 0 and no increase (``stages/select.py``): the zeros say "not measured",
not a figure.

No scenario of the suite made the check name such an effect, so the check is a stand-in that names
compliance (never chosen: the robot's only hidden error is its joint offsets, written out in
:mod:`offset_truth` and measured by Pinocchio) once, then defers to the real check. Seen failing on
``row.increase if row else 0.0`` turned to ``-1.0`` and ``row.z if row else 0.0`` turned to ``1.0``
(a measuring sample's survivor: the branch ran in no test)."""

from __future__ import annotations

import numpy as np

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.stages import select
from tcr_accuracy.model.robot import load_robot

from offset_truth import measured_with_offsets

OFFSETS = np.array([2e-3, -1.5e-3, 1e-3, 0.0, 2e-3, -1e-3])


def test_a_harmful_effect_with_no_leave_one_out_row_is_listed_with_zeros(monkeypatch):
    robot = load_robot()
    _, _, measured = measured_with_offsets(robot, OFFSETS, 60, 8, 1e-5)
    real = select.harmful_effect
    named = []

    def naming_once(engine, current, loo):
        if not named:
            named.append([r.effect for r in loo])
            return "compliance"
        return real(engine, current, loo)

    monkeypatch.setattr(select, "harmful_effect", naming_once)
    result = GapDiagnosis(robot=robot, effects=["joint_offsets", "compliance"], folds=5,
                          stability_replays=2).fit(measured).result_
    assert named and "compliance" not in named[0]
    listed = [e for e in result.eliminated if e["effect"] == "compliance" and e["z"] == 0.0]
    assert listed and listed[0]["increase_mm"] == 0.0
    assert list(result.selected_effects) == ["frames", "joint_offsets"]
