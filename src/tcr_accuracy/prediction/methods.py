"""The prediction methods by name: the one list the commands, scripts and tests choose from.

:data:`METHODS` names every predictor :func:`make_predictor` builds; :data:`DEFAULT_METHOD`
is the one ``predict`` and ``compensate`` use unless told. Each method is an estimator
mapping joint values (n, n_joints) [rad, m] to TCP position errors (n, 3) [m].

This module imports no heavy library at load time: the command-line parser reads
:data:`METHODS` for ``--method`` and ``--help`` stays instant, so :func:`make_predictor`
imports the estimator modules (scikit-learn, Pinocchio) when it is called.
"""

from __future__ import annotations

from ..exceptions import InputError

METHODS = ("kriging", "kriging-pf", "gp", "local-gp", "idw-joint", "idw-cartesian", "mlp-cartesian", "calibration",
           "calibration+gp", "calibration+local-gp", "diagnosis", "diagnosis+gp")

#: the diagnosis' fitted effect model plus a Gaussian process of what it leaves
DEFAULT_METHOD = "diagnosis+gp"


def make_predictor(method: str, robot, *, random_state=None):
    """A fresh estimator by name (see METHODS)."""
    from .baselines import InverseDistanceWeighting, make_cartesian_idw, make_cartesian_mlp
    from .calibration import DiagnosisCalibration, GeometricCalibration
    from .composed import ResidualCorrected
    from .gaussian_process import make_gaussian_process
    from .kriging import JointKriging
    from .local_gp import LocalGaussianProcess

    if method == "kriging":
        return JointKriging()
    if method == "kriging-pf":
        return JointKriging(weight_search="particle_filter", random_state=random_state)
    if method == "gp":
        return make_gaussian_process(robot.n_joints, random_state=random_state)
    if method == "local-gp":
        return LocalGaussianProcess(random_state=random_state)
    if method == "idw-joint":
        return InverseDistanceWeighting()
    if method == "idw-cartesian":
        return make_cartesian_idw(robot)
    if method == "mlp-cartesian":
        return make_cartesian_mlp(robot, random_state=random_state)
    if method == "calibration":
        return GeometricCalibration(robot=robot)
    if method == "calibration+gp":
        return ResidualCorrected(base=GeometricCalibration(robot=robot),
                                 residual=make_gaussian_process(robot.n_joints, random_state=random_state))
    if method == "calibration+local-gp":
        return ResidualCorrected(base=GeometricCalibration(robot=robot),
                                 residual=LocalGaussianProcess(random_state=random_state))
    if method == "diagnosis":
        return DiagnosisCalibration(robot=robot, random_state=random_state)
    if method == "diagnosis+gp":
        return ResidualCorrected(base=DiagnosisCalibration(robot=robot, random_state=random_state),
                                 residual=make_gaussian_process(robot.n_joints, random_state=random_state))
    raise InputError(f"unknown prediction method {method!r}; choose one of {', '.join(METHODS)}")
