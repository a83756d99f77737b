"""Property-based tests (hypothesis) of the kinematic core, and the URDF reader's refusal of entities.

Properties, each for many joint values and error vectors drawn by hypothesis (derandomized:
the same examples on every run):

* zero error is the nominal robot: the batched engine with x = 0 and the perturbed model
  for x = 0 give Pinocchio's forward kinematics of the nominal model;
* small errors move the TCP as the first-order prediction J(q) x of ``error_jacobian``
  (Pinocchio's kinematic regressor), with a residual of second order in |x|;
* a perturbation and its inverse cancel: perturbing the as-built robot by -x (each twist
  is one ``exp6`` on one side of one placement) restores every placement and the TCP;
* a base twist moves the whole TCP pose rigidly: ``exp6(xi) * oMtool``.
"""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tcr_accuracy import cli
from tcr_accuracy.model.errors import ErrorModel
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.jacobians import error_jacobian
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.model.robot import load_robot, robot_from_urdf_text

PROPERTY = settings(max_examples=25, derandomize=True, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])


def unit_vectors(size):
    return hnp.arrays(np.float64, size, elements=st.floats(-1.0, 1.0, allow_nan=False, width=64))


def _joint_values(robot, u):
    """Map u in [-1, 1]^n into the joint limits (unbounded joints: +-pi)."""
    lo = np.where(np.isnan(robot.lower_limits), -np.pi, robot.lower_limits)
    hi = np.where(np.isnan(robot.upper_limits), np.pi, robot.upper_limits)
    return lo + 0.5 * (np.asarray(u) + 1.0) * (hi - lo)


def _pinocchio_tcp(robot, q):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(q))
    return data.oMf[robot.tool_frame_id]


ROBOTS = ["tool_changer", "ur5"]


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request):
    return load_robot(request.param)


N_JOINTS = 6  # both robots of ROBOTS have six joints
N_PARAMS = 7 * N_JOINTS + 12


@PROPERTY
@given(u=unit_vectors(N_JOINTS))
def test_zero_error_gives_the_nominal_pose(robot, u):
    q = _joint_values(robot, u)
    em = ErrorModel(robot)
    reference = _pinocchio_tcp(robot, q)
    engine = tcp_poses(robot, q, em.zeros(), em)
    np.testing.assert_allclose(engine.position[0], reference.translation, atol=1e-12)
    np.testing.assert_allclose(engine.rotation[0], reference.rotation, atol=1e-12)
    as_built = em.perturbed_robot(em.zeros())
    np.testing.assert_allclose(_pinocchio_tcp(as_built, q).homogeneous, reference.homogeneous, atol=1e-12)


@PROPERTY
@given(u=unit_vectors(N_JOINTS), direction=unit_vectors(N_PARAMS).filter(lambda d: np.abs(d).max() > 0.1))
def test_small_errors_match_the_first_order_jacobian(robot, u, direction):
    q = _joint_values(robot, u)
    em = ErrorModel(robot)
    jac = error_jacobian(robot, q, em)
    nominal = tcp_poses(robot, q)
    residuals = []
    for eps in (1e-3, 1e-4):
        x = eps * direction  # every entry up to eps [m or rad]
        actual = tcp_poses(robot, q, x, em)
        predicted = jac @ x
        dp = actual.position[0] - nominal.position[0]
        rotvec = pin.log3(actual.rotation[0] @ nominal.rotation[0].T)
        residual = np.linalg.norm(np.concatenate([dp - predicted[:3], rotvec - predicted[3:]]))
        # second order: |residual| <= C |x|^2, C of the order of the reach [m]
        size = np.linalg.norm(x)
        assert residual <= 20.0 * size**2 + 1e-12, (eps, residual, size)
        residuals.append(residual)
    # ten times smaller errors leave a hundred times smaller residual (a wrong Jacobian
    # column would leave a first-order part: only ten times smaller)
    assert residuals[1] <= residuals[0] / 50.0 + 1e-13, residuals


@PROPERTY
@given(u=unit_vectors(N_JOINTS), direction=unit_vectors(N_PARAMS).filter(lambda d: np.abs(d).min() > 0.05),
       drive_only=st.booleans())
