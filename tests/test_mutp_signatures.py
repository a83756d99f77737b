"""Keyword-only parameters of the diagnosis' and the pose design's functions stay keyword-only (issue 36; the
project's style: keyword-only options, scikit-learn's conventions for estimators): a ``*`` marker turned into
``/`` (a planted change cosmic-ray makes of the ``*``) would let a positional call bind a tolerance or a
count to the wrong option without a word. The marker's place is written out here per function (as the
signatures read at this commit), not read from the source at test time."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from tcr_accuracy.diagnosis import bayes_design, compare, design, diagnose
from tcr_accuracy.diagnosis.stages import candidates, search, select, setup
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.robot import load_robot

# (function, its positional parameters in order, its first keyword-only parameter)
SIGNATURES = [
    (bayes_design.design_columns, ["robot", "q", "effects"], "payload_kg"),
    (bayes_design.fit_prior, ["columns", "errors"], "noise_m"),
    (bayes_design.plan_design, ["measured", "candidates", "task", "prior", "k"], "criterion"),
    (bayes_design.learning_curve, ["columns", "errors", "prior", "rng"], "n_sizes"),
    (bayes_design.stop_advice, ["curve", "design"], "min_gain_m"),
    (design.plan_poses, ["robot", "measured_q", "effects", "k"], "separate"),
    (design.plan_discriminating_poses, ["robot", "measured_q", "rivals", "k"], "candidates"),
    (compare.compare_models, ["robot", "old", "new", "q"], "z"),
    (diagnose.diagnose, ["robot", "measurements"], "effects"),
    (diagnose.GapDiagnosis.__init__, ["self"], "robot"),
    (diagnose.GapDiagnosis.fit, ["self", "measurements", "y"], "progress"),
    (select.select_effects, ["registered", "candidate_set"], "selection_z"),
    (search.search_sets, ["engine", "greedy", "first", "testable"], "forward"),
    (search.beam, ["engine", "testable"], "entry"),
    (setup.compare_setups, ["registered", "folds"], "rank_tol"),
    (candidates.build_candidates, ["registered", "names"], "folds"),
]


@pytest.mark.parametrize("function, positional, first_keyword", SIGNATURES,
                         ids=[f"{f.__module__.rsplit('.', 1)[-1]}.{f.__qualname__}" for f, _, _ in SIGNATURES])
def test_options_after_the_star_are_keyword_only(function, positional, first_keyword):
    """The positional parameters may also be named (none positional-only), and every parameter from the first
    option on is keyword-only. Seen failing on ``fit_prior(columns, errors, *, noise_m=None)`` turned to
    ``(columns, errors, /, noise_m=None)`` and on GapDiagnosis' ``__init__(self, *, robot=None, ...)`` turned to
    ``(self, /, robot=None, ...)`` (planted by hand)."""
    parameters = list(inspect.signature(function).parameters.values())
    leading = [p for p in parameters if p.kind is p.POSITIONAL_OR_KEYWORD]
    assert [p.name for p in leading] == positional
    assert not [p for p in parameters if p.kind is p.POSITIONAL_ONLY]
    options = [p for p in parameters if p.kind is p.KEYWORD_ONLY]
    if first_keyword is not None:
        assert options and options[0].name == first_keyword
    assert len(leading) + len(options) == len([p for p in parameters if p.kind not in (p.VAR_POSITIONAL,
                                                                                          p.VAR_KEYWORD)])


def _small_columns(n=6):
    owner = np.array(["frames"] * 2 + ["compliance"] * 2)
    g = np.random.default_rng(4).normal(size=(n, 3, 4)) * 1e-3
    return bayes_design.DesignColumns(g, owner, ["frames", "compliance"])


def _calls():
    """(function, a call by position past its positional parameters, the same call with the options named and
    what it must give): the named call runs the function's body (a mutant of its signature then runs this
    test), the positional one must be refused before."""
    robot = load_robot()
    q = np.zeros((3, robot.n_joints))
    columns = _small_columns()
    errors = np.zeros((6, 3))
    return [
        (bayes_design.fit_prior, lambda: bayes_design.fit_prior(columns, errors, 1e-5),
         lambda: bayes_design.fit_prior(columns, errors, noise_m=1e-5).noise_m == 1e-5),
        (bayes_design.design_columns, lambda: bayes_design.design_columns(robot, q, ["frames"], 0.0),
         lambda: bayes_design.design_columns(robot, q, ["frames"], payload_kg=0.0).g.shape == (3, 3, 9)),
        (bayes_design.learning_curve,
         lambda: bayes_design.learning_curve(columns, errors, bayes_design.typical_prior(["compliance"]),
                                             np.random.default_rng(0), 5),
         lambda: _refused(lambda: bayes_design.learning_curve(
             columns, errors, bayes_design.typical_prior(["compliance"]), np.random.default_rng(0), n_sizes=5))),
        (design.plan_poses, lambda: design.plan_poses(robot, q, ["joint_offsets"], 0, None),
         lambda: _refused(lambda: design.plan_poses(robot, q, ["joint_offsets"], 0, separate=None))),
        (design.plan_discriminating_poses, lambda: design.plan_discriminating_poses(robot, q, [], 0, q),
         lambda: _refused(lambda: design.plan_discriminating_poses(robot, q, [], 0, candidates=q))),
        (diagnose.diagnose, lambda: diagnose.diagnose(robot, None, None),
         lambda: _refused(lambda: diagnose.diagnose(robot, None, effects=None))),
        (diagnose.GapDiagnosis.__init__, lambda: diagnose.GapDiagnosis(robot),
         lambda: diagnose.GapDiagnosis(robot=robot).robot is robot),
        (diagnose.GapDiagnosis.fit, lambda: diagnose.GapDiagnosis().fit(None, None, None),
         lambda: _refused(lambda: diagnose.GapDiagnosis().fit(None, None, progress=None))),
    ]


def _refused(call) -> bool:
    """Whether the call stops with an InputError (bad input, inside the function's body)."""
    try:
        call()
    except InputError:
        return True
    return False


def test_options_cannot_be_given_by_position():
    """Each function called with an option by position is refused (TypeError), named it runs (the body's own
    answer or its InputError on the bad input given). Seen failing on ``fit_prior(columns, errors, *,
    noise_m=None)`` turned to ``(columns, errors, /, noise_m=None)``, on ``GapDiagnosis.__init__(self, *,
    robot=None, ...)`` turned to ``(self, /, robot=None, ...)`` and on plan_poses' ``k: int, *, separate=None``
    turned to ``k: int, /, separate=None`` (planted by hand)."""
    for function, positional, named in _calls():
        with pytest.raises(TypeError):
            positional()
        assert named(), function.__qualname__
