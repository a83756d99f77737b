"""Keyword-only options of the pose design's, the comparison's and the selection stages' functions, checked by
CALLING each (tests/test_mutp_signatures.py reads the signatures, which runs no function body, so a mutant of a
signature line -- cosmic-ray turns the ``*`` marker into ``/`` -- ran none of its tests): each function is
called with every argument named, which must reach its body (a stand-in input raises :class:`Reached` at the
first attribute the body reads), and with an option by position, which must be refused (TypeError) before.
Seen failing on ``k: int, *, criterion`` -> ``k: int, /, criterion`` in ``plan_design`` (the survivor of seed
3700) and on the same turn in ``beam``, ``compare_setups`` and ``select_effects`` (planted by hand)."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis import bayes_design, compare
from tcr_accuracy.diagnosis.stages import candidates, search, select, setup


class Reached(Exception):
    """The function's body was entered."""


class Tripwire:
    """Any attribute read, call, iteration or index raises :class:`Reached`."""

    def __getattr__(self, name):
        raise Reached(name)

    def __iter__(self):
        raise Reached("iter")

    def __getitem__(self, key):
        raise Reached("getitem")

    def __len__(self):
        raise Reached("len")

    def __array__(self, *args, **kwargs):
        raise Reached("array")


T = Tripwire()
_curve = bayes_design.LearningCurve(sizes=np.array([10]), rms_m=np.ones(1), low_m=np.ones(1), high_m=np.ones(1),
                                    expected_rms_m=np.ones(1), noise_weight=1.0, variance_weight=1.0,
                                    boot=np.ones((4, 2)), noise_floor_m=1e-3)

# (name, the call with every argument named, the call with the first option by position)
CALLS = [
    ("plan_design", lambda: bayes_design.plan_design(measured=None, candidates=T, task=T, prior=T, k=1, criterion="D"),
     lambda: bayes_design.plan_design(None, T, T, T, 1, "D")),
    ("stop_advice", lambda: bayes_design.stop_advice(curve=_curve, design=T, min_gain_m=None),
     lambda: bayes_design.stop_advice(_curve, T, None)),
    ("compare_models", lambda: compare.compare_models(robot=T, old=T, new=T, q=T, z=3.0),
     lambda: compare.compare_models(T, T, T, T, 3.0)),
    ("select_effects", lambda: select.select_effects(registered=T, candidate_set=T, selection_z=3.0,
                                                     min_relative_gain=0.0),
     lambda: select.select_effects(T, T, 3.0, 0.0)),
    ("search_sets", lambda: search.search_sets(engine=T, greedy=["frames"], first=None, testable=[], forward=None,
                                               prune=None, selection_z=3.0, min_relative_gain=0.0),
     lambda: search.search_sets(T, ["frames"], None, [], None, None, 3.0, 0.0)),
    ("beam", lambda: search.beam(engine=T, testable=[], entry=None, width=1),
     lambda: search.beam(T, [], None, 1)),
    ("compare_setups", lambda: setup.compare_setups(registered=T, folds=[], rank_tol=1e-6, min_motion=1e-6),
     lambda: setup.compare_setups(T, [], 1e-6, 1e-6)),
    ("build_candidates", lambda: candidates.build_candidates(registered=T, names=["frames"], folds=3, rank_tol=1e-6,
                                                             tracker_noise=None, rng=None),
     lambda: candidates.build_candidates(T, ["frames"], 3, 1e-6, None, None)),
]


@pytest.mark.parametrize("name, named, positional", CALLS, ids=[c[0] for c in CALLS])
def test_named_calls_reach_the_body_and_options_by_position_are_refused(name, named, positional):
    """Named: the body runs (Reached); an option by position: TypeError before the body."""
    with pytest.raises(Reached):
        named()
    with pytest.raises(TypeError, match="positional argument"):
        positional()
