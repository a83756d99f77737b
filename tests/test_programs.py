"""Robot programs filtered through a calibration (``export --program``, issue 42 item 1).

Each fixture is a program written here, in its language, with comments, variables, tool data, a work
object or base, control flow, an instruction nobody knows, a motion the filter does not take, a target
that is an expression and one the robot cannot reach; its numbers are computed here from joint values
by Pinocchio's own forward kinematics of the nominal robot with the program's tool (what the controller
would store). The calibration is a hidden truth built here on Pinocchio: error screws on every joint
placement (``M_j <- M_j exp6(xi_j)``), encoder offsets and the measured point's offset, handed to the
filter as the :class:`~tcr_accuracy.asbuilt.model.AsBuiltModel` of those numbers.

Checked, reading the filtered text back with this file's own readers:

* every filtered target, commanded as written (a pose through the controller's inverse kinematics,
  solved here by scipy from the target's joints), puts the true robot's TCP on the programmed target
  within a thousandth of the noise floor (0.015 mm);
* every line that holds no target is the same, byte for byte; with a calibration of zero effects the
  whole program comes back unchanged under its header;
* the unreachable target, the expression and the motion not taken are listed, written as they were;
* a file that does not parse is one line naming the file, line and column, exit 2.

The robots: example-robot-data's UR5 (URScript, the joint trajectory CSV), a KUKA KR 6 R900 and an
ABB IRB 120 from robots/ (ROS-Industrial's joint origins and axes).
"""

import json
import math
import re

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import least_squares

from tcr_accuracy.asbuilt.model import AsBuiltModel
from tcr_accuracy.asbuilt.programs import filter_program
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.robot import load_robot

from conftest import REPO, run_command

DATA = REPO / "robots"
NOISE_FLOOR_M = 0.015e-3
TOLERANCE_M = 1e-3 * NOISE_FLOOR_M
HEADER = ["Filtered for the test"]
NUMBER = r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"


# ---------------------------------------------------------------------------------------
# The hidden calibration, and the controller's kinematics, on Pinocchio alone
# ---------------------------------------------------------------------------------------
class Truth:
    """A robot, its hidden calibration (placement screws, encoder offsets, measured point) and the
    AsBuiltModel that states it."""

    def __init__(self, robot, seed, size=1.0):
        rng = np.random.default_rng(seed)
        self.robot = robot
        self.screws = {j: np.r_[rng.normal(0, 2e-4 * size, 3), rng.normal(0, 2e-4 * size, 3)]
                       for j in robot.joint_names}
        self.offsets = rng.normal(0, math.radians(0.03) * size, robot.n_joints)
        self.measured_point = np.array([0.01, -0.02, 0.05]) * size
        components = ("dx", "dy", "dz", "rx", "ry", "rz")
        parameters = {"geometry": {f"geometry.{j}.{c}": float(v) for j in robot.joint_names
                                   for c, v in zip(components, self.screws[j])},
                      "joint_offsets": {f"joint_offsets.{j}": float(v) for j, v in zip(robot.joint_names, self.offsets)},
                      "frames": {f"frames.tool.{c}": float(v) for c, v in zip(("dx", "dy", "dz"), self.measured_point)}}
        self.model = AsBuiltModel(robot, parameters if size else {}, str(robot.urdf_path))
        self.real = pin.Model(robot.model)
        for j in robot.joint_names:
            jid = self.real.getJointId(j)
            self.real.jointPlacements[jid] = self.real.jointPlacements[jid] * pin.exp6(self.screws[j])
        self.base = _frame_of(robot.model, "base") if robot.model.existFrame("base") else np.eye(4)

    def flange(self, q, real=False):
        """root_M_flange (4, 4) of the nominal robot at q, or of the real one at q + offsets."""
        model = self.real if real else self.robot.model
        data = model.createData()
        pin.framesForwardKinematics(model, data, _configuration(self.robot, model, q + (self.offsets if real else 0)))
        return data.oMf[model.getFrameId(self.robot.tool_frame)].homogeneous

    def tcp(self, q, tool=None, real=False):
        """root_M_tcp with the tool (flange_M_tcp; None: the measured point as a pure offset)."""
        tool = _translation(self.measured_point) if tool is None else tool
        return self.flange(q, real) @ tool


def _configuration(robot, model, q):
    out = pin.neutral(model)
    for name, value in zip(robot.joint_names, q):
        joint = model.joints[model.getJointId(name)]
        out[joint.idx_q:joint.idx_q + joint.nq] = [value] if joint.nq == 1 else [math.cos(value), math.sin(value)]
    return out


def _frame_of(model, name):
    return model.frames[model.getFrameId(name)].placement.homogeneous


