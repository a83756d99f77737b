"""The closed-form rigid fit, the per-session tracker frames, the tracker registration and the
instrument at its own origin (``frames/rigid.py``, ``sessions.py``, ``registration.py``,
``instrument.py``), against computations written out: a Kabsch fit on numpy's SVD (Arun, Huang
and Blostein 1987), the collinearity and identifiability tests at their thresholds and past them,
a homogeneous matrix by hand, hidden tracker frames read on Pinocchio, the instrument's
specification (issue 36: mutation kill rate). Each test names a planted change it was seen to catch.
"""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.exceptions import InputError
from tcr_accuracy.frames.registration import register_tracker
from tcr_accuracy.frames.rigid import homogeneous, rigid_fit
from tcr_accuracy.frames.sessions import register_sessions, to_base_frame

from test_mut_iso_budget import _kabsch  # numpy's SVD Kabsch fit, written out there


def _rotation(axis_angle):
    """Rodrigues' formula on raw numpy."""
    w = np.asarray(axis_angle, dtype=float)
    angle = np.linalg.norm(w)
    k = w / angle
    skew = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * skew + (1 - np.cos(angle)) * skew @ skew


def test_a_noisy_fit_far_from_both_origins_is_the_svd_kabsch_fit():
    """Twelve points 3 m from the base's origin, measured 5 m from the tracker's with 50 um of noise: the
    rotation and translation equal numpy's SVD Kabsch fit of the same points (to 1e-10), not the
    noise-free truth. Seen failing on ``measured - mm`` turned to ``measured + mm``, ``nominal - mn`` to
    ``nominal * mn`` in the alignment, ``mm - r @ mn`` to ``mm + r @ mn``, and the measured mean's
    ``axis=0`` to ``axis=1``."""
    rng = np.random.default_rng(40)
    nominal = rng.uniform(-0.6, 0.6, (12, 3)) + [3.0, -1.0, 0.5]
    rotation = _rotation([0.3, -0.9, 1.7])
    measured = nominal @ rotation.T + [5.0, 2.0, -1.0] + rng.normal(0.0, 50e-6, (12, 3))
    r, t = rigid_fit(nominal, measured)
    expected_r, expected_t = _kabsch(nominal, measured)
    np.testing.assert_allclose(r, expected_r, atol=1e-10)
    np.testing.assert_allclose(t, expected_t, atol=1e-10)
    assert np.abs(r - rotation).max() > 1e-7  # the noise moved the fit: the least-squares one is asked for


def test_three_points_are_enough_two_are_refused_and_shapes_must_be_n_by_3():
    """Three points off a line give the frame exactly; two are refused naming the count; arrays that are not
    (N, 3), or not the same shape, are refused naming both shapes. Seen failing on ``nominal.shape[0] < 3``
    turned to ``< 4`` and to ``< 2``, the count in the words read from ``shape[-1]``, and the shape test's
    ``ndim != 2`` turned to ``!= 3``, ``shape[1] != 3`` to ``!= 4`` and to ``shape[0] != 3``."""
    nominal = np.array([[0.2, 0.0, 0.1], [0.0, 0.5, 0.0], [0.4, 0.3, 0.9]])
    rotation = _rotation([0.0, 0.0, 0.5])
    r, t = rigid_fit(nominal, nominal @ rotation.T + [1.0, 2.0, 3.0])
    np.testing.assert_allclose(r, rotation, atol=1e-12)
    np.testing.assert_allclose(t, [1.0, 2.0, 3.0], atol=1e-12)
    four = np.vstack([nominal, [[1.0, -0.5, 0.2]]])
    r, t = rigid_fit(four, four @ rotation.T)
    np.testing.assert_allclose(r, rotation, atol=1e-12)
    with pytest.raises(InputError) as refused:
        rigid_fit(nominal[:2], nominal[:2])
    assert str(refused.value) == "rigid fit: 2 points; a tracker frame needs at least 3 poses"
    for a, b in ((np.zeros((5, 2)), np.zeros((5, 2))), (np.zeros((5, 4)), np.zeros((5, 4))),
                 (np.zeros(3), np.zeros(3)), (np.zeros((2, 5, 3)), np.zeros((2, 5, 3))),
                 (np.zeros((5, 3)), np.zeros((4, 3)))):
        with pytest.raises(InputError) as refused:
            rigid_fit(a, b)
        assert str(refused.value) == (f"rigid fit: nominal and measured points must both be (N, 3), got {a.shape} "
                                      f"and {b.shape}")


