"""Checks of training data that the estimators share."""

from __future__ import annotations

from ..exceptions import InputError


def check_enough_points(n_samples: int, n_features: int, who: str) -> None:
    """Raise InputError unless there are more training rows than joints (features)."""
    if n_samples <= n_features:
        raise InputError(
            f"{who}: needs more training points than joints, got n_samples = {n_samples} for "
            f"{n_features} joints; measure at least {n_features + 1} (the seed used 160 for 6)")


def check_joints_and_position_errors(robot, X, y, who: str) -> None:
    """Raise InputError unless there is a robot, X is (n, robot.n_joints) joint values and y
    is (n, 3) position errors [m], as the robot-model estimators need."""
    if robot is None:
        raise InputError(f"{who} needs a robot")
    if y.ndim != 2 or y.shape[1] != 3 or X.shape[1] != robot.n_joints:
        raise InputError(f"{who}: needs joint values (n, {robot.n_joints}) and position errors (n, 3), got "
                         f"{X.shape} (n_samples = {X.shape[0]}, n_features = {X.shape[1]}) and {y.shape}")


#: scikit-learn's estimator checks that fit on data of their own shape (2 to 10 features of random
#: numbers, 1-D or 5-column targets, 1 sample): an estimator of one robot's kinematics takes that
#: robot's joint values (n, n_joints) and position errors (n, 3), and refuses anything else with an
#: InputError. Each is declared an expected failure with this reason (``check_estimator(estimator,
#: expected_failed_checks=expected_failed_checks(estimator))``); every other check must pass.
SHAPE_CHECKS = (
    "check_fit_score_takes_y", "check_estimators_overwrite_params", "check_dont_overwrite_parameters",
    "check_estimators_fit_returns_self", "check_readonly_memmap_input", "check_n_features_in_after_fitting",
    "check_positive_only_tag_during_fit", "check_estimators_dtypes", "check_dtype_object",
    "check_pipeline_consistency", "check_estimators_nan_inf", "check_estimators_pickle",
    "check_f_contiguous_array_estimator", "check_regressors_train", "check_regressor_data_not_an_array",
    "check_regressor_multioutput", "check_regressors_no_decision_function", "check_supervised_y_2d",
    "check_regressors_int", "check_methods_sample_order_invariance", "check_methods_subset_invariance",
    "check_dict_unchanged", "check_fit_idempotent", "check_fit_check_is_fitted", "check_n_features_in",
    "check_fit2d_predict1d")
#: The same for the estimators that turn joint values into TCP positions in a first step (the
#: ``*-cartesian`` pipelines): the step refuses other shapes before the target is looked at, and in
#: the words of the joint values (not scikit-learn's ``n_samples = 1``), so the checks of the
#: target's NaN and of one-sample and one-feature data fail too.
PIPELINE_SHAPE_CHECKS = SHAPE_CHECKS + ("check_supervised_y_no_nan", "check_fit2d_1sample", "check_fit2d_1feature")
WHY = "fits on random data of its own shape; this estimator takes one robot's joint values (n, n_joints)"


def expected_failed_checks(estimator) -> dict:
    """{check name: reason} of scikit-learn's estimator checks ``estimator`` cannot pass: those of
    :data:`SHAPE_CHECKS` for an estimator of one robot's kinematics (a ``robot`` parameter, a
    composition with one, a pipeline whose first step needs one), nothing for the others.

    Parameters
    ----------
    estimator : scikit-learn estimator
        One of :func:`~tcr_accuracy.prediction.methods.make_predictor`'s.

    Returns
    -------
    dict of str to str
    """
    steps = getattr(estimator, "steps", None)
    if steps is not None:
        return {c: WHY for c in PIPELINE_SHAPE_CHECKS} if any(_kinematic(s) for _, s in steps) else {}
    return {c: WHY for c in SHAPE_CHECKS} if _kinematic(estimator) else {}


def _kinematic(estimator) -> bool:
    params = estimator.get_params(deep=False) if hasattr(estimator, "get_params") else {}
    return params.get("robot") is not None or any(_kinematic(v) for v in params.values() if hasattr(v, "get_params"))