def _translation(v):
    out = np.eye(4)
    out[:3, 3] = v
    return out


def _rpy_pose(x, y, z, rotation):
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, (x, y, z)
    return out


def _solve(truth, pose, tool, start):
    """The controller's inverse kinematics of ``pose`` (root frame) with ``tool``, from ``start``: scipy on
    Pinocchio's forward kinematics."""
    def residual(q):
        got = truth.tcp(q, tool)
        return np.r_[got[:3, 3] - pose[:3, 3], pin.log3(pose[:3, :3].T @ got[:3, :3])]

    fit = least_squares(residual, start, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.abs(fit.fun).max() < 1e-11, "the written pose is out of the controller's reach"
    return fit.x


def _miss(truth, tool, q_command, target):
    """|true TCP at the command - programmed target| [m]."""
    return float(np.linalg.norm(truth.tcp(q_command, tool, real=True)[:3, 3] - target[:3, 3]))


def _check_lines(original, filtered, insert_at, target_lines):
    """The filtered text is the original with a block of header lines inserted at line ``insert_at`` (0-based)
    and only the lines ``target_lines`` (1-based) changed."""
    old = original.splitlines(keepends=True)
    new = filtered.splitlines(keepends=True)
    extra = len(new) - len(old)
    assert extra > 0
    body = new[:insert_at] + new[insert_at + extra:]
    assert len(body) == len(old)
    for k, (a, b) in enumerate(zip(old, body), start=1):
        if k not in target_lines:
            assert a == b, f"line {k} changed: {a!r} -> {b!r}"
    return body


# ---------------------------------------------------------------------------------------
# URScript on the UR5
# ---------------------------------------------------------------------------------------
UR_TEMPLATE = """# Drilling a plate: written by hand for the filter test
def drill_plate():
  # the drill: 120 mm along the flange's z, turned 20 deg
  set_tcp({TOOL})
  set_payload(1.2)
  global home = {Q0}
  approach = {P1}
  hole_1 = {P2}
  movej(home, a=1.4, v=1.05)
  movej(approach, a=1.4, v=1.05)
  $ 4 "MoveL"
  movel(hole_1, a=0.5, v=0.05)
  if get_standard_digital_in(0):
    movel({P3}, a=0.5, v=0.05, r=0.0005)
  else:
    movep({P4}, a=0.5, v=0.05, r=0.001)
  end
  spindle_on(3000)
  movel(pose_trans(hole_1, p[0, 0, -0.05, 0, 0, 0]), a=0.5, v=0.1)
  movec(hole_1, approach, a=0.5, v=0.1)
  movej({Q1}, a=1.4, v=1.05)
  movel(p[3.0, 0.0, 0.5, 0.0, 3.1415, 0.0], a=0.5, v=0.1)
end
"""
UR_TOOL = _rpy_pose(0.0, 0.0, 0.12, pin.rpy.rpyToMatrix(0.0, 0.0, math.radians(20.0)))


def _urscript_pose(truth, q):
    pose = np.linalg.inv(truth.base) @ truth.tcp(q, UR_TOOL)
    values = [*pose[:3, 3], *pin.log3(pose[:3, :3])]
    return "p[" + ", ".join(f"{v:.6f}" for v in values) + "]", pose


def _urscript_fixture(truth):
    q0 = np.radians([10.0, -100.0, 95.0, -85.0, -90.0, 15.0])
    joints = {"Q0": q0, "P1": q0 + np.radians([5, 5, -3, 2, 1, -4]), "P2": q0 + np.radians([8, 7, -5, 3, 2, -6]),
              "P3": q0 + np.radians([10, 8, -6, 4, 2, -8]), "P4": q0 + np.radians([12, 9, -7, 5, 3, -9]),
              "Q1": q0 + np.radians([-20, 10, -10, 0, 5, 30])}
    text_values, expected = {}, {}
    for key, q in joints.items():
        q = np.round(q, 6)
        joints[key] = q
        if key.startswith("Q"):
            text_values[key] = "[" + ", ".join(f"{v:.6f}" for v in q) + "]"
            expected[key] = ("joints", q)
        else:
            text_values[key], pose = _urscript_pose(truth, q)
            expected[key] = ("pose", truth.base @ _parse_urscript_pose(text_values[key]))
    text_values["TOOL"] = "p[" + ", ".join(f"{v:.6f}" for v in (*UR_TOOL[:3, 3], *pin.log3(UR_TOOL[:3, :3]))) + "]"
    return UR_TEMPLATE.format(**text_values), joints, expected


def _parse_urscript_pose(text):
    values = [float(v) for v in re.findall(NUMBER, text)]
    return _rpy_pose(*values[:3], pin.exp3(np.array(values[3:6])))


def _urscript_targets(text):
    """{key: the literal's text} of the fixture's targets, read from the filtered text by position."""
    lines = text.splitlines()
    body = [line for line in lines if not line.startswith("# ") or "Drilling" in line]
    found = {}
    for key, pattern in (("Q0", r"global home = (\[.*\])"), ("P1", r"approach = (p\[.*\])"),
                         ("P2", r"hole_1 = (p\[.*\])"), ("P3", r"    movel\((p\[.*?\]), a"),
                         ("P4", r"    movep\((p\[.*?\]), a"), ("Q1", r"  movej\((\[.*?\]), a")):
        found[key] = next(re.search(pattern, line).group(1) for line in body if re.search(pattern, line))
    return found


@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5")


def test_a_urscript_program_lands_on_its_targets(ur5):
    truth = Truth(ur5, 1)
    text, joints, expected = _urscript_fixture(truth)
    result = filter_program(truth.model, {"drill.script": text}, threshold=TOLERANCE_M, header=HEADER)
    filtered = result.texts["drill.script"]
    body = _check_lines(text, filtered, 0, {6, 7, 8, 14, 16, 21})
    written = _urscript_targets("".join(body))
    worst = 0.0
    for key, (kind, target) in expected.items():
        if kind == "joints":
            command = np.array([float(v) for v in re.findall(NUMBER, written[key])])
            programmed = truth.tcp(joints[key], UR_TOOL)
        else:
            command = _solve(truth, truth.base @ _parse_urscript_pose(written[key]), UR_TOOL, joints[key])
            programmed = target
        miss = _miss(truth, UR_TOOL, command, programmed)
        before = _miss(truth, UR_TOOL, joints[key], programmed)
        assert before > 1e-4  # the calibration moves each target by a tenth of a millimetre or more
        worst = max(worst, miss)
    print(f"URScript: worst miss filtered {worst * 1e3:.2g} mm")
    assert worst <= TOLERANCE_M
    status = {t.label: (t.status, t.reason) for t in result.targets}
    assert status["movel at drill.script:22"][0] == "not filtered"
    assert "no inverse kinematics" in status["movel at drill.script:22"][1]
    assert any("expression" in reason for s, reason in status.values() if s == "not filtered")
    assert any("spindle_on" in u for u in result.unknown) and any("movec" in u for u in result.unknown)
    assert filtered.startswith("# Filtered for the test\n")
    assert "# movel at drill.script:22: no inverse kinematics" in filtered
    assert sum(t.status == "filtered" for t in result.targets) == 6


@pytest.mark.parametrize("language", ["URScript", "KRL", "RAPID", "CSV"])
def test_a_calibration_without_effects_gives_the_program_back_byte_for_byte(language, ur5, kuka, abb):
    """No effect, nothing to correct: every file comes back as it was, byte for byte (under its header when one
    is asked for)."""
    if language == "URScript":
        truth = Truth(ur5, 1, size=0.0)
        files = {"drill.script": _urscript_fixture(truth)[0]}
    elif language == "KRL":
        truth = Truth(kuka, 2, size=0.0)
        src, dat, _ = _krl_fixture(truth)
        files = {"weld_seam.src": src, "weld_seam.dat": dat}
    elif language == "RAPID":
        truth = Truth(abb, 3, size=0.0)
        files = {"DrillCell.mod": _rapid_fixture(truth)[0]}
    else:
        truth = Truth(ur5, 4, size=0.0)
        files = {"path.csv": "time_from_start," + ",".join(ur5.joint_names) + "\n0.0,0.1,-1.5,1.4,-1.6,-1.5,0.2\n"
                             "0.5,0.11,-1.49,1.41,-1.59,-1.5,0.21\n"}
    result = filter_program(truth.model, files, threshold=TOLERANCE_M)
    assert result.texts == files
    with_header = filter_program(truth.model, files, threshold=TOLERANCE_M, header=HEADER)
    for name, text in files.items():  # the original with a block of comment lines inserted, nothing else
        new = with_header.texts[name]
        prefix = next(k for k in range(len(text) + 1) if k == len(text) or new[k] != text[k])
        prefix = text.rfind("\n", 0, prefix) + 1  # the insertion starts a line
        suffix = next(k for k in range(len(text) - prefix + 1) if k == len(text) - prefix or new[-1 - k] != text[-1 - k])
        assert new[:prefix] == text[:prefix] and new[len(new) - suffix:] == text[len(text) - suffix:]
        assert prefix + suffix >= len(text)
        inserted = new[prefix:len(new) - (len(text) - prefix)]
        assert inserted.splitlines()[0].endswith(HEADER[0])
        assert all(line[:2] in ("# ", "; ", "! ") for line in inserted.splitlines())


# ---------------------------------------------------------------------------------------
# KRL on a KUKA KR 6
# ---------------------------------------------------------------------------------------
KRL_SRC = """&ACCESS RVP
&REL 3
&PARAM TEMPLATE = C:\\KRC\\Roboter\\Template\\vorgabe
DEF weld_seam( )
;FOLD INI;%{{PE}}
  ;FOLD BASISTECH INI
    GLOBAL INTERRUPT DECL 3 WHEN $STOPMESS==TRUE DO IR_STOPM ( )
    INTERRUPT ON 3
    BAS (#INITMOV,0 )
  ;ENDFOLD (BASISTECH INI)
;ENDFOLD (INI)
; the welding torch: 200 mm out, tilted 30 deg
$TOOL = {TOOL}
$BASE = $NULLFRAME
PTP XHOME
;FOLD PTP P1 Vel=100 % PDAT1 Tool[1] Base[0];%{{PE}}
$BWDSTART=FALSE
PDAT_ACT=PPDAT1
BAS(#PTP_PARAMS,100)
PTP XP1
;ENDFOLD
LIN XP2 C_DIS
LIN {P3}
torch_on(5)
FOR I = 1 TO 2
  LIN XP4
ENDFOR
LIN_REL {{Z 20.0}}
PTP {{X 2500.0, Y 0.0, Z 600.0, A 0.0, B 90.0, C 0.0, S 2, T 2}}
PTP {Q1}
END
"""
KRL_DAT = """&ACCESS RVP
&REL 3
DEFDAT weld_seam
;FOLD EXTERNAL DECLARATIONS;%{{PE}}%MKUKATPBASIS,%CEXT,%VCOMMON,%P
;ENDFOLD (EXTERNAL DECLARATIONS)
DECL E6AXIS XHOME={Q0}
DECL E6POS XP1={P1}
DECL E6POS XP2={P2}
DECL E6POS XP4={P4}
DECL E6POS XUNUSED={{X 400.0,Y 0.0,Z 500.0,A 0.0,B 90.0,C 0.0,S 2,T 2,E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}
DECL PDAT PPDAT1={{VEL 100,ACC 100,APO_DIST 100}}
ENDDAT
"""
KR_TOOL = _rpy_pose(0.0, 0.0, 0.2, pin.rpy.rpyToMatrix(0.0, math.radians(-30.0), 0.0))


def _zyx(rotation):
    """KUKA's A, B, C [deg] of a rotation: R = Rz(A) Ry(B) Rx(C), written out."""
    b = math.atan2(-rotation[2, 0], math.hypot(rotation[2, 1], rotation[2, 2]))
    a = math.atan2(rotation[1, 0], rotation[0, 0])
    c = math.atan2(rotation[2, 1], rotation[2, 2])
    return [math.degrees(v) for v in (a, b, c)]


def _from_zyx(a, b, c):
    return (pin.rpy.rpyToMatrix(0, 0, math.radians(a)) @ pin.rpy.rpyToMatrix(0, math.radians(b), 0)
            @ pin.rpy.rpyToMatrix(math.radians(c), 0, 0))


def _kuka_status(truth, q):
    """Status and Turn written out for the KR 6: bit 0 the wrist point (A5's origin) behind A1, bit 1 in front of
    the line through A2 and A3 (x-z plane of the A1 frame), bit 2 A5 negative; Turn: the negative axes."""
    model = truth.robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, _configuration(truth.robot, model, q))
    a1 = data.oMi[1].rotation @ model.jointPlacements[1].rotation.T
    wrist, p2, p3 = (a1.T @ (data.oMi[j].translation - data.oMi[1].translation) for j in (5, 2, 3))
    d, w = p3 - p2, wrist - p2
    status = int(wrist[0] < 0) | int(w[0] * d[2] - w[2] * d[0] > 0) << 1 | int(q[4] < 0) << 2
    return status, sum(1 << i for i, v in enumerate(q) if v < 0)