def _cloud(spread0, spread1, offset=(2.0, -3.0, 1.5), n=7):
    """n points whose centred singular values are (spread0, spread1, 0): orthonormal columns times them."""
    basis = np.linalg.qr(np.random.default_rng(6).normal(size=(n, 2)) - 0.0)[0]
    basis -= basis.mean(axis=0)  # centred columns ...
    basis = np.linalg.qr(basis)[0]  # ... orthonormal again (still centred: the span of centred vectors)
    directions = _rotation([0.4, 0.2, -0.7])[:, :2]
    return basis @ np.diag([spread0, spread1]) @ directions.T + offset


def test_points_on_a_line_far_from_the_origin_are_refused_and_the_threshold_is_a_millionth():
    """The collinearity test on the centred points' singular values: points on a line 4 m from the origin
    are refused; a cloud whose second singular value is 2e-6 of the first is fitted, 0.5e-6 refused (at
    0.1 m and at 10 m, so the test is relative to the cloud's size, not to 1 m); points in a plane are
    fitted (the third singular value is not looked at). Seen failing on ``nominal - mn`` turned to
    ``nominal % mn`` and ``nominal + mn`` (a line off the origin spans two directions about it), ``1e-6``
    turned to ``1.000001`` and ``-0.999999``, ``max(spread[0], 1e-300)`` to ``max(spread[0], 1.0)`` and to ``-1.0`` (a cloud under 1e-300 m),
    ``spread[1]`` to ``spread[2]`` and to ``spread[0]``, and ``max(spread[1], ...)`` for spread[0]."""
    t = np.linspace(0.0, 4.0, 5)[:, None]
    line = np.array([0.5, 0.7, 2.0]) + t * [1.0, 1.0, 0.0]
    with pytest.raises(InputError, match="lie on one line"):
        rigid_fit(line, line + 1.0)
    # a cloud under 1e-300 m: its second singular value (5e-307) is compared with 1e-6 x the floor 1e-300, not
    # with 1e-6 x its first (1e-301)
    tiny = np.array([[0.0, 0.0, 0.0], [1e-301, 0.0, 0.0], [0.0, 5e-307, 0.0], [1e-301, 5e-307, 0.0]])
    with pytest.raises(InputError, match="lie on one line"):
        rigid_fit(tiny, tiny)
    for size in (0.1, 10.0):
        for ratio, refused in ((2e-6, False), (0.5e-6, True)):
            cloud = _cloud(size, ratio * size)
            singular = np.linalg.svd(cloud - cloud.mean(axis=0), compute_uv=False)
            assert singular[1] / singular[0] == pytest.approx(ratio, rel=1e-6)
            if refused:
                with pytest.raises(InputError, match="lie on one line"):
                    rigid_fit(cloud, cloud)
            else:
                r, _ = rigid_fit(cloud, cloud + [0.0, 0.0, 1.0])  # fitted (ill-conditioned about the line)
                np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)


def test_the_homogeneous_matrix_holds_rotation_and_translation_and_a_last_row_0_0_0_1():
    """(4, 4): the rotation top left, the translation in the last column, (0, 0, 0, 1) below; it maps a point
    as R p + t. Seen failing on ``np.eye(4)`` turned to ``np.eye(5)`` and ``np.eye(3)``, ``out[:3, :3]`` to
    ``out[:2, :3]`` and ``out[:3, 3]`` to ``out[:3, 2]``."""
    rotation = _rotation([0.1, 0.2, 0.3])
    translation = np.array([0.4, -0.5, 0.6])
    expected = np.zeros((4, 4))
    expected[:3, :3], expected[:3, 3], expected[3, 3] = rotation, translation, 1.0
    got = homogeneous(rotation, translation)
    assert got.shape == (4, 4)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_allclose((got @ [1.0, 2.0, 3.0, 1.0])[:3], rotation @ [1.0, 2.0, 3.0] + translation)


