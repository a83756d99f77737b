"""Which error matters, globally: Sobol indices of the TCP error, from SALib.

Variance-based global sensitivity of the TCP error to every random input at once (the
sources of an :class:`~tcr_accuracy.model.errors.ErrorBudget`, or the d, s, theta, w_x, w_y of
each joint of a :class:`~tcr_accuracy.model.clearance.ClearanceModel`, as listed by
:func:`~tcr_accuracy.analysis.random_inputs.random_inputs`): first order S1 and total ST with
bootstrap confidence intervals, from SALib (Saltelli sampling; Saltelli 2010 estimator
for S1, Jansen for ST). SALib samples the unit hypercube; each column is mapped through
the input's inverse CDF (:meth:`ErrorSource.ppf`), so any distribution works. Next to
them, the first-order (Jacobian) prediction of S1 for a linear sampler.

Outputs are the columns :data:`tcr_accuracy.analysis.sensitivity.OUTPUTS` (m, then rad).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..exceptions import InputError
from ..model.jacobians import error_jacobian
from ..model.kinematics import tcp_poses
from .random_inputs import RandomInputs, random_inputs
from .sensitivity import OUTPUTS, error_columns


@dataclass(frozen=True)
class SobolIndices:
    """Variance-based sensitivity of the TCP error to the random inputs of a sampler.

    Attributes
    ----------
    source_names, groups : list of str, length n_inputs
    outputs : tuple of str, length n_outputs (subset of :data:`OUTPUTS`)
    first_order, first_order_conf, total_order, total_order_conf : ndarray of shape
        (n_outputs, n_inputs). NaN for an output whose variance is zero.
    variance : ndarray of shape (n_outputs,)
        Variance of each output over the Sobol sample [m^2 or rad^2].
    linear_share : ndarray of shape (3, n_inputs)
        First-order (Jacobian) prediction of S1 for dx, dy, dz: ``(J a_k)^2 var_k``
        over its sum; equal to S1 when the TCP error is linear in the inputs. NaN for
        samplers that are not linear in their inputs (clearance).
    n_base : int
        SALib's base sample size N; the model was evaluated N (n_inputs + 2) times.
    conf_level : float
    """

    source_names: list[str]
    groups: list[str]
    outputs: tuple[str, ...]
    first_order: np.ndarray
    first_order_conf: np.ndarray
    total_order: np.ndarray
    total_order_conf: np.ndarray
    variance: np.ndarray
    linear_share: np.ndarray
    n_base: int
    conf_level: float

    @property
    def n_evaluations(self) -> int:
        return self.n_base * (len(self.source_names) + 2)

    def ranking(self, output: str = "norm") -> list[int]:
        """Input indices by decreasing total index ST for one output."""
        k = self.outputs.index(output)
        return [int(i) for i in np.argsort(-np.nan_to_num(self.total_order[k], nan=-1.0), kind="stable")]


def linear_variance_shares(inputs: RandomInputs, q: np.ndarray) -> np.ndarray:
    """(3, n_inputs) first-order variance share of each input in dx, dy, dz.

    From Pinocchio's error Jacobian J (3 position rows, n_params): input k moves the
    TCP by ``J a_k`` per unit, so its variance contribution is ``(J a_k)^2 var_k``.
    """
    n = len(inputs.sources)
    if inputs.matrix is None:
        return np.full((3, n), np.nan)
    jac = error_jacobian(inputs.error_model.robot, q, inputs.error_model)[:3]
    contrib = (jac @ inputs.matrix) ** 2 * np.array([s.variance for s in inputs.sources])
    total = contrib.sum(axis=1, keepdims=True)
    return np.where(total > 0, contrib / np.where(total > 0, total, 1.0), np.nan)


def sobol_indices(sampler, q: np.ndarray, n_base: int = 1024, seed: int = 0,
                  outputs: Sequence[str] = OUTPUTS, num_resamples: int = 100,
                  conf_level: float = 0.95, chunk: int = 100_000,
                  progress: Callable[[int], None] | None = None) -> SobolIndices:
    """First-order and total Sobol indices of every random input, via SALib.

    Parameters
    ----------
    sampler : ErrorBudget or ClearanceModel
        Its independent inputs (see :func:`random_inputs`) are the Sobol factors.
    q : ndarray of shape (n_joints,)
        Joint values [rad, m].
    n_base : int
        SALib's base sample size N, a power of two (Sobol sequences balance only then);
        the kinematics runs N (n_inputs + 2) times.
    seed : int
        Seeds SALib's scrambled Sobol sequence and its bootstrap.
    outputs : names from :data:`OUTPUTS`
    num_resamples, conf_level : bootstrap settings of the confidence intervals.
    chunk : model evaluations per batch (bounds the memory).
    progress : callable, optional, called with the number of evaluations done per batch.
    """
    from SALib.analyze import sobol as sobol_analyze
    from SALib.sample import sobol as sobol_sample

    if n_base < 2 or n_base & (n_base - 1):
        raise InputError(f"Sobol base sample size {n_base}: must be a power of two >= 2 (e.g. 1024)")
    unknown = [o for o in outputs if o not in OUTPUTS]
    if unknown:
        raise InputError(f"unknown Sobol output(s) {', '.join(unknown)} (known: {', '.join(OUTPUTS)})")
    inputs = random_inputs(sampler)
    d = len(inputs.sources)
    if d == 0:
        raise InputError("Sobol indices: the error budget has no sources")
    problem = {"num_vars": d, "names": [f"x{k}" for k in range(d)], "bounds": [[0.0, 1.0]] * d}
    u = sobol_sample.sample(problem, n_base, calc_second_order=False, seed=seed)
    bootstrap_seed = int(np.random.SeedSequence([seed, 1]).generate_state(1)[0]) | 1
    robot, em = inputs.error_model.robot, inputs.error_model
    nominal = tcp_poses(robot, q)
    cols = [OUTPUTS.index(o) for o in outputs]
    y = np.empty((u.shape[0], len(cols)))
    for start in range(0, u.shape[0], chunk):
        x = inputs.to_parameters(inputs.values_from_unit(u[start:start + chunk]))
        y[start:start + chunk] = error_columns(robot, q, x, em, nominal)[:, cols]
        if progress is not None:
            progress(min(chunk, u.shape[0] - start))
    shape = (len(cols), d)
    s1, s1c, st, stc = (np.full(shape, np.nan) for _ in range(4))
    variance = y.var(axis=0)
    for k in range(len(cols)):
        # an output the inputs cannot move (e.g. an angle under pure translations): no indices
        if variance[k] <= 1e-24 * max(1e-300, float(np.mean(y[:, k] ** 2))):
            continue
        # SALib reads ``if seed:``, so seed 0 would give unseeded bootstrap intervals: pass
        # a never-zero seed derived from ours (odd), so that every seed repeats exactly
        res = sobol_analyze.analyze(problem, y[:, k], calc_second_order=False, num_resamples=num_resamples,
                                    conf_level=conf_level, seed=bootstrap_seed)
        s1[k], s1c[k], st[k], stc[k] = res["S1"], res["S1_conf"], res["ST"], res["ST_conf"]
    return SobolIndices(
        source_names=inputs.names, groups=inputs.groups, outputs=tuple(outputs),
        first_order=s1, first_order_conf=s1c, total_order=st, total_order_conf=stc, variance=variance,
        linear_share=linear_variance_shares(inputs, q), n_base=n_base, conf_level=conf_level,
    )