def _krl_pose(truth, q, binary=False):
    pose = truth.tcp(q, KR_TOOL)
    x, y, z = pose[:3, 3] * 1e3
    a, b, c = _zyx(pose[:3, :3])
    s, t = _kuka_status(truth, q)
    s_text, t_text = (f"'B{s:03b}'", f"'B{t:06b}'") if binary else (str(s), str(t))
    body = f"X {x:.4f}, Y {y:.4f}, Z {z:.4f}, A {a:.4f}, B {b:.4f}, C {c:.4f}, S {s_text}, T {t_text}"
    return body


def _krl_fixture(truth):
    q0 = np.radians([5.0, -80.0, 95.0, 10.0, 40.0, -20.0])
    joints = {"Q0": q0, "P1": q0 + np.radians([6, 5, -4, 3, 4, -5]), "P2": q0 + np.radians([10, 8, -6, 4, 6, -8]),
              "P3": q0 + np.radians([12, 9, -7, 5, 7, -9]), "P4": q0 + np.radians([14, 11, -8, 6, 8, -10]),
              "Q1": q0 + np.radians([-15, -10, 10, -20, 10, 40])}
    values = {}
    for key, q in joints.items():
        joints[key] = q = np.round(np.degrees(q), 4) * math.pi / 180.0
        if key.startswith("Q"):
            axes = ", ".join(f"A{i + 1} {v:.4f}" for i, v in enumerate(np.degrees(q)))
            values[key] = "{" + (axes + ", E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0" if key == "Q0" else axes) + "}"
        elif key == "P3":
            values[key] = "{" + _krl_pose(truth, q, binary=True) + "}"
        else:
            values[key] = "{" + _krl_pose(truth, q).replace(", ", ",") + ",E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}"
    x, y, z = KR_TOOL[:3, 3] * 1e3
    values["TOOL"] = "{X %.1f, Y %.1f, Z %.1f, A %.4f, B %.4f, C %.4f}" % (x, y, z, *_zyx(KR_TOOL[:3, :3]))
    return KRL_SRC.format(**values), KRL_DAT.format(**values), joints


