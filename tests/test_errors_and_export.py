"""Error model layout, seed presets, perturbed copies, and the as-built URDF export."""

import math

import numpy as np
import pytest
import yourdfpy

from tcr_accuracy.asbuilt.urdf import as_built_urdf
from tcr_accuracy.model.errors import ErrorModel, ErrorSource, seed_budget
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.model.robot import load_robot, robot_from_urdf_text

from conftest import random_joint_values, tool_changer_tcp_by_hand


def test_layout_names_and_units(tool_changer):
    em = ErrorModel(tool_changer)
    assert em.size == 6 * 6 + 6 + 6 + 6
    assert em.names[:7] == ["j1.dx", "j1.dy", "j1.dz", "j1.rx", "j1.ry", "j1.rz", "j2.dx"]
    assert em.parameters[em.index("j4.drive")].unit == "m"
    assert em.parameters[em.index("j5.drive")].unit == "rad"
    assert em.parameters[em.index("base.rz")].unit == "rad"
    with pytest.raises(InputError, match="unknown error parameter"):
        em.index("j9.dx")


def test_perturbed_robot_leaves_the_nominal_untouched(tool_changer):
    em = ErrorModel(tool_changer)
    before = [p.homogeneous.copy() for p in tool_changer.joint_placements]
    x = np.random.default_rng(0).normal(0, 1e-2, em.size)
    as_built = em.perturbed_robot(x)
    after = [p.homogeneous for p in tool_changer.joint_placements]
    for b, a in zip(before, after):
        np.testing.assert_array_equal(a, b)
    assert not np.allclose(as_built.joint_placements[2].homogeneous, before[2])


def test_zero_error_gives_the_nominal_pose(tool_changer):
    """x = 0 through the error model is the URDF's own chain, multiplied out by hand."""
    em = ErrorModel(tool_changer)
    q = random_joint_values(tool_changer, 10, np.random.default_rng(1))
    expected = np.array([tool_changer_tcp_by_hand(qi) for qi in q])
    got = tcp_poses(tool_changer, q, em.zeros(), em)
    np.testing.assert_allclose(got.position, expected[:, :3, 3], atol=1e-12)
    np.testing.assert_allclose(got.rotation, expected[:, :3, :3], atol=1e-12)


def test_table2_preset_spreads_are_the_seed_numbers(tool_changer):
    budget = seed_budget(tool_changer, "table2")
    std = {s.name: s.std for s in budget.sources}
    assert std["l3 link length"] == pytest.approx(0.2e-3)
    assert std["l4 link length"] == pytest.approx(0.25e-3)
    assert std["j3 drive"] == pytest.approx(math.radians(0.1548))
    assert std["j4 drive"] == pytest.approx(0.25e-3)
    assert std["j6 drive"] == pytest.approx(math.radians(0.5))  # our choice, stated in the docs
    # link lengths move the joints along the links: l3 along y, l1 along z
    l3 = next(s for s in budget.sources if s.name == "l3 link length")
    em = budget.error_model
    assert l3.direction[em.index("j3.dy")] == pytest.approx(1.0)
    assert np.count_nonzero(l3.direction) == 1


def test_table1_preset_deflects_revolute_axes_only(tool_changer):
    budget = seed_budget(tool_changer, "table1")
    tilts = [s for s in budget.sources if s.group == "axis_deflection"]
    assert len(tilts) == 2 * 5 and all(s.std == pytest.approx(0.00435) for s in tilts)
    assert not any(s.name.startswith("j4") for s in tilts)
    em = budget.error_model
    # the tilts of j1 (axis z) are about x and y
    j1 = [s for s in tilts if s.name.startswith("j1")]
    assert {int(np.flatnonzero(s.direction)[0]) for s in j1} == {em.index("j1.rx"), em.index("j1.ry")}


def test_budget_sampling_matches_its_covariance(tool_changer):
    budget = seed_budget(tool_changer, "table1")
    x = budget.sample(200_000, np.random.default_rng(3))
    cov = budget.parameter_covariance()
    diag = np.diag(cov)
    used = diag > 0
    np.testing.assert_allclose(x[:, used].var(axis=0), diag[used], rtol=0.02)


def test_table2_refuses_a_robot_with_other_joints(ur5):
    with pytest.raises(InputError, match="table2"):
        seed_budget(ur5, "table2")


@pytest.mark.parametrize("kwargs, message", [
    (dict(distribution="lognormal"), "unknown distribution"),
    (dict(std=-1.0), "spread"),
    (dict(distribution="uniform", low=1.0, high=0.0), "uniform"),
])
def test_bad_sources_are_refused(tool_changer, kwargs, message):
    with pytest.raises(InputError, match=message):
        ErrorSource("s", "drive", np.zeros(3), "rad", **kwargs)


@pytest.mark.parametrize("name", ["tool_changer", "ur5"])
def test_as_built_urdf_reloaded_by_yourdfpy_gives_the_pinocchio_pose(name, tmp_path):
    robot = load_robot(name)
    em = ErrorModel(robot)
    rng = np.random.default_rng(7)
    x = rng.normal(0, 2e-3, em.size)
    text, tool = as_built_urdf(robot, x, em)
    path = tmp_path / "as_built.urdf"
    path.write_text(text)
    urdf = yourdfpy.URDF.load(str(path), load_meshes=False, load_collision_meshes=False)
    for q in random_joint_values(robot, 5, rng):
        expected = tcp_poses(robot, q, x, em)
        urdf.update_cfg(dict(zip(robot.joint_names, q)))
        transform = urdf.get_transform(frame_to=tool, frame_from=urdf.base_link)
        np.testing.assert_allclose(transform[:3, 3], expected.position[0], atol=1e-9)
        np.testing.assert_allclose(transform[:3, :3], expected.rotation[0], atol=1e-9)
    # the TCP frame itself stays where the maker put it (REP 199): only the measured frame is new
    nominal = yourdfpy.URDF.load(str(robot.urdf_path), load_meshes=False, load_collision_meshes=False) \
        if robot.urdf_path else None
    if nominal is not None:
        for joint in nominal.robot.joints:
            if joint.type == "fixed":
                np.testing.assert_array_equal(urdf.joint_map[joint.name].origin, joint.origin)
    # and Pinocchio reads it back as a nominal robot with the same pose
    reloaded = robot_from_urdf_text(text, tool)
    np.testing.assert_allclose(tcp_poses(reloaded, robot.working_pose).position,
                               tcp_poses(robot, robot.working_pose, x, em).position, atol=1e-12)


def test_tool_error_on_a_moving_link_frame_adds_a_child_link(ur5):
    robot = load_robot("ur5", tool="wrist_3_link")
    em = ErrorModel(robot)
    x = em.zeros()
    x[em.index("tool.dz")] = 0.01
    text, tool = as_built_urdf(robot, x, em)
    assert tool == "wrist_3_link_measured"
    reloaded = robot_from_urdf_text(text, tool)
    np.testing.assert_allclose(tcp_poses(reloaded, robot.working_pose).position,
                               tcp_poses(robot, robot.working_pose, x, em).position, atol=1e-12)
