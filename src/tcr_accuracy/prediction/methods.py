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
           "calibration+gp", "calibration+local-gp", "diagnosis", "diagnosis+gp", "bayes")

#: the diagnosis' fitted effect model plus a Gaussian process of what it leaves
DEFAULT_METHOD = "diagnosis+gp"


def make_predictor(method: str, robot, *, random_state=None):
    """A fresh, unfitted estimator by name.

    Parameters
    ----------
    method : str
        One of :data:`METHODS` (``kriging``, ``gp``, ``diagnosis+gp``, ...).
    robot : RobotModel
        The nominal robot (the methods that model its kinematics take it as a parameter).
    random_state : int, numpy.random.Generator or None, default=None
        Passed to every estimator in it that draws random numbers.

    Returns
    -------
    estimator
        A scikit-learn estimator: ``fit(Q (n, n_joints) [rad, m], E (n, 3) [m])``,
        ``predict(Q) -> (m, 3)`` TCP position errors [m]; ``sklearn.base.clone`` copies it.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> tcr.make_predictor("gp", robot, random_state=0).get_params()["random_state"]
    0
    """
    from .baselines import InverseDistanceWeighting, make_cartesian_idw, make_cartesian_mlp
    from .bayesian import BayesianCalibration
    from .calibration import DiagnosisCalibration, GeometricCalibration
    from .composed import ResidualCorrected
    from .gaussian_process import make_gaussian_process
    from .kriging import JointKriging
    from .local_gp import LocalGaussianProcess

    if method == "kriging":
        return JointKriging(random_state=random_state)
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
    if method == "bayes":
        return BayesianCalibration(robot=robot)
    raise InputError(f"unknown prediction method {method!r}; choose one of {', '.join(METHODS)}")