def _krl_aggregate(text, name):
    """{component: value} of an aggregate in the filtered text: the declaration of ``name`` or the inline one on
    the line starting with ``name``."""
    line = next(line for line in text.splitlines() if line.startswith(name))
    body = line[line.index("{") + 1:line.rindex("}")]
    out = {}
    for part in body.split(","):
        key, value = part.split()
        out[key.upper()] = int(value[2:-1], 2) if value.startswith("'B") else float(value)
    return out


def _krl_command(truth, aggregate, start):
    pose = _rpy_pose(*(aggregate[k] * 1e-3 for k in "XYZ"), _from_zyx(aggregate["A"], aggregate["B"], aggregate["C"]))
    q = _solve(truth, pose, KR_TOOL, start)
    assert _kuka_status(truth, q) == (int(aggregate["S"]) & 7, int(aggregate["T"]) & 63)  # the branch the S and T name
    return q, pose


@pytest.fixture(scope="module")
def kuka():
    return load_robot(str(DATA / "kuka_kr6.urdf"), "tool0")


def test_a_krl_program_lands_on_its_targets(kuka):
    truth = Truth(kuka, 2)
    src, dat, joints = _krl_fixture(truth)
    result = filter_program(truth.model, {"weld_seam.src": src, "weld_seam.dat": dat}, threshold=TOLERANCE_M,
                            header=HEADER)
    new_src, new_dat = result.texts["weld_seam.src"], result.texts["weld_seam.dat"]
    _check_lines(src, new_src, 3, {23, 30})
    _check_lines(dat, new_dat, 2, {6, 7, 8, 9})
    assert new_src.startswith("&ACCESS RVP\n&REL 3\n&PARAM TEMPLATE") and new_src.splitlines()[3] == "; Filtered for the test"
    worst = 0.0
    for key, where, text in (("P1", "DECL E6POS XP1", new_dat), ("P2", "DECL E6POS XP2", new_dat),
                             ("P4", "DECL E6POS XP4", new_dat), ("P3", "LIN {", new_src)):
        aggregate = _krl_aggregate(text, where)
        command, _ = _krl_command(truth, aggregate, joints[key])
        _, programmed = _krl_command(truth, _krl_aggregate(dat if text is new_dat else src, where), joints[key])
        worst = max(worst, _miss(truth, KR_TOOL, command, programmed))
        assert _miss(truth, KR_TOOL, joints[key], programmed) > 1e-4
    for key, where, text in (("Q0", "DECL E6AXIS XHOME", new_dat), ("Q1", "PTP {A1", new_src)):
        aggregate = _krl_aggregate(text, where)
        command = np.radians([aggregate[f"A{i}"] for i in range(1, 7)])
        worst = max(worst, _miss(truth, KR_TOOL, command, truth.tcp(joints[key], KR_TOOL)))
    print(f"KRL: worst miss filtered {worst * 1e3:.2g} mm")
    assert worst <= TOLERANCE_M
    home = next(line for line in new_dat.splitlines() if line.startswith("DECL E6AXIS XHOME"))
    assert home.endswith(", E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}")  # the external axes as they were
    refused = {t.label: t.reason for t in result.not_filtered}
    assert any("no inverse kinematics" in r for label, r in refused.items() if "weld_seam.src:29" in label)
    assert any("torch_on" in u for u in result.unknown) and any("LIN_REL" in u for u in result.unknown)
    assert any("XUNUSED is used by no motion" in n for n in result.notes)


