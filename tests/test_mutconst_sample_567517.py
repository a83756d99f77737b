"""Three survivors of a measuring sample (seed 567517), each against a computation written here.

* ISO 9283's words for a fitted measurement frame name the TCP-offset axes the poses could fix
  ("along dx, dz"), not the separator of their parameter names (seen failing on
  ``n.rpartition(".")[2]`` turned to ``[1]``).
* A joint of wide travel (+-13 rad, a URDF arm of :mod:`small_arms`) is turned by whole turns to the value
  nearest home among those its limits allow, by brute force over -2..2 turns: from -2 - 2 pi with
  home 2, one turn up reaches -2 (4 from home), two turns 2 pi - 2 (2.28 from home); the second
  must win (seen failing on ``np.abs(shifted - self.home[j])`` turned to ``+`` where the best
  distance so far is kept).
* The box-constrained quadratic starts with the bounds the gradient pushes against from d = 0
  held, as the active-set method's working set (Nocedal & Wright, Algorithm 16.3): where those are
  the optimum's active bounds it solves once for the free rest; the answer is scipy's
  ``lsq_linear`` on the same problem (seen failing on ``gradient < 0`` turned to ``< -1``: a gradient
  of -0.5 then leaves its bound free and costs a second solve).
"""

from types import SimpleNamespace

import numpy as np
from scipy.optimize import lsq_linear

from tcr_accuracy.diagnosis import least_squares
from tcr_accuracy.iso9283.evaluate import _fit_words
from tcr_accuracy.iso9283.reach import Reach, Workspace

from small_arms import two_joint_arm



def test_the_frame_fit_words_name_the_offset_axes_fitted():
    partial = SimpleNamespace(fitted=["frames.base.dx", "frames.tool.dx", "frames.tool.dz"], residual_rms=1.234e-5)
    words = _fit_words(partial, 5)
    assert "fitted along dx, dz (the rest is not identifiable" in words
    assert words.startswith("Kabsch on the barycentres of the 5 poses") and words.endswith("0.0123 mm")
    whole = SimpleNamespace(fitted=[f"frames.tool.{a}" for a in ("dx", "dy", "dz")], residual_rms=0.0)
    assert "with the measured point's offset from the TCP frame fitted;" in _fit_words(whole, 3)
    none = SimpleNamespace(fitted=["frames.base.rz"], residual_rms=0.0)
    assert "is not identifiable from these poses (one orientation" in _fit_words(none, 3)


def test_whole_turns_take_the_value_nearest_home_among_all_the_limits_allow():
    robot = two_joint_arm(travel=13.0)
    home = np.array([2.0, 0.0])
    reach = Reach(robot, None, Workspace(), home, "exact")
    q = np.array([[-2.0 - 2 * np.pi, 0.1], [-2.5 - 2 * np.pi, -0.1]])
    lo, hi = robot.joint_bounds(np.inf)
    shifts = [t for t in (0, -2, -1, 1, 2)
              if np.all(q[:, 0] + 2 * np.pi * t >= lo[0]) and np.all(q[:, 0] + 2 * np.pi * t <= hi[0])]
    best = min(shifts, key=lambda t: np.max(np.abs(q[:, 0] + 2 * np.pi * t - home[0])))
    assert best == 2
    expected = q.copy()
    expected[:, 0] += 2 * np.pi * best
    np.testing.assert_allclose(reach.nearest_home(q), expected, rtol=0, atol=1e-12)


def test_the_bounds_pushed_against_from_the_start_are_held_from_the_start(monkeypatch):
    rng = np.random.default_rng(5)
    a = rng.normal(size=(8, 4))
    hessian = a.T @ a + np.eye(4)
    gradient = np.array([-0.5, 0.3, 0.2, 0.4])
    low, high = np.array([-1.0, 0.0, -1.0, 0.0]), np.array([0.0, 1.0, 1.0, 1.0])
    # d_0 pushed up against its upper bound 0, d_1 and d_3 down against their lower bounds 0: held, and
    # the free d_2 solves its 1 x 1 system once; the optimum is checked first
    expected = lsq_linear(np.linalg.cholesky(hessian).T,
                          -np.linalg.solve(np.linalg.cholesky(hessian), gradient), bounds=(low, high),
                          tol=1e-14, method="bvls").x
    solves = []
    real_solve = np.linalg.solve

    def counting(matrix, rhs):
        solves.append(np.shape(matrix))
        return real_solve(matrix, rhs)

    monkeypatch.setattr(least_squares.np.linalg, "solve", counting)
    d = least_squares.box_quadratic(hessian, gradient, low, high)
    monkeypatch.undo()
    np.testing.assert_allclose(d, expected, atol=1e-10)
    assert d[0] == d[1] == d[3] == 0.0  # held where the gradient pushes them out of the box
    assert solves == [(1, 1)]