def test_each_session_gets_its_own_hidden_tracker_frame_and_points_map_back_to_the_base():
    """Two sessions (rows alternating), each measured from its own hidden tracker frame with 20 um of noise,
    two reflectors and one base reference (fixed at a known place in the base frame, its measured place
    the session's mean): each session's frame is numpy's SVD Kabsch fit of that session's rows of both
    reflectors plus the reference's one point; to_base_frame maps each row back by its own session's
    frame, R^T (p - t). A session of two rows is refused naming it. Seen failing on the session loop's
    ``max(len(labels), 1)`` turned to ``max(..., 2)`` on one session, the reference's mean over
    ``axis=0`` turned to ``axis=1``, ``rows.size < 3`` turned to ``< 4`` and to ``< 2``, and the map's
    ``points[rows] - translation`` turned to ``+``."""
    rng = np.random.default_rng(12)
    n = 10
    session_of = np.arange(n) % 2
    a = rng.uniform(-0.8, 0.8, (n, 3)) + [0.5, 0.0, 0.6]
    b = a + rng.normal(0.0, 0.05, (n, 3))
    place = np.array([0.3, -0.2, 0.0])
    frames = [(_rotation([0.1, -0.2, 0.9]), np.array([3.0, 1.0, -0.5])),
              (_rotation([-0.3, 0.1, 2.2]), np.array([-2.0, 4.0, 0.2]))]
    measured = [np.empty((n, 3)), np.empty((n, 3))]
    seen = np.empty((n, 3))
    for s, (r, t) in enumerate(frames):
        rows = session_of == s
        for k, p in enumerate((a, b)):
            measured[k][rows] = p[rows] @ r.T + t + rng.normal(0.0, 20e-6, (rows.sum(), 3))
        seen[rows] = place @ r.T + t + rng.normal(0.0, 20e-6, (rows.sum(), 3))
    references = [("base_ref", place, seen, None)]
    stations = register_sessions([a, b], measured, session_of, ["S1", "S2"], references)
    assert len(stations) == 2
    for s, (r, t) in enumerate(stations):
        rows = session_of == s
        nominal = np.vstack([a[rows], b[rows], place[None]])
        observed = np.vstack([measured[0][rows], measured[1][rows], seen[rows].mean(axis=0)[None]])
        expected_r, expected_t = _kabsch(nominal, observed)
        np.testing.assert_allclose(r, expected_r, atol=1e-10)
        np.testing.assert_allclose(t, expected_t, atol=1e-10)
        np.testing.assert_allclose(r, frames[s][0], atol=2e-4)
    back = to_base_frame(measured[0], session_of, stations)
    expected = np.empty((n, 3))
    for s, (r, t) in enumerate(stations):
        rows = session_of == s
        expected[rows] = (measured[0][rows] - t) @ r
    np.testing.assert_allclose(back, expected, atol=1e-12)
    np.testing.assert_allclose(back, a, atol=2e-4)

    one = register_sessions([a, b], [a @ frames[0][0].T + frames[0][1], b @ frames[0][0].T + frames[0][1]],
                            np.zeros(n, dtype=int), [])
    assert len(one) == 1
    np.testing.assert_allclose(one[0][0], frames[0][0], atol=1e-10)
    three = np.array([0, 0, 0, 1, 1, 1, 1, 1, 1, 1])
    register_sessions([a, b], measured, three, ["S1", "S2"])  # three rows are enough
    with pytest.raises(InputError) as refused:
        register_sessions([a, b], measured, np.array([0, 0, 1, 1, 1, 1, 1, 1, 1, 1]), ["S1", "S2"])
    assert str(refused.value) == "session S1: 2 measurements, a session's tracker frame needs at least 3"


def _pinocchio_tcp(robot, q, offset):
    """The UR5's TCP plus an offset in the TCP frame, by Pinocchio's forward kinematics here."""
    import pinocchio as pin

    data = robot.model.createData()
    out = []
    for row in q:
        pin.framesForwardKinematics(robot.model, data, row)
        placement = data.oMf[robot.tool_frame_id]
        out.append(placement.translation + placement.rotation @ offset)
    return np.array(out)