# ---------------------------------------------------------------------------------------
# RAPID on an ABB IRB 120
# ---------------------------------------------------------------------------------------
RAPID_TEMPLATE = """MODULE DrillCell
    ! written by hand for the filter test: a drill on a plate
    PERS tooldata tDrill:={TOOL};
    PERS wobjdata wPlate:=[FALSE,TRUE,"",[[350,-100,50],[0.996194698,0,0,0.087155743]],[[0,0,0],[1,0,0,0]]];
    CONST jointtarget jHome:={J0};
    CONST robtarget pApproach:={R1};
    CONST robtarget pHole1:={R2};
    VAR num nHoles:=0;
    PROC main()
        MoveAbsJ jHome\\NoEOffs, v1000, z50, tool0;
        MoveJ pApproach, v500, z10, tDrill\\WObj:=wPlate;
        MoveL pHole1, v50, fine, tDrill\\WObj:=wPlate;
        WHILE nHoles < 2 DO
            MoveL {R3}, v50, fine, tDrill\\WObj:=wPlate;
            nHoles := nHoles + 1;
        ENDWHILE
        MoveL Offs(pHole1,0,0,50), v200, z10, tDrill\\WObj:=wPlate;
        SpindleOn 3000;
        MoveL [[3000,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v200, fine, tDrill\\WObj:=wPlate;
        MoveAbsJ {J1}\\NoEOffs, v1000, z50, tool0;
    ENDPROC
ENDMODULE
"""
ABB_TOOL = _rpy_pose(0.0, 0.0, 0.11, pin.rpy.rpyToMatrix(0.0, math.radians(30.0), 0.0))
ABB_WOBJ = _rpy_pose(0.35, -0.1, 0.05, pin.Quaternion(0.996194698, 0, 0, 0.087155743).normalized().toRotationMatrix())


