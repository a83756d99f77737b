"""The diagnosis' hyper-parameters are refused exactly outside their stated ranges, at each end.

Each range is written out here, as a user reads it: folds >= 2 (a k-fold split needs two folds);
a tracker noise in (0, 1] m; a selection z in (0, 100); a relative gain in [0, 1); a rank tolerance
in (0, 1); an orientation weight in (0, 1000) m/rad; 1 to 100,000 stability replays (a frequency
needs a replay); 1 to 1,000 fold assignments. Each end is tried on its value and just past it, so
a bound moved by one unit (a planted ``Interval(Integral, 2, ...)`` -> ``3``, ``100_000`` ->
``100_001``, ``1e3`` -> ``1001``, ``0`` -> ``-1``) or opened where it was closed fails a case.
"""

import pytest

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.hyperparameters import validate_hyperparameters

#: parameter -> (values accepted, values refused)
RANGES = {
    "folds": ([2, 3, 10], [1, 0, -2]),
    "tracker_noise": ([None, 1e-9, 2e-5, 1.0], [0.0, -1e-9, 1.0 + 1e-9, 1.5]),
    "selection_z": ([1e-9, 0.5, 3.0, 99.999], [0.0, -1e-9, 100.0, 100.5]),
    "min_relative_gain": ([0.0, 1e-9, 0.5, 0.999], [-1e-9, -0.5, 1.0, 1.5]),
    "rank_tol": ([1e-12, 1e-6, 0.5, 0.999], [0.0, -1e-9, 1.0, 1.5]),
    "orientation_weight": ([None, 1e-9, 0.5, 999.9], [0.0, -1e-9, 1000.0, 1000.5]),
    "stability_replays": ([1, 50, 100_000], [0, -1, 100_001]),
    "fold_repeats": ([None, 1, 5, 1000], [0, -1, 1001]),
}


@pytest.mark.parametrize("name", sorted(RANGES))
def test_each_hyperparameter_is_accepted_inside_its_range_and_refused_just_outside(name):
    accepted, refused = RANGES[name]
    for value in accepted:
        validate_hyperparameters(GapDiagnosis(**{name: value}))  # no error
    for value in refused:
        with pytest.raises(InputError) as caught:
            validate_hyperparameters(GapDiagnosis(**{name: value}))
        assert caught.value.parameter == name, (name, value)
        assert caught.value.value == value
        assert f"'{name}' parameter of GapDiagnosis" in str(caught.value)


def test_the_defaults_are_the_documented_ones_and_inside_their_ranges():
    """The class docstring's defaults (folds 5, selection z 3.0, gain 0.002, rank tolerance 1e-6,
    50 replays), read from the estimator a user makes with no argument."""
    params = GapDiagnosis().get_params()
    assert (params["folds"], params["selection_z"], params["min_relative_gain"], params["rank_tol"],
            params["stability_replays"]) == (5, 3.0, 0.002, 1e-6, 50)
    assert params["tracker_noise"] is None and params["orientation_weight"] is None
    assert params["fold_repeats"] is None and params["random_state"] == 0
    validate_hyperparameters(GapDiagnosis())