@pytest.fixture(scope="module")
def hidden_tracker():
    """A UR5 read at 30 poses by a tracker 2.4 m away, turned 0.7 rad about a skew axis, the reflector
    (5, -8, 25) mm off tool0 in its frame: noise-free readings made here on Pinocchio."""
    from tcr_accuracy.model.robot import load_robot

    robot = load_robot("ur5")
    rng = np.random.default_rng(77)
    q = rng.uniform(-2.5, 2.5, (30, 6))
    offset = np.array([5.0, -8.0, 25.0]) * 1e-3
    rotation = _rotation(np.array([0.2, 0.5, -0.4]) / np.linalg.norm([0.2, 0.5, -0.4]) * 0.7)
    translation = np.array([2.0, -1.2, 0.5])
    measured = _pinocchio_tcp(robot, q, offset) @ rotation.T + translation
    return robot, q, offset, rotation, translation, measured


def test_a_noise_free_registration_finds_the_hidden_frame_and_offset_to_a_micrometre(hidden_tracker):
    """From noise-free readings the refinement lands on the hidden frame and offset (1e-9 m, 1e-9 rad),
    the residual RMS is nil, and every view of the fit is the hidden frame's: trackerMbase (and its
    older name ``matrix``) the homogeneous matrix, vectors turned by R^T, points mapped both ways, the
    rotation vector in degrees (scipy's, here numpy's Rodrigues inverse), the tool parameters with the
    base twist zeroed, the measured-frame robot's TCP at the reflector. Seen failing on the folded
    twist's ``r0 @ twist.rotation`` turned to ``twist.rotation`` alone, ``rotation_vector_deg``'s
    degrees, ``out[:3, 3] = ... translation`` moved, ``vectors_to_base`` and the measured-frame robot's
    ``tool_slice.start + 3`` turned to ``+ 2``."""
    robot, q, offset, rotation, translation, measured = hidden_tracker
    fit = register_tracker(robot, q, measured)
    np.testing.assert_allclose(fit.rotation, rotation, atol=1e-9)
    np.testing.assert_allclose(fit.translation, translation, atol=1e-9)
    np.testing.assert_allclose(fit.tool_offset, offset, atol=1e-9)
    assert fit.residual_rms < 1e-9 and fit.n_points == 30
    expected = np.eye(4)
    expected[:3, :3], expected[:3, 3] = rotation, translation
    np.testing.assert_allclose(fit.trackerMbase, expected, atol=1e-9)
    np.testing.assert_allclose(fit.matrix, expected, atol=1e-9)
    vectors = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, -1.0]])
    np.testing.assert_allclose(fit.vectors_to_base(vectors), vectors @ rotation, atol=1e-9)
    points = np.array([[0.3, -0.2, 0.8]])
    np.testing.assert_allclose(fit.to_tracker(points), points @ rotation.T + translation, atol=1e-9)
    np.testing.assert_allclose(fit.to_base(measured), _pinocchio_tcp(robot, q, offset), atol=1e-9)
    angle = np.arccos((np.trace(rotation) - 1.0) / 2.0)
    axis = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0],
                     rotation[1, 0] - rotation[0, 1]]) / (2.0 * np.sin(angle))
    doc = fit.to_dict()
    np.testing.assert_allclose(doc["rotation_vector_deg"], np.degrees(angle * axis), atol=1e-7)
    assert doc["rotation_angle_deg"] == pytest.approx(np.degrees(0.7), abs=1e-7)
    np.testing.assert_allclose(doc["rotation_matrix"], rotation, atol=1e-9)
    tool = fit.tool_parameters()
    names = list(fit.parameter_names)
    assert all(tool[i] == 0.0 for i, n in enumerate(names) if n.startswith("frames.base."))
    np.testing.assert_allclose([tool[names.index(f"frames.tool.{c}")] for c in ("dx", "dy", "dz")], offset,
                               atol=1e-9)
    from tcr_accuracy.model.kinematics import tcp_poses

    moved = fit.measured_frame_robot(robot)
    np.testing.assert_allclose(tcp_poses(moved, q).position, _pinocchio_tcp(robot, q, offset), atol=1e-9)
    np.testing.assert_allclose(fit.tcp_positions(robot, q), _pinocchio_tcp(robot, q, offset), atol=1e-9)


