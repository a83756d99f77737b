"""Two survivors of a second measuring sample (seed 472537), each against a computation written here.

* The damped solver's box path: a direction the data do not see (a zero eigenvalue of the scaled
  Gram matrix) keeps a curvature floor of 1e-10 times the largest eigenvalue, so a small gradient
  along it moves the step by -g / (1e-10 top), inside the box, not to the box's wall. Written out
  for a Gram matrix with unit diagonal, correlation 0.9 and a third column that moves nothing
  (top = 1.9). Seen failing on ``1e-10 * self.top`` turned to ``1e-10 ** self.top`` (a floor of
  1e-19: the step runs to the wall at -1).
* The relinearisation at the fitted robot takes each pose's Jacobian at its joints turned by the
  fitted joint-side errors, q + x (joints turned by 0.2 rad, written out in :mod:`offset_truth` and
  measured by Pinocchio): the joints handed to the Jacobian are the commanded ones plus about the
  hidden offsets, not minus (seen failing on ``part.q + x[:, em.drive_slice]`` turned to ``-``; the
  refit converges to the same offsets either way, so only the place of the new linearisation tells).
"""

from __future__ import annotations

import numpy as np

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.least_squares import DampedSolver
from tcr_accuracy.diagnosis.stages import select
from tcr_accuracy.model.robot import load_robot

from offset_truth import measured_with_offsets


def test_an_unseen_direction_keeps_a_curvature_floor_of_1e_10_of_the_top_eigenvalue():
    gram = np.array([[1.0, 0.9, 0.0], [0.9, 1.0, 0.0], [0.0, 0.0, 0.0]])
    solver = DampedSolver(gram)
    assert abs(solver.top - 1.9) < 1e-15
    assert list(solver.kept) == [False, True, True]  # eigenvalues 0, 0.1, 1.9 in ascending order
    gradient = np.array([10.0, -10.0, 1e-12])
    low, high = -np.ones(3), np.ones(3)
    step, _ = solver.step(gradient, 0.0, low, high)  # unbounded, the pair would move by -+100: boxed
    assert np.all(step >= low - 1e-15) and np.all(step <= high + 1e-15)
    assert abs(step[2] - (-1e-12 / (1e-10 * 1.9))) < 1e-9 * 5.3e-3  # -5.26e-3: inside the box
    # the pair: the box's corner (-1, 1) is where the gradient pushes (the quadratic's minimum lies beyond it)
    np.testing.assert_allclose(step[:2], [-1.0, 1.0], atol=1e-12)


#: hidden joint offsets [rad; m for the prismatic fourth joint]: three joints turned by 11.5 degrees
OFFSETS = np.array([0.0, 0.2, -0.2, 0.0, 0.2, 0.0])


def test_the_jacobian_is_taken_again_at_the_joints_turned_by_the_fitted_offsets(monkeypatch):
    robot = load_robot()
    q, _, measured = measured_with_offsets(robot, OFFSETS, 40, 3, 1e-5)
    handed = []
    real = select.position_jacobians

    def recording(robot_, q_fitted, *args, **kwargs):
        handed.append(np.array(q_fitted))
        return real(robot_, q_fitted, *args, **kwargs)

    monkeypatch.setattr(select, "position_jacobians", recording)
    result = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=5, stability_replays=2).fit(measured).result_
    assert any("Jacobian was taken again" in n for n in result.notes)
    (turned,) = handed  # one measured frame
    shift = turned - q
    np.testing.assert_allclose(shift, np.broadcast_to(shift[0], shift.shape), atol=1e-12)  # one offset per joint
    np.testing.assert_allclose(shift[0, 1:3], OFFSETS[1:3], atol=0.05)  # the turned shoulder and elbow: + 0.2, - 0.2
