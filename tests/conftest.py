"""Shared fixtures: models are built in-process (no network, no files outside the repo)."""

import os
import signal
from pathlib import Path

import numpy as np
import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.model.robot import load_robot

REPO = Path(__file__).resolve().parents[1]

# the commands tests start as subprocesses (`python -m tcr_accuracy`) run this checkout's code, not whatever
# copy of the package pip installed last (a worktree, or an install older than the working tree)
os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO / "src"), os.environ.get("PYTHONPATH")]))


@pytest.fixture(scope="session")
def tool_changer():
    return load_robot()


@pytest.fixture(scope="session")
def ur5():
    return load_robot("ur5")


def run_command(argv, capsys):
    """The command line in this process: (exit code, stdout, stderr)."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def pinocchio_kinematics(robot, q):
    """(data, TCP placement) of the robot's Pinocchio model at chain joints q (n_joints,), set joint by
    joint by name: Pinocchio's own forward kinematics, none of the package's."""
    import pinocchio as pin

    data = robot.model.createData()
    qp = pin.neutral(robot.model)
    for name, v in zip(robot.joint_names, q):
        qp[robot.model.joints[robot.model.getJointId(name)].idx_q] = v
    pin.framesForwardKinematics(robot.model, data, qp)
    return data, data.oMf[robot.model.getFrameId(robot.tool_frame)]


def random_joint_values(robot, n, rng, span=np.pi):
    """(n, n_joints) joint values inside the limits (unbounded joints within +-span)."""
    lo = np.where(np.isnan(robot.lower_limits), -span, np.maximum(robot.lower_limits, -span))
    hi = np.where(np.isnan(robot.upper_limits), span, np.minimum(robot.upper_limits, span))
    return rng.uniform(lo, hi, size=(n, robot.n_joints))


# ---------------------------------------------------------------------------------------
# The tool-changer's forward kinematics by hand, for tests that need an independent path
# ---------------------------------------------------------------------------------------
#: Joints of robots/tool_changer.urdf as written there: name, kind, origin xyz in the
#: parent link [m] (all origins have rpy = 0), axis. The TCP frame 'tool' sits at j6's
#: child link origin with identity rotation.
TOOL_CHANGER_JOINTS = [
    ("j1", "revolute", (0.0, 0.0, 0.315), (0.0, 0.0, 1.0)),
    ("j2", "revolute", (0.0, 0.0, 0.21), (1.0, 0.0, 0.0)),
    ("j3", "revolute", (0.0, 0.796, 0.0), (1.0, 0.0, 0.0)),
    ("j4", "prismatic", (0.0, 0.56, 0.0), (0.0, 1.0, 0.0)),
    ("j5", "revolute", (0.0, 0.24, 0.0), (1.0, 0.0, 0.0)),
    ("j6", "revolute", (0.0, 0.165, 0.0), (0.0, 0.0, 1.0)),
]


def _rotation_about(axis, angle):
    """Rodrigues' formula written out: R = I + sin(a) K + (1 - cos(a)) K^2, K = [axis]x."""
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def tool_changer_tcp_by_hand(q, link_errors=None, drive_errors=None):
    """base_M_tool (4, 4) of the tool-changer as a product of homogeneous matrices.

    Parameters
    ----------
    q : array-like of shape (6,)
        Joint values [rad, m].
    link_errors : array-like of shape (6,), optional
        Length errors [m] of the six links (the joint origins' offsets), each along its
        own offset, as the seed's Table 2 link lengths l1..l6.
    drive_errors : array-like of shape (6,), optional
        Drive offsets [rad, m] added to q.

    Uses numpy only: no Pinocchio and nothing from tcr_accuracy.
    """
    link_errors = np.zeros(6) if link_errors is None else np.asarray(link_errors, float)
    drive_errors = np.zeros(6) if drive_errors is None else np.asarray(drive_errors, float)
    out = np.eye(4)
    for i, (_, kind, origin, axis) in enumerate(TOOL_CHANGER_JOINTS):
        origin = np.asarray(origin)
        placement = np.eye(4)
        placement[:3, 3] = origin + link_errors[i] * origin / np.linalg.norm(origin)
        motion = np.eye(4)
        value = q[i] + drive_errors[i]
        if kind == "revolute":
            motion[:3, :3] = _rotation_about(axis, value)
        else:
            motion[:3, 3] = np.asarray(axis) * value
        out = out @ placement @ motion
    return out