def test_without_the_frame_or_without_the_offset_only_the_other_is_fitted(hidden_tracker):
    """``fit_base=False``: the readings are taken as base-frame points (rotation I, translation 0) and only
    the three offsets are fitted: on base-frame readings, the offset exactly; ``fit_tool=False``: the
    offset held at zero, the frame fitted to the tool0 points, its residual RMS the RMS of the distances
    between the readings and the frame's tool0 (written out here). Seen failing on the wanted columns'
    ``fit_base and`` test and the RMS's ``** 2`` turned to ``** 3``."""
    robot, q, offset, rotation, translation, measured = hidden_tracker
    in_base = _pinocchio_tcp(robot, q, offset)
    fit = register_tracker(robot, q, in_base, fit_base=False)
    assert fit.fitted == ("frames.tool.dx", "frames.tool.dy", "frames.tool.dz")
    np.testing.assert_array_equal(fit.closed_form_rotation, np.eye(3))
    np.testing.assert_array_equal(fit.closed_form_translation, np.zeros(3))
    np.testing.assert_allclose(fit.rotation, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(fit.tool_offset, offset, atol=1e-9)
    fit = register_tracker(robot, q, measured, fit_tool=False)
    assert fit.fitted == tuple(f"frames.base.{c}" for c in ("dx", "dy", "dz", "rx", "ry", "rz"))
    np.testing.assert_array_equal(fit.tool_offset, np.zeros(3))
    tool0 = _pinocchio_tcp(robot, q, np.zeros(3))
    d = measured - (tool0 @ fit.rotation.T + fit.translation)
    assert fit.residual_rms == pytest.approx(np.sqrt(np.mean(np.sum(d ** 2, axis=1))), rel=1e-9)
    assert fit.residual_rms > 5e-3  # the 27 mm offset left unfitted


def test_a_column_within_a_millionth_of_the_earlier_ones_is_not_identifiable():
    """_identifiable keeps a column when the part of it the earlier ones do not span exceeds 1e-6 of its own
    norm (numpy's least-squares residual of it on the earlier columns, here): a column 2e-6 off the span
    kept, 0.5e-6 off dropped, a zero column dropped; no columns, none. Seen failing on
    ``IDENTIFIABILITY_TOL = 1e-6`` turned to ``1.000001`` and to ``-0.999999``, ``norms[k] > 0`` to
    ``> 1`` and the empty block's ``columns.shape[1] == 0`` to ``== 1``."""
    from tcr_accuracy.frames.registration import IDENTIFIABILITY_TOL, _identifiable

    assert IDENTIFIABILITY_TOL == 1e-6
    rng = np.random.default_rng(8)
    a, b, c, d = rng.normal(size=(4, 20)) * 0.3  # columns of norm ~1.3, under 1 after the scale below
    c = c - np.linalg.lstsq(np.column_stack([a, b]), c, rcond=None)[0] @ np.vstack([a, b])
    c /= np.linalg.norm(c)
    columns = np.column_stack([a, b, a + b + 2e-6 * np.linalg.norm(a + b) * c, a - b + 0.5e-6 * np.linalg.norm(a - b) * c,
                               np.zeros(20), 0.5 * d])
    kept = _identifiable(columns)
    for k in range(columns.shape[1]):
        earlier = columns[:, [i for i in range(k)]]
        rest = columns[:, k] - (earlier @ np.linalg.lstsq(earlier, columns[:, k], rcond=None)[0] if k else 0.0)
        norm = np.linalg.norm(columns[:, k])
        assert (k in kept) == bool(norm > 0 and np.linalg.norm(rest) > 1e-6 * norm)
    assert kept == [0, 1, 2, 5]
    assert _identifiable(columns[:, :1]) == [0]  # one column of its own
    assert _identifiable(np.zeros((20, 0))) == []


def test_registration_refuses_mismatched_or_non_finite_readings_in_one_line(hidden_tracker):
    """Joint values and positions of different lengths, positions not (N, 3), joints not (N, 6): one line
    naming both shapes; a NaN: one line. Seen failing on ``measured.shape[1] != 3`` turned to ``!= 4`` and
    ``q.shape[0] != measured.shape[0]`` read from ``q.shape[1]``."""
    robot, q, _, _, _, measured = hidden_tracker
    for joints, points in ((q, measured[:29]), (q, measured[:, :2]), (q[:, :5], measured)):
        with pytest.raises(InputError) as refused:
            register_tracker(robot, joints, points)
        assert str(refused.value) == (f"registration: needs joint values (N, 6) and positions (N, 3), got "
                                      f"{joints.shape} and {points.shape}")
    bad = measured.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError, match="^registration: joint values and positions must be finite$"):
        register_tracker(robot, q, bad)