def test_a_perturbation_and_its_inverse_cancel(robot, u, direction, drive_only):
    q = _joint_values(robot, u)
    em = ErrorModel(robot)
    x = 0.05 * direction  # up to 50 mm and 0.05 rad: far from first order
    # a placement twist and a drive offset on the same joint do not commute, so the two kinds
    # are undone separately: each alone is one exp6 on one side of a placement
    if drive_only:
        x[em.placement_slice] = x[em.base_slice] = x[em.tool_slice] = 0.0
    else:
        x[em.drive_slice] = 0.0
    as_built = em.perturbed_robot(x)
    restored = ErrorModel(as_built).perturbed_robot(-x)
    for nominal, back in zip(robot.joint_placements, restored.joint_placements):
        np.testing.assert_allclose(back.homogeneous, nominal.homogeneous, atol=1e-12)
    np.testing.assert_allclose(restored.tool_placement.homogeneous, robot.tool_placement.homogeneous, atol=1e-12)
    np.testing.assert_allclose(_pinocchio_tcp(restored, q).homogeneous, _pinocchio_tcp(robot, q).homogeneous,
                               atol=1e-12)


@PROPERTY
@given(u=unit_vectors(N_JOINTS), twist=unit_vectors(6))
def test_a_base_twist_moves_the_tcp_rigidly(robot, u, twist):
    q = _joint_values(robot, u)
    em = ErrorModel(robot)
    x = em.zeros()
    x[em.base_slice] = 0.3 * twist
    expected = pin.exp6(pin.Motion(0.3 * twist)) * _pinocchio_tcp(robot, q)
    actual = tcp_poses(robot, q, x, em)
    np.testing.assert_allclose(actual.position[0], expected.translation, atol=1e-12)
    np.testing.assert_allclose(actual.rotation[0], expected.rotation, atol=1e-12)


# ---------------------------------------------------------------------------------------
# XML entity expansion is refused
# ---------------------------------------------------------------------------------------
#: The classic "billion laughs": ten nested entities, each ten times the one before; fully
#: expanded, lol9 is 10^9 copies of "lol" (3 GB).
BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE robot [
  <!ENTITY lol "lol">
  <!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
  <!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;">
  <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
  <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
  <!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
  <!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
  <!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
  <!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
  <!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">
]>
<robot name="&lol9;">
  <link name="base"/>
  <link name="tip"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="tip"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>
"""

XXE = """<?xml version="1.0"?>
<!DOCTYPE robot [<!ENTITY secret SYSTEM "file:///etc/passwd">]>
<robot name="&secret;"><link name="base"/></robot>
"""


@pytest.fixture
def no_xml_parsing(monkeypatch):
    """Make every XML parser used by the package fail loudly: a refusal must come before any parse.

    This is how the test shows the refusal is fast without timing it: no parser, and so no
    entity expansion, ever sees the document.
    """
    import xml.etree.ElementTree as ElementTree

    def forbidden(*args, **kwargs):
        raise AssertionError("the document reached an XML parser")

    monkeypatch.setattr(ElementTree, "fromstring", forbidden)
    monkeypatch.setattr(ElementTree, "XMLParser", forbidden)
    monkeypatch.setattr(pin, "buildModelFromXML", forbidden)


@pytest.mark.parametrize("document", [BILLION_LAUGHS, XXE], ids=["billion-laughs", "external-entity"])
def test_entity_documents_are_refused_before_parsing(document, no_xml_parsing):
    with pytest.raises(InputError, match=r"line 2: URDF declares a DTD or entity .*entity expansion is refused"):
        robot_from_urdf_text(document, "tip", source="lol.urdf")


def test_billion_laughs_file_gives_one_line_and_exit_2(tmp_path, capsys, no_xml_parsing):
    path = tmp_path / "lol.urdf"
    path.write_text(BILLION_LAUGHS)
    assert cli.main(["pose", "--robot", str(path), "--tool", "tip", "--q", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "entity expansion is refused" in err and "lol.urdf" in err


@PROPERTY
@given(spelling=st.sampled_from(["<!DOCTYPE", "<!doctype", "<! DOCTYPE", "<!ENTITY", "<!\nEntity"]),
       prefix_lines=st.integers(0, 5))
def test_any_spelling_of_a_dtd_is_refused_and_located(spelling, prefix_lines):
    text = '<?xml version="1.0"?>\n' + "<!-- -->\n" * prefix_lines + f"{spelling} robot []>\n<robot name='r'/>"
    with pytest.raises(InputError, match=f"line {prefix_lines + 2}: "):
        robot_from_urdf_text(text, None, source="x.urdf")
