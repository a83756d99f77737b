"""The ISO 9283 cube search (``iso9283/plan.py``) against its definition written out here: each
candidate centre's edge grown by bisection between the best cube so far and the smallest of the
room above the floor and the cube whose half space diagonal is the farthest candidate's reach
(``2 far / sqrt 3``, far = the farthest TCP + 1 mm), a later centre tried only where a cube 1 %
larger than the best is served, and the candidates the best-conditioned configurations spread
over the workspace. The robot's reach is replaced by a stand-in that serves a cube up to an edge
chosen per centre, so the bisection's result is the closed form ``lo + (hi - lo) floor((S - lo) /
(hi - lo) 2^b) / 2^b``. Each test names a planted change it was seen to catch.
"""

import math

import numpy as np
import pytest

import tcr_accuracy.iso9283.plan as plan_module
from tcr_accuracy import load_robot
from tcr_accuracy.iso9283.reach import Reach, Workspace
from tcr_accuracy.model.jacobians import tcp_jacobian
from tcr_accuracy.model.kinematics import tcp_poses

#: Two UR5 configurations whose TCPs are the candidate centres.
Q = np.array([[0.3, -1.2, 1.5, -1.9, -1.57, 0.0], [-0.8, -1.0, 1.2, -1.7, -1.57, 0.4]])


def _bisected(lo, hi, serves, b):
    """The edge b bisection steps reach on [lo, hi] when every edge up to ``serves`` is served."""
    return lo + (hi - lo) * math.floor((serves - lo) / (hi - lo) * 2 ** b) / 2 ** b


@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5")


def _search(monkeypatch, ur5, serves, **kwargs):
    """plan_iso_cube over the candidates Q with a reach that serves a cube about the candidate nearest
    its P1 up to the edge ``serves[k]``; the arguments the candidates were drawn with, recorded."""
    centres = tcp_poses(ur5, Q).position
    asked = {"sighted": set()}

    class Oracle(Reach):
        def solve(self, targets, rotation, q_start, sighted=0):
            targets = np.atleast_2d(targets)
            asked["sighted"].add((len(targets), sighted))
            if len(targets) > 1:
                k = int(np.argmin(np.linalg.norm(centres - targets[0], axis=1)))
                edge = float(np.ptp(targets[5:, 0]))
                if edge > serves[k]:
                    return None
            return np.tile(np.asarray(q_start, dtype=float), (len(targets), 1))

    def candidates(reach, rng, n_samples, n_centres):
        asked.update(n_samples=n_samples, n_centres=n_centres, mode=reach.mode, next_draws=rng.random(3))
        return Q.copy()

    monkeypatch.setattr(plan_module, "Reach", Oracle)
    monkeypatch.setattr(plan_module, "_candidate_configurations", candidates)
    return plan_module.plan_iso_cube(ur5, 0, home=Q[0], **kwargs), centres, asked


def test_the_search_bisects_between_the_best_cube_and_the_farthest_reach_ten_times(monkeypatch, ur5):
    """Above a floor 2 m down (the room never binds), the upper end of every bisection is 2 far / sqrt 3
    with far the farthest candidate TCP from the base + 1 mm; the first centre serves up to 0.8 of it,
    the second up to 1.15 times what the first found: the second is tried (1.01 times the best is
    served) and grown by ten steps (the default) from the first's edge. The candidates were drawn
    from 1000 configurations, 60 centres, by the generator after the orientation mode's 20 draws (the
    UR5's frame Jacobian has rank 6: exact); every cube asked of the reach holds its five poses (not its
    eight corners) to the tracker's sight, and a centre alone itself. Catches ``2.0 * far / np.sqrt(3.0)`` with any number changed,
    ``+ 1e-3`` changed, ``0.5 * (low + high)`` as ``1.5 *``, the defaults ``bisections=10``,
    ``n_samples=1000`` and ``n_centres=60`` changed, the mode's 20 configurations changed, and any ``sighted=5`` (P1..P5 held to the
    tracker's line of sight, not the corners) or ``sighted=1`` changed."""
    centres = tcp_poses(ur5, Q).position
    far = float(np.max(np.linalg.norm(centres, axis=1))) + 1e-3
    hi = 2 * far / math.sqrt(3)
    first = _bisected(0.0, hi, 0.8 * hi, 10)
    serves = [0.8 * hi, 1.15 * first]
    plan, got_centres, asked = _search(monkeypatch, ur5, serves, workspace=Workspace(floor=-2.0))
    second = _bisected(first, hi, serves[1], 10)
    after_mode = np.random.default_rng(0)
    after_mode.uniform(*ur5.joint_bounds(math.pi), (20, 6))  # the orientation mode's 20 configurations
    np.testing.assert_array_equal(asked.pop("next_draws"), after_mode.random(3))
    assert asked == {"n_samples": 1000, "n_centres": 60, "mode": "exact", "sighted": {(13, 5), (1, 1)}}
    assert plan.searched and plan.n_centres == 2
    assert plan.size == pytest.approx(second, rel=1e-12)
    np.testing.assert_allclose(plan.centre, got_centres[1], atol=1e-15)