def _quaternion_text(rotation):
    q = pin.Quaternion(rotation)
    return "[" + ",".join(f"{v:.9f}" for v in (q.w, q.x, q.y, q.z)) + "]"


def _abb_configuration(truth, q):
    """cf1, cf4, cf6 (quadrants) and cfx (4: wrist behind axis 1, 2: behind the lower arm, 1: axis 5 negative),
    written out for the IRB 120."""
    model = truth.robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, _configuration(truth.robot, model, q))
    a1 = data.oMi[1].rotation @ model.jointPlacements[1].rotation.T
    wrist, p2, p3 = (a1.T @ (data.oMi[j].translation - data.oMi[1].translation) for j in (5, 2, 3))
    d, w = p3 - p2, wrist - p2
    front = w[0] * d[2] - w[2] * d[0] > 0
    cfx = 4 * int(wrist[0] < 0) + 2 * int(not front) + int(q[4] < 0)
    return [math.floor(math.degrees(q[k]) / 90.0) for k in (0, 3, 5)] + [cfx]


def _rapid_fixture(truth):
    q0 = np.radians([-10.0, 20.0, 10.0, 15.0, 45.0, -30.0])
    joints = {"J0": q0, "R1": q0 + np.radians([5, 4, -3, 4, 3, -5]), "R2": q0 + np.radians([8, 6, -4, 5, 5, -7]),
              "R3": q0 + np.radians([10, 8, -5, 6, 6, -9]), "J1": q0 + np.radians([25, -10, 10, -30, 20, 100])}
    values = {}
    for key, q in joints.items():
        joints[key] = q = np.round(np.degrees(q), 4) * math.pi / 180.0
        if key.startswith("J"):
            values[key] = "[[" + ",".join(f"{v:.4f}" for v in np.degrees(q)) + "],[9E9,9E9,9E9,9E9,9E9,9E9]]"
        else:
            pose = np.linalg.inv(ABB_WOBJ) @ truth.tcp(q, ABB_TOOL)
            configuration = ",".join(str(v) for v in _abb_configuration(truth, q))
            values[key] = ("[[" + ",".join(f"{v:.4f}" for v in pose[:3, 3] * 1e3) + "]," + _quaternion_text(pose[:3, :3])
                           + f",[{configuration}],[9E9,9E9,9E9,9E9,9E9,9E9]]")
    values["TOOL"] = ("[TRUE,[[" + ",".join(f"{v:g}" for v in ABB_TOOL[:3, 3] * 1e3) + "]," +
                      _quaternion_text(ABB_TOOL[:3, :3]) + "],[1.2,[0,0,50],[1,0,0,0],0,0,0]]")
    return RAPID_TEMPLATE.format(**values), joints


