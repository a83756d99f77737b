"""A fit as the engine keeps it between the stages: its parameters, scores and per-row squared
held-out errors, with the per-row residual arrays made again only when a stage reads them.

A diagnosis fits some 70 models, and the paired tests that compare them read one (N,) array per
model (each row's squared held-out error, :func:`~tcr_accuracy.diagnosis.paired.row_squares`);
kept whole, each model's training and held-out residuals ((N, 3) each, with orientation rows and
every fold assignment's) were 430 MB of the diagnosis' 2.3 GB at 10^5 poses. The few stages that
read the arrays themselves (the structure tests, the residual analysis of the final model) get them
remade from the fit's parameters and its folds' steps, by the same computation, to the same floats.
Figures few models are asked for (the standard errors, an eigendecomposition of the model's Gram
matrix) are made when first read.
"""

from __future__ import annotations

from typing import Callable

#: the per-row arrays of a fit (:meth:`~tcr_accuracy.diagnosis.fitting.FitEngine.evaluate`) made on demand
RESIDUAL_KEYS = frozenset({"train_residual", "heldout_residual", "heldout_repeats", "train_orientation",
                           "heldout_orientation"})


class FitResult(dict):
    """The dict :meth:`~tcr_accuracy.diagnosis.fitting.FitEngine.evaluate` returns, without its
    per-row residual arrays (:data:`RESIDUAL_KEYS`): reading one of those calls ``remake(self)``, which
    returns all of them (the engine keeps the last fit's so that a stage reading several remakes once).
    ``lazy``: key -> a function making that figure when it is first read (then kept)."""

    def __init__(self, fields: dict, remake: Callable[["FitResult"], dict], lazy: dict | None = None):
        super().__init__({k: v for k, v in fields.items() if k not in RESIDUAL_KEYS})
        self._remake = remake
        self._lazy = dict(lazy or {})

    def __missing__(self, key):
        if key in self._lazy:
            value = self._lazy.pop(key)()
            self[key] = value
            return value
        if key not in RESIDUAL_KEYS:
            raise KeyError(key)
        return self._remake(self)[key]

    def __contains__(self, key) -> bool:
        return dict.__contains__(self, key) or key in self._lazy or key in RESIDUAL_KEYS

    def get(self, key, default=None):
        return self[key] if key in self else default