def write_measurement_csv(path, robot, q, positions=None):
    """A measurement CSV (joint columns in display units, x_mm, y_mm, z_mm when positions
    (N, 3) [m] are given) of joint values q (N, n_joints) [rad, m]; returns the path as str."""
    cols = [f"{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]
    lines = [",".join(cols + (["x_mm", "y_mm", "z_mm"] if positions is not None else []))]
    for i in range(len(q)):
        vals = list(q[i] * robot.display_scale) + ([] if positions is None else list(positions[i] * 1e3))
        lines.append(",".join(f"{v:.10g}" for v in vals))
    path.write_text("\n".join(lines) + "\n")
    return str(path)


@pytest.fixture(scope="session")
def measurements(tmp_path_factory):
    """A measurement CSV of 24 simulated poses of the tool-changer (seed 2): what the
    hostile-input tests read, copy and forge."""
    path = tmp_path_factory.mktemp("small_campaign") / "m.csv"
    assert main(["simulate", "--n", "24", "--random", "--seed", "2", "--out", str(path), "--quiet"]) == 0
    return path


@pytest.fixture(scope="session")
def small_campaign(measurements):
    """(measurement CSV, diagnosis JSON): :func:`measurements` and its diagnosis with joint offsets."""
    diagnosis = measurements.with_name("d.json")
    assert main(["diagnose", str(measurements), "--effects", "joint_offsets", "--quiet", "--json",
                 str(diagnosis)]) == 0
    return measurements, diagnosis


@pytest.fixture(scope="session")
def m60(tmp_path_factory):
    """``simulate --scenario examples/scenario_compliance.yaml --n 60 --seed 2``: 60 poses of the
    tool-changer that agree with its joints, for the hostile-input tests to forge."""
    path = tmp_path_factory.mktemp("m60") / "m60.csv"
    assert main(["simulate", "--scenario", str(REPO / "examples" / "scenario_compliance.yaml"), "--n", "60",
                 "--seed", "2", "--out", str(path), "--quiet"]) == 0
    return path


# ---------------------------------------------------------------------------------------
# Signals without signalling pytest
# ---------------------------------------------------------------------------------------
class SignalDeath(BaseException):
    """What the stand-in raises where a real signal would have killed the process (its
    default action): it fails the test instead of ending pytest."""


class FakeSignals:
    """Python's ``signal`` module as ``tcr_accuracy.cli.signals`` uses it, with no real signal:
    the handlers live in a dict, and :meth:`send` runs the one installed for a signal at once, in
    the calling thread, as Python runs a handler for a signal a process sends itself (at the next
    bytecode of the main thread). A signal whose handler is the default one raises
    :class:`SignalDeath`, as the process would have died; SIGINT starts with Python's handler
    (KeyboardInterrupt)."""

    SIG_DFL, SIG_IGN = signal.SIG_DFL, signal.SIG_IGN

    def __init__(self):
        self.handlers = {signal.SIGINT: signal.default_int_handler}  # as Python starts: Ctrl-C raises
        self.sent = []  # by the test (kill from outside)
        self.raised = []  # by the code under test (signal.raise_signal)
        for name in ("SIGINT", "SIGTERM", "SIGHUP"):
            setattr(self, name, getattr(signal, name))

    def signal(self, signum, handler):
        previous = self.handlers.get(signum, self.SIG_DFL)
        self.handlers[signum] = handler
        return previous

    def getsignal(self, signum):
        return self.handlers.get(signum, self.SIG_DFL)

    def send(self, signum):
        """Deliver ``signum`` to this (pretend) process now, as another process would."""
        self.sent.append(signum)
        self._deliver(signum)

    def raise_signal(self, signum):
        """``signal.raise_signal``: the process sends ``signum`` to itself."""
        self.raised.append(signum)
        self._deliver(signum)

    def _deliver(self, signum):
        handler = self.getsignal(signum)
        if handler in (self.SIG_DFL, None):
            raise SignalDeath(f"signal {signal.Signals(signum).name} with its default action: the process dies")
        if handler != self.SIG_IGN:
            handler(signum, None)


@pytest.fixture
def fake_signals(monkeypatch):
    """A :class:`FakeSignals` standing in for the ``signal`` module the command line's signal
    helper (``tcr_accuracy.cli.signals``) installs its handlers with; send signals with
    ``fake_signals.send(fake_signals.SIGTERM)``."""
    from tcr_accuracy.cli import signals

    fake = FakeSignals()
    monkeypatch.setattr(signals, "signal", fake)
    return fake
