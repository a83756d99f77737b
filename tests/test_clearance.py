"""Joint clearance (seed Eq. 27-43, Table 4) as SE3 perturbations of the placements."""

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.model.clearance import ClearanceModel, radial_offset_added
from tcr_accuracy.model.kinematics import tcp_poses, tcp_poses_pinocchio
from tcr_accuracy.analysis.montecarlo import run_monte_carlo


def test_tool_changer_clearance_joints_and_planes(tool_changer):
    model = ClearanceModel.from_robot(tool_changer)
    assert [tool_changer.joint_names[j] for j in model.joints] == ["j1", "j2", "j3", "j5", "j6"]
    a, u, v = model.frames()
    # j1, j6 turn about z: radial plane x-y (horizontal); j2, j3, j5 about x: plane y-z (vertical)
    np.testing.assert_array_equal(a, [[0, 0, 1], [1, 0, 0], [1, 0, 0], [1, 0, 0], [0, 0, 1]])
    np.testing.assert_array_equal(u, [[1, 0, 0], [0, 1, 0], [0, 1, 0], [0, 1, 0], [1, 0, 0]])
    np.testing.assert_array_equal(v, [[0, 1, 0], [0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 1, 0]])


def test_one_sample_equals_a_hand_built_se3_product(tool_changer):
    """x from the model, against Trans(d a + s(cos u + sin v)) * Rot(w_x u + w_y v) built with pin.exp6."""
    model = ClearanceModel.from_robot(tool_changer)
    c = model.sample_components(1, np.random.default_rng(7))
    x = model.to_parameters(c)[0]
    em = model.error_model
    hand_axes = {"j1": ((0, 0, 1), (1, 0, 0), (0, 1, 0)), "j2": ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
                 "j3": ((1, 0, 0), (0, 1, 0), (0, 0, 1)), "j5": ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
                 "j6": ((0, 0, 1), (1, 0, 0), (0, 1, 0))}
    placements = []
    k = 0
    for j, name in enumerate(tool_changer.joint_names):
        nominal = tool_changer.joint_placements[j]
        if name not in hand_axes:
            placements.append(nominal)
            np.testing.assert_array_equal(x[em.index(f"{name}.dx"):em.index(f"{name}.dx") + 6], 0.0)
            continue
        a, u, v = (np.array(e, dtype=float) for e in hand_axes[name])
        d, s, th = c.axial[0, k], c.radial[0, k], c.angle[0, k]
        wx, wy = c.deflection_u[0, k], c.deflection_v[0, k]
        shift = pin.exp6(np.concatenate([d * a + s * np.cos(th) * u + s * np.sin(th) * v, np.zeros(3)]))
        tilt = pin.exp6(np.concatenate([np.zeros(3), wx * u + wy * v]))
        expected = shift * tilt
        twist = x[em.index(f"{name}.dx"):em.index(f"{name}.dx") + 6]
        got = pin.exp6(twist)
        np.testing.assert_allclose(got.homogeneous, expected.homogeneous, atol=1e-14)
        placements.append(nominal * expected)
        k += 1
    # TCP of a hand-built Pinocchio model with those placements
    pmodel = pin.Model(tool_changer.model)
    for j, placement in enumerate(placements):
        pmodel.jointPlacements[j + 1] = placement
    data = pmodel.createData()
    pin.framesForwardKinematics(pmodel, data, tool_changer.to_pinocchio_q(tool_changer.working_pose))
    engine = tcp_poses(tool_changer, tool_changer.working_pose, x, em)
    np.testing.assert_allclose(engine.position[0], data.oMf[tool_changer.tool_frame_id].translation, atol=1e-12)


def test_parameter_covariance_matches_sampled_parameters(tool_changer):
    model = ClearanceModel.from_robot(tool_changer, deflection_std=0.002)
    x = model.sample(200_000, np.random.default_rng(1))
    cov = model.parameter_covariance()
    active = np.diag(cov) > 0
    # uniform theta: s cos(theta) has variance radial_std^2 / 2 (0.125 mm^2 here)
    np.testing.assert_allclose(x[:, active].var(axis=0), np.diag(cov)[active], rtol=0.02)
    assert cov[model.error_model.index("j2.dy"), model.error_model.index("j2.dy")] == pytest.approx(0.5 * 0.5e-3**2)


def test_adding_the_radial_vector_afterwards_agrees_only_without_deflection(tool_changer):
    """Eq. 43 (add radial vectors in the base frame) vs the SE3 placements."""
    q = tool_changer.working_pose
    for deflection, expect_equal in ((0.0, True), (0.01, False)):
        model = ClearanceModel.from_robot(tool_changer, deflection_std=deflection)
        c = model.sample_components(2000, np.random.default_rng(3))
        full = tcp_poses(tool_changer, q, model.to_parameters(c), model.error_model).position
        no_radial = tcp_poses(tool_changer, q, model.to_parameters(c, include_radial=False),
                              model.error_model).position
        added = no_radial + radial_offset_added(model, q, c)
        gap = np.abs(full - added).max()
        if expect_equal:
            assert gap < 1e-12
        else:
            # second order, |w| s: 5 joints x (3 sigma of 0.01 rad) x (3 sigma of 0.5 mm) bounds it
            assert 1e-7 < gap < 5 * 0.03 * 1.5e-3


def test_clearance_preset_runs_through_the_engine_like_the_loop(tool_changer):
    model = ClearanceModel.from_robot(tool_changer)
    x = model.sample(50, np.random.default_rng(5))
    q = tool_changer.working_pose
    np.testing.assert_allclose(tcp_poses(tool_changer, q, x, model.error_model).position,
                               tcp_poses_pinocchio(tool_changer, q, x, model.error_model).position, atol=1e-12)
    result = run_monte_carlo(model, q, 4000, 0)
    # Table 4's 0.087 rad deflections at ~1.7 m reach give errors of order 0.1 m, not the seed's 0.5 mm
    assert 0.05 < result.stats.std[0] < 0.5


def test_bad_spreads_are_rejected(tool_changer):
    from tcr_accuracy.exceptions import InputError

    with pytest.raises(InputError, match="radial_std"):
        ClearanceModel.from_robot(tool_changer, radial_std=-1.0)
