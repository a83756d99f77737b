"""Keyword-only parameters of the diagnosis' and the pose design's functions stay keyword-only (issue 36; the
project's style: keyword-only options, scikit-learn's conventions for estimators): a ``*`` marker turned into
``/`` (a planted change cosmic-ray makes of the ``*``) would let a positional call bind a tolerance or a
count to the wrong option without a word. The marker's place is written out here per function (as the
signatures read at this commit), not read from the source at test time."""

from __future__ import annotations

import inspect

import pytest

from tcr_accuracy.diagnosis import bayes_design, compare, design, diagnose
from tcr_accuracy.diagnosis.stages import candidates, search, select, setup

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