def _rapid_literal(text, start):
    line = next(line for line in text.splitlines() if line.strip().startswith(start))
    return [float(v) for v in re.findall(NUMBER, line[line.index("[["):])]


@pytest.fixture(scope="module")
def abb():
    return load_robot(str(DATA / "abb_irb120.urdf"), "tool0")


def test_a_rapid_program_lands_on_its_targets(abb):
    truth = Truth(abb, 3)
    text, joints = _rapid_fixture(truth)
    result = filter_program(truth.model, {"DrillCell.mod": text}, threshold=TOLERANCE_M, header=HEADER)
    filtered = result.texts["DrillCell.mod"]
    body = "".join(_check_lines(text, filtered, 1, {5, 6, 7, 14, 20}))
    assert filtered.splitlines()[1] == "! Filtered for the test"
    worst = 0.0
    for key, start in (("R1", "CONST robtarget pApproach"), ("R2", "CONST robtarget pHole1"), ("R3", "MoveL [[")):
        values = _rapid_literal(body, start)
        rotation = pin.Quaternion(*values[3:7]).normalized().toRotationMatrix()
        pose = ABB_WOBJ @ _rpy_pose(*(np.array(values[:3]) * 1e-3), rotation)
        command = _solve(truth, pose, ABB_TOOL, joints[key])
        assert _abb_configuration(truth, command) == [int(v) for v in values[7:11]]
        written = _rapid_literal(text, start)  # the programmed target: the literal as the fixture wrote it
        programmed = ABB_WOBJ @ _rpy_pose(*(np.array(written[:3]) * 1e-3),
                                          pin.Quaternion(*written[3:7]).normalized().toRotationMatrix())
        assert _miss(truth, ABB_TOOL, joints[key], programmed) > 1e-4
        worst = max(worst, _miss(truth, ABB_TOOL, command, programmed))
    for key, start in (("J0", "CONST jointtarget jHome"), ("J1", "MoveAbsJ [[")):
        command = np.radians(_rapid_literal(body, start)[:6])
        flange = np.eye(4)  # MoveAbsJ with tool0: the flange's point
        worst = max(worst, _miss(truth, flange, command, truth.tcp(joints[key], flange)))
    print(f"RAPID: worst miss filtered {worst * 1e3:.2g} mm")
    assert worst <= TOLERANCE_M
    refused = {t.label: t.reason for t in result.not_filtered}
    assert any("no inverse kinematics" in r for label, r in refused.items() if "DrillCell.mod:19" in label)
    assert any("Offs(pHole1" in r for r in refused.values())
    assert any("SpindleOn" in u for u in result.unknown)


# ---------------------------------------------------------------------------------------
# A joint trajectory CSV on the UR5
# ---------------------------------------------------------------------------------------
def test_a_joint_trajectory_csv_lands_on_its_points(ur5):
    truth = Truth(ur5, 4)
    rng = np.random.default_rng(5)
    q = np.radians([0.0, -90.0, 90.0, -90.0, -90.0, 0.0]) + np.cumsum(rng.normal(0, 0.02, (8, 6)), axis=0)
    header = "time_from_start," + ",".join(ur5.joint_names) + ",shoulder_pan_joint_velocity\n"
    rows = "".join(f"{0.5 * k:.1f}," + ",".join(f"{v:.8f}" for v in row) + ",0.1\n" for k, row in enumerate(q))
    text = "# a path for the test\n" + header + rows
    result = filter_program(truth.model, {"path.csv": text}, threshold=TOLERANCE_M, header=HEADER)
    lines = result.texts["path.csv"].splitlines()
    assert lines[0] == "# Filtered for the test" and "# a path for the test" in lines
    data = [line.split(",") for line in lines if line[0].isdigit()]
    assert len(data) == 8 and all(row[-1] == "0.1" for row in data)
    for row, original in zip(data, q):
        command = np.array([float(v) for v in row[1:7]])
        assert _miss(truth, None, command, truth.tcp(original)) <= TOLERANCE_M
    assert any("shoulder_pan_joint_velocity" in u for u in result.unknown)