def test_above_20000_poses_the_frame_is_fitted_on_a_reproducible_subset_and_judged_on_all(hidden_tracker):
    """20 001 noise-free readings of the hidden frame, the one row the subset leaves out (numpy's
    default_rng(0) choice of 20 000 rows, as the module states it draws them) read 1 m off: the frame and
    offset are the hidden ones to 1e-8 (the far reading never entered the fit; had it, it would pull the
    frame by ~50 um), while the residual RMS is over all 20 001 rows (that one reading's 1 m / sqrt(20 001)).
    Seen failing on ``REGISTRATION_MAX_POSES = 20_000`` turned to ``20001`` and ``19999`` and the subset's
    ``default_rng(0)`` turned to ``default_rng(1)``."""
    from tcr_accuracy.frames.registration import REGISTRATION_MAX_POSES

    robot, q, offset, rotation, translation, _ = hidden_tracker
    assert REGISTRATION_MAX_POSES == 20_000
    rng = np.random.default_rng(5)
    many = rng.uniform(-2.5, 2.5, (20_001, 6))
    from tcr_accuracy.model.kinematics import tcp_poses

    poses = tcp_poses(robot, many)
    measured = (poses.position + np.einsum("nij,j->ni", poses.rotation, offset)) @ rotation.T + translation
    kept = np.random.default_rng(0).choice(20_001, 20_000, replace=False)
    left_out = int(np.setdiff1d(np.arange(20_001), kept)[0])
    measured[left_out] += [1.0, 0.0, 0.0]
    fit = register_tracker(robot, many, measured)
    np.testing.assert_allclose(fit.rotation, rotation, atol=1e-8)
    np.testing.assert_allclose(fit.translation, translation, atol=1e-8)
    np.testing.assert_allclose(fit.tool_offset, offset, atol=1e-8)
    assert fit.n_points == 20_001
    assert fit.residual_rms == pytest.approx(1.0 / np.sqrt(20_001), rel=1e-6)


def test_a_point_at_the_instruments_own_origin_has_no_line_of_sight_and_stays_finite():
    """A reading at the tracker's origin (distance 0) and one 0.5 m away along y: at the origin the covariance
    is (a_t / 2)^2 I (no line of sight: only the transverse MPE at distance 0) and the whitening
    floor / (a_t / 2) I, both finite; the other point's as the specification gives (along y: (a_r + b_r 0.5) / 2,
    across: (a_t + b_t 0.5) / 2). Seen failing on both ``np.maximum(distance, 1e-9)`` turned to
    ``np.maximum(distance, -0.999999999)`` (0 / 0) and to ``1.000000001`` (a point under 1 m given a line
    of sight shorter than 1)."""
    from tcr_accuracy.frames.instrument import Instrument

    um = 1e-6
    tracker = Instrument("t", (10 * um, 0.3 * um), (15 * um, 6 * um))
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.5, 0.0]])
    s_t0 = 15 * um / 2
    s_r, s_t = (10 * um + 0.15 * um) / 2, (15 * um + 3 * um) / 2
    cov = tracker.covariances(points)
    np.testing.assert_allclose(cov[0], s_t0 ** 2 * np.eye(3), rtol=1e-12, atol=0)
    np.testing.assert_allclose(cov[1], np.diag([s_t ** 2, s_r ** 2, s_t ** 2]), rtol=1e-12, atol=0)
    floor = np.sqrt(np.mean([3 * s_t0 ** 2, s_r ** 2 + 2 * s_t ** 2]) / 3.0)
    w = tracker.whitening(points, np.eye(3))
    np.testing.assert_allclose(w[0], floor / s_t0 * np.eye(3), rtol=1e-12)
    np.testing.assert_allclose(w[1], floor * np.diag([1 / s_t, 1 / s_r, 1 / s_t]), rtol=1e-12)
