"""``diagnose()``, the function form, hands the estimator the defaults its docstring states.

A stand-in estimator records the keywords ``diagnose`` passes on: called with only a robot and
measurements, they must be the documented defaults (5 folds, seed 0, the noise estimated, z 3.0,
a relative gain of 0.002, a rank tolerance of 1e-6, the orientation weight from the data), written
out here. Seen failing on ``folds: int = 5`` -> ``6``, ``selection_z: float = 3.0`` -> ``4.0``,
``min_relative_gain`` 0.002 -> 1.002 and ``rank_tol`` 1e-6 -> 1.000001 in ``diagnose``'s signature.

And the estimator's repr: scikit-learn's at its default width of 700 characters, on one line (seen
failing on ``N_CHAR_MAX=700`` -> ``699``).
"""

from types import SimpleNamespace

from sklearn.base import BaseEstimator

from tcr_accuracy.diagnosis import diagnose as diagnose_module

DOCUMENTED = {"effects": None, "folds": 5, "random_state": 0, "tracker_noise": None, "selection_z": 3.0,
              "min_relative_gain": 0.002, "rank_tol": 1e-6, "orientation_weight": None, "instrument": None,
              "tcp_offset": None}


class _Recorder:
    made = []

    def __init__(self, **keywords):
        self.keywords = keywords
        _Recorder.made.append(self)

    def fit(self, measurements, *, progress=None, references=()):
        self.fitted = (measurements, progress, references)
        self.result_ = SimpleNamespace(marker="result")
        return self


def test_the_function_form_passes_the_documented_defaults(monkeypatch):
    monkeypatch.setattr(diagnose_module, "GapDiagnosis", _Recorder)
    _Recorder.made.clear()
    robot, measurements = object(), object()
    result = diagnose_module.diagnose(robot, measurements)
    (made,) = _Recorder.made
    assert made.keywords == {"robot": robot, **DOCUMENTED}
    assert made.fitted == (measurements, None, ())
    assert result.marker == "result"


def test_the_function_form_passes_what_it_is_given(monkeypatch):
    monkeypatch.setattr(diagnose_module, "GapDiagnosis", _Recorder)
    _Recorder.made.clear()
    given = {"effects": ["compliance"], "folds": 3, "random_state": 7, "tracker_noise": 2e-5, "selection_z": 2.5,
             "min_relative_gain": 0.01, "rank_tol": 1e-8, "orientation_weight": 0.4, "instrument": "tracker",
             "tcp_offset": [0.0, 0.0, 0.1]}
    progress = print
    diagnose_module.diagnose("robot", "data", progress=progress, references=("ref",), **given)
    (made,) = _Recorder.made
    assert made.keywords == {"robot": "robot", **given}
    assert made.fitted == ("data", progress, ("ref",))


def test_the_repr_is_scikit_learns_at_700_characters_on_one_line():
    long_effects = [f"effect_number_{i:03d}" for i in range(80)]  # a parameter list far past 700 characters
    estimator = diagnose_module.GapDiagnosis(effects=long_effects, folds=3)
    expected = " ".join(BaseEstimator.__repr__(estimator, N_CHAR_MAX=700).split())
    assert repr(estimator) == expected
    assert "..." in expected and "\n" not in repr(estimator)
    # scikit-learn keeps N_CHAR_MAX // 2 characters at each end: 699 keeps one fewer (701 the same 350)
    assert repr(estimator) != " ".join(BaseEstimator.__repr__(estimator, N_CHAR_MAX=699).split())