# ---------------------------------------------------------------------------------------
# What does not parse
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("name, text, where", [
    ("bad.script", "def a():\n  movel(p[0.1, 0.2, 0.3)\nend\n", "bad.script:2:"),
    ("bad.script", "def a():\n  movel(p[0.1, 0.2, 0.3, 0, 0, 0])\n", "bad.script:3:1"),
    ("bad.src", "DEF a( )\nIF $IN[1] THEN\nPTP XHOME\nEND\n", "bad.src:4:1"),
    ("bad.mod", "MODULE m\n  PROC main()\n    MoveL p10, v100, fine, tool0\n  ENDPROC\nENDMODULE\n", "bad.mod:6:1"),
    ("bad.mod", "MODULE m\n  PROC main()\n    MoveL [[1,2],[3], v100, fine, tool0;\n  ENDPROC\nENDMODULE\n",
     "bad.mod:3:40"),
    ("bad.csv", "time_from_start,a\n0,1\n", "bad.csv:1:1"),
])
def test_a_program_that_does_not_parse_is_one_line(name, text, where, ur5):
    with pytest.raises(InputError) as caught:
        filter_program(Truth(ur5, 0, size=0.0).model, {name: text})
    message = str(caught.value)
    assert message.startswith(where) and "\n" not in message, message


# ---------------------------------------------------------------------------------------
# The command line
# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ur5_diagnosis(tmp_path_factory, ur5):
    """A simulated UR5 calibration through the command line: simulate, diagnose --json."""
    folder = tmp_path_factory.mktemp("programs")
    import contextlib
    import io

    from tcr_accuracy.cli import main

    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "--robot", "ur5", "--random", "--n", "120", "--seed", "5", "--noise-mm",
                     "0.015", "--out", str(folder / "ur5.csv"), "--quiet"]) == 0
        assert main(["diagnose", str(folder / "ur5.csv"), "--robot", "ur5", "--effects", "joint_offsets,geometry",
                     "--noise-mm", "0.015", "--json", str(folder / "d.json"), "--quiet"]) == 0
    return folder


def test_export_writes_the_filtered_programs_under_their_names(ur5_diagnosis, ur5, capsys):
    folder = ur5_diagnosis
    truth = Truth(ur5, 1, size=0.0)
    text, _, _ = _urscript_fixture(truth)
    (folder / "drill.script").write_text(text)
    code, out, err = run_command(["export", str(folder / "d.json"), "--to", str(folder / "out"), "--program",
                                  str(folder / "drill.script"), "--quiet"], capsys)
    assert code == 0, err
    written = (folder / "out" / "drill.script").read_text()
    assert written.startswith("# Filtered by tcr-accuracy export on ")
    assert "through the calibrated model of d.json (ur5" in written and "as_built.yaml" in written
    assert "drill.script (URScript): 6 of 8 motion targets filtered" in out
    assert "not filtered: movel at drill.script:22: no inverse kinematics" in out
    assert "kept as written, not understood: drill.script:18: spindle_on(3000)" in out
    noise = json.loads((folder / "d.json").read_text())["noise_floor_mm"]
    assert f"to {1e-3 * noise:.3g} mm" in written


@pytest.mark.parametrize("case", ["does not parse", "twice", "clash", "unknown suffix", "other robot"])
def test_export_refuses_a_bad_program_in_one_line(case, ur5_diagnosis, tmp_path, capsys):
    folder = ur5_diagnosis
    program = tmp_path / "p.script"
    program.write_text("def a():\n  movel(p[0.1, 0.2)\nend\n")
    args = [str(program)]
    expected = "p.script:2:"
    if case == "twice":
        other = tmp_path / "b"
        other.mkdir()
        (other / "p.script").write_text("movej([0, 0, 0, 0, 0, 0])\n")
        program.write_text("movej([0, 0, 0, 0, 0, 0])\n")
        args, expected = [str(program), str(other / "p.script")], "two files named p.script"
    elif case == "clash":
        program = tmp_path / "dh.csv"
        program.write_text("time_from_start," + ",".join(load_robot("ur5").joint_names) + "\n0,0,0,0,0,0,0\n")
        args, expected = [str(program)], "--program dh.csv: export writes a file of that name"
    elif case == "unknown suffix":
        program = tmp_path / "p.txt"
        program.write_text("x\n")
        args, expected = [str(program)], "p.txt: not a program this filter reads"
    elif case == "other robot":
        program.write_text("movej([0, 0, 0, 0, 0, 0, 0])\n")
        expected = "p.script:1: 7 joint values, but ur5 has 6 joints"
    code, out, err = run_command(["export", str(folder / "d.json"), "--to", str(tmp_path / "out"), "--program",
                                  *args, "--quiet"], capsys)
    assert code == 2, (case, err)
    assert len(err.strip().splitlines()) == 1 and expected in err, err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