def test_a_later_centre_is_tried_only_where_a_cube_one_percent_larger_is_served(monkeypatch, ur5):
    """The second centre serves 0.5 % more than the first found (less than 1.01 times): it is not grown,
    the first centre's cube is kept; twelve steps. Catches the skip test's ``low * 1.01`` as ``0.01``
    or ``2.01`` (with 12 steps, growing from the best finds a cube 0.5 % larger)."""
    centres = tcp_poses(ur5, Q).position
    hi = 2 * (float(np.max(np.linalg.norm(centres, axis=1))) + 1e-3) / math.sqrt(3)
    first = _bisected(0.0, hi, 0.7 * hi, 12)
    assert _bisected(first, hi, 1.005 * first, 12) > first  # what growing the second would find
    plan, got_centres, _ = _search(monkeypatch, ur5, [0.7 * hi, 1.005 * first], workspace=Workspace(floor=-2.0),
                                   bisections=12)
    assert plan.size == pytest.approx(first, rel=1e-12)
    np.testing.assert_allclose(plan.centre, got_centres[0], atol=1e-15)


def test_the_room_above_the_floor_bounds_the_bisection(monkeypatch, ur5):
    """Above the mounting plane the first centre's room (twice its height) is below 2 far / sqrt 3 and
    every cube is served: the edge is the room less 2^-6 of it after six steps; the second centre
    serves nothing larger. Catches ``min(2.0 * far / ..., workspace.room(p_c))`` reading the room
    wrong and ``best[0] < MIN_CUBE_SIZE`` with its bound changed."""
    centres = tcp_poses(ur5, Q).position
    room = 2 * centres[0, 2]
    assert room < 2 * (float(np.max(np.linalg.norm(centres, axis=1))) + 1e-3) / math.sqrt(3)
    plan, got_centres, _ = _search(monkeypatch, ur5, [10.0, 0.0], bisections=6)
    assert plan.size == pytest.approx(room * (1 - 2 ** -6), rel=1e-12)
    np.testing.assert_allclose(plan.centre, got_centres[0], atol=1e-15)


def test_candidates_are_the_best_conditioned_configurations_spread_over_the_workspace(ur5):
    """``_candidate_configurations`` written out: 300 configurations drawn uniformly within half a turn
    of home (the same generator), those with the TCP above the floor and no joint origin below it
    kept; scored by the smallest singular value of the TCP frame Jacobian (rank 6: the sixth); the
    best 4 x 5 = 20; of them the best first, then each the farthest (TCP) from those chosen.
    Catches ``n_centres * 4`` changed, ``_generic_rank(spectra) - 1`` as ``- 2`` or ``+ 1``, the
    spectra cut ``[:6]`` changed, ``np.argsort(-score)`` as ``+score`` and the farthest-point
    ``np.argmax(gap)`` fed the wrong axis."""
    home = np.array([0.0, -math.pi / 2, 0.0, -math.pi / 2, 0.0, 0.0])
    reach = Reach(ur5, None, Workspace(floor=0.05), home, "exact")
    got = plan_module._candidate_configurations(reach, np.random.default_rng(7), 300, 5)
    lo, hi = ur5.joint_bounds(math.pi)
    lo, hi = np.maximum(lo, home - math.pi), np.minimum(hi, home + math.pi)
    q = np.random.default_rng(7).uniform(lo, hi, (300, 6))
    q = q[tcp_poses(ur5, q).position[:, 2] >= 0.05]
    q = q[[not reach.below(row) for row in q]]
    data = ur5.model.createData()
    score = np.array([np.linalg.svd(tcp_jacobian(ur5, row, data)[1], compute_uv=False)[5] for row in q])
    top = q[np.argsort(-score)[:20]]
    positions = tcp_poses(ur5, top).position
    chosen = [0]
    while len(chosen) < 5:
        gap = [min(np.linalg.norm(p - positions[c]) for c in chosen) for p in positions]
        chosen.append(int(np.argmax(gap)))
    np.testing.assert_array_equal(got, top[chosen])


def test_a_given_cube_holds_its_five_poses_to_the_line_of_sight_and_keeps_its_size(monkeypatch, ur5):
    """A cube given by its centre (the first candidate's TCP) and a 150 mm edge, every cube served: it
    is planned as given (not searched, one centre), and every cube asked of the reach holds its five
    poses, not its corners, to the tracker's sight (the centre alone, itself). Catches ``sighted=5``
    in the given cube's solve or the nearer-home solve, and ``sighted=1``, changed."""
    centres = tcp_poses(ur5, Q).position
    plan, _, asked = _search(monkeypatch, ur5, [10.0, 10.0], centre=centres[0], size=0.15)
    assert not plan.searched and plan.n_centres == 1 and plan.size == 0.15
    np.testing.assert_allclose(plan.centre, centres[0], atol=1e-15)
    assert asked == {"sighted": {(13, 5), (1, 1)}}  # the candidates were not drawn
