"""The box-constrained quadratic of the fit core (``diagnosis/least_squares.py``: ``box_quadratic``) on
problems of the diagnosis' own scale (Gram blocks of columns in metres: H ~ 1e-12 and less), against its
minimiser found here by enumerating every active set (each coordinate free, on its lower or on its upper
bound) and keeping the one that satisfies the KKT conditions. The minimiser of 1/2 d^T H d + g^T d over a box
does not change when H and g are scaled together. Each test names a planted change it was seen to catch
(issue 36)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tcr_accuracy.diagnosis.least_squares import box_quadratic


def _kkt_minimiser(hessian, gradient, low, high):
    """The box's minimiser by brute force: for each active set, the free coordinates' stationary point with
    the others on their bounds; the one inside the box whose bound multipliers (H d + g) hold it there
    (>= 0 on a lower bound, <= 0 on an upper one)."""
    k = gradient.size
    scale = np.abs(gradient).max()
    for state in itertools.product((0, -1, 1), repeat=k):  # free, on low, on high
        state = np.array(state)
        d = np.where(state == -1, low, np.where(state == 1, high, 0.0))
        free = state == 0
        if free.any():
            rhs = -(gradient[free] + hessian[np.ix_(free, ~free)] @ d[~free])
            d[free] = np.linalg.solve(hessian[np.ix_(free, free)], rhs)
        if np.any(d < low - 1e-12) or np.any(d > high + 1e-12):
            continue
        multiplier = hessian @ d + gradient
        if np.all(multiplier[state == -1] >= -1e-9 * scale) and np.all(multiplier[state == 1] <= 1e-9 * scale):
            return d
    raise AssertionError("no active set satisfies the KKT conditions")


@pytest.mark.parametrize("size", [1.0, 1e-9, 1e-15])
def test_a_bound_held_at_the_start_is_let_go_at_any_scale_of_the_problem(size):
    """d_0 starts held on its lower bound 0 (its gradient pushes it down) but its coupling to d_1, which
    the gradient pushes far up, pulls it off: the minimiser has d_0 > 0. The same problem with H and g
    times 1, 1e-9 and 1e-15 (a Gram block of columns in metres): the brute-force KKT minimiser each time,
    to 1e-12 of its size. Seen failing on the multipliers' tolerance ``max(|g|, 1e-300)`` turned to
    ``max(|g|, 1.0)`` (a wrong-signed multiplier of 1e-15 taken for zero: d_0 left on its bound)."""
    hessian = np.array([[1.0, -0.9, 0.0], [-0.9, 1.0, 0.2], [0.0, 0.2, 1.0]])
    gradient = np.array([0.1, -1.0, 0.2])
    low, high = np.array([0.0, -2.0, -2.0]), np.array([3.0, 3.0, 0.5])
    expected = _kkt_minimiser(hessian, gradient, low, high)
    assert expected[0] > 1.0  # the bound it starts on is let go
    d = box_quadratic(hessian * size, gradient * size, low, high)
    np.testing.assert_allclose(d, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(d, _kkt_minimiser(hessian * size, gradient * size, low, high), rtol=0, atol=1e-12)


def _random_problems(count: int):
    """(H, g, low, high) of ``count`` random positive definite 4 x 4 problems (seed 3005), boxes around 0, a
    bound at 0 with probability 0.3 (both, now and then: a coordinate whose bounds meet)."""
    rng = np.random.default_rng(3005)
    for _ in range(count):
        a = rng.standard_normal((6, 4))
        hessian, gradient = a.T @ a + 0.1 * np.eye(4), rng.standard_normal(4) * 3.0
        low = -rng.uniform(0.0, 1.0, 4) * (rng.random(4) > 0.3)
        yield hessian, gradient, low, rng.uniform(0.0, 1.0, 4) * (rng.random(4) > 0.3)


def test_box_quadratics_of_many_sizes_and_active_sets_are_their_kkt_minimisers():
    """Random positive definite 4 x 4 problems with boxes around 0 (some touching it), each at scales 1 and
    1e-14: the brute-force KKT minimiser, to 1e-10 of its size. Seen failing on the multipliers' tolerance
    ``1e-300`` turned to ``1.0``."""
    for hessian, gradient, low, high in _random_problems(30):
        expected = _kkt_minimiser(hessian, gradient, low, high)
        for size in (1.0, 1e-14):
            d = box_quadratic(hessian * size, gradient * size, low, high)
            np.testing.assert_allclose(d, expected, rtol=0, atol=1e-10 * max(np.abs(expected).max(), 1e-3))


def test_a_coordinate_whose_bounds_meet_stays_put_and_the_others_find_their_minimiser():
    """d_0 in [0, 0] (its gradient pushes it up, its multiplier negative on a bound that is also its lower
    one) and d_3 held at its upper bound 0 by the start, though the minimiser takes it down to its lower
    bound: the brute-force KKT minimiser (d_3 = -0.0568). The active set let d_0 go each time (the largest
    'wrong' multiplier), fixed it again at once, and ran out of iterations with d_3 never released: a point
    0.026 above the minimum (found by the random problems below, seed 3005, the 24th). Seen failing on the
    fix's ``-np.inf`` turned to ``np.inf`` (the unary minus removed)."""
    hessian, gradient, low, high = list(_random_problems(24))[-1]
    assert low[0] == high[0] == 0.0 and low[3] < 0.0 == high[3]
    expected = _kkt_minimiser(hessian, gradient, low, high)
    assert expected[0] == 0.0 and expected[3] == low[3]
    d = box_quadratic(hessian, gradient, low, high)
    np.testing.assert_allclose(d, expected, rtol=0, atol=1e-12)
