"""The small linear algebra under the fit engine: damped Gauss-Newton steps from a fixed Gram
matrix, and the box-constrained quadratic step where bounds stop the free one.

Hand-written on the normal equations (see :meth:`~tcr_accuracy.diagnosis.fitting.FitEngine._minimise`
for why): one eigendecomposition of the small Gram matrix serves every iteration and damping.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from scipy.linalg import get_lapack_funcs


class DampedSolver:
    """Levenberg-Marquardt steps from a fixed Gram matrix J^T J (k, k): columns scaled to
    unit norm, one eigendecomposition, so that a step for any damping is two small products
    (and a small box-constrained least squares when bounds stop the free step)."""

    def __init__(self, gram: np.ndarray):
        self.norms = np.sqrt(np.clip(np.diag(gram), 0.0, None))
        self.norms[self.norms == 0] = 1.0
        self.values, self.vectors = np.linalg.eigh(gram / np.outer(self.norms, self.norms))
        top = float(self.values[-1]) if self.values.size else 0.0
        # eigenvalues within round-off of zero carry no information (lstsq drops them too)
        self.kept = self.values > top * self.values.size * np.finfo(float).eps * 10
        self.top = top
        # (a zero Gram matrix keeps no eigenvalue: every step is zero and the damping never read)
        self.first_damping = 1e-3 * top

    def step(self, gradient: np.ndarray, damping: float, room_low: np.ndarray | None = None,
             room_high: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """The step d minimising |r + J d|^2 + damping |D d|^2 (D: the column norms) for
        gradient J^T r, with room_low <= d <= room_high when given, and the cost cut the
        linear model predicts for it."""
        scaled = gradient / self.norms
        c = self.vectors.T @ scaled
        coefficient = np.zeros_like(c)
        coefficient[self.kept] = -c[self.kept] / (self.values[self.kept] + damping)
        d = (self.vectors @ coefficient) / self.norms
        if room_low is not None and (np.any(d < room_low) or np.any(d > room_high)):
            d = self._boxed(scaled, damping, room_low, room_high)
            coefficient = self.vectors.T @ (d * self.norms)
        predicted = -float(2.0 * gradient @ d + np.clip(self.values, 0.0, None) @ coefficient**2)
        return d, predicted

    def _boxed(self, scaled_gradient, damping, room_low, room_high) -> np.ndarray:
        """The damped quadratic model minimised inside the box, in the scaled coordinates."""
        curvature = np.clip(self.values, 0.0, None) + max(damping, 1e-10 * self.top, 1e-300)
        hessian = (self.vectors * curvature) @ self.vectors.T
        low, high = room_low * self.norms, room_high * self.norms
        return box_quadratic(hessian, scaled_gradient, low, np.maximum(high, low)) / self.norms

    def covariance(self, variance: float) -> np.ndarray:
        """(k, k) s^2 (J^T J)^+ of the scaled parameters (directions the data do not see: 0)."""
        inverse = np.where(self.kept, 1.0 / np.where(self.kept, self.values, 1.0), 0.0)
        return variance * ((self.vectors * inverse) @ self.vectors.T) / np.outer(self.norms, self.norms)

    def standard_errors(self, variance: float) -> np.ndarray:
        """(k,) standard errors of the parameters, sqrt(diag(s^2 (J^T J)^+)), for residual
        variance s^2 per observation; directions the data do not see get inf."""
        inverse = np.where(self.kept, 1.0 / np.where(self.kept, self.values, 1.0), 0.0)
        diag = (self.vectors**2) @ inverse / self.norms**2
        unseen = (self.vectors[:, ~self.kept] ** 2).sum(axis=1) > 1e-6
        return np.where(unseen, np.inf, np.sqrt(variance * diag))


def box_quadratic(hessian: np.ndarray, gradient: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """argmin 1/2 d^T H d + g^T d subject to low <= d <= high, for H (k, k) positive definite
    and low <= 0 <= high (d = 0 feasible): the primal active-set method (Nocedal & Wright,
    Algorithm 16.3) on a box.

    Hand-written: scipy's only box-constrained least squares, ``lsq_linear`` (BVLS or TRF),
    calls a dense ``lstsq`` at every inner iteration; on the diagnosis' small problems
    (k <= a few hundred, a handful of active bounds) that was half of a real robot's
    diagnosis time, where this takes one Cholesky solve per change of the active set.
    """
    k = gradient.size
    d = np.zeros(k)
    fixed = ((d <= low) & (gradient > 0)) | ((d >= high) & (gradient < 0))
    for _ in range(4 * k + 10):
        free = ~fixed
        target = d.copy()
        if free.any():
            rhs = -(gradient[free] + hessian[np.ix_(free, fixed)] @ d[fixed])
            target[free] = np.linalg.solve(hessian[np.ix_(free, free)], rhs)
        move = target - d
        # the longest step along move that stays in the box, and the bound that stops it
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(move < 0, (low - d) / move, np.where(move > 0, (high - d) / move, np.inf))
        ratio[fixed] = np.inf
        if ratio.size and ratio.min() < 1.0:
            blocking = int(np.argmin(ratio))
            d = d + max(ratio[blocking], 0.0) * move
            d[blocking] = low[blocking] if move[blocking] < 0 else high[blocking]
            fixed[blocking] = True
            continue
        d = target
        if not fixed.any():
            return d
        multiplier = hessian[fixed] @ d + gradient[fixed]  # > 0 holds a lower bound, < 0 an upper
        on_low = d[fixed] <= low[fixed]
        wrong = np.where(on_low, -multiplier, multiplier)
        # a coordinate whose bounds meet (low == high) is held whatever its multiplier's sign (let go, it was
        # fixed again at once, and the other bounds were never released)
        wrong[on_low & (d[fixed] >= high[fixed])] = -np.inf
        if wrong.max() <= 1e-12 * max(float(np.abs(gradient).max()), 1e-300):
            return d
        fixed[np.flatnonzero(fixed)[int(np.argmax(wrong))]] = False
    return np.clip(d, low, high)


def cholesky_solve(matrix: np.ndarray, rhs: np.ndarray, strict: bool = False) -> np.ndarray:
    """matrix^-1 rhs for a symmetric positive definite matrix (LU where round-off breaks Cholesky;
    with ``strict``, numpy's LinAlgError instead, and also where the matrix is too ill-conditioned
    for the step to mean anything)."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    try:
        factor = cho_factor(matrix, check_finite=False)
        if strict:
            diagonal = np.abs(np.diag(factor[0]))
            if diagonal.min() <= 1e-7 * diagonal.max():
                raise np.linalg.LinAlgError("near singular")
        return cho_solve(factor, rhs, check_finite=False)
    except LinAlgError:
        if strict:
            raise np.linalg.LinAlgError("not positive definite") from None
        return np.linalg.solve(matrix, rhs)


def cholesky_factor(matrix: np.ndarray, overwrite: bool = False) -> np.ndarray | None:
    """The upper Cholesky factor U (A = U^T U) of a symmetric (k, k) matrix, or None where it is not
    positive definite: LAPACK's potrf straight on the matrix's memory (a C-ordered array is the
    Fortran-ordered transpose of itself), in place with ``overwrite``, else in one copy. Only U's
    triangle is meaningful (the other keeps what the matrix held there); pass it as
    ``(factor, False)`` to scipy's ``cho_solve``, or to ``solve_triangular`` with ``lower=False``.

    Hand-written around LAPACK: scipy's ``cholesky`` and ``cho_factor`` copy a C-ordered matrix into
    Fortran order first, a second pass over a thousand-column system that the fits of a fine angle
    table make a hundred times."""
    work = matrix if overwrite and matrix.flags.c_contiguous and matrix.dtype == np.float64 \
        else np.array(matrix, dtype=float, order="C")
    potrf, = get_lapack_funcs(("potrf",), (work,))
    factor, info = potrf(work.T, lower=False, overwrite_a=True, clean=False)
    return factor if info == 0 else None


class FactorCache:
    """Factors of small systems kept under keys (the fit engine's penalised blocks,
    :class:`~tcr_accuracy.diagnosis.block_fit.SharedBlock`), the least recently used going first beyond
    ``max_bytes``. Only factors of at most ``max_columns`` columns are worth keeping (:meth:`keeps`):
    the cyclic effect's few hundred columns come back with most candidate models, a fine angle table's
    kept columns (1,231 at 10^4 poses, a 12 MB factor) change with nearly every model around them
    (which of its modes the other effects take), so that its factors were never asked for again."""

    def __init__(self, max_bytes: int = 24 * 2**20, max_columns: int = 640):
        self.max_bytes, self.max_columns = max_bytes, max_columns
        self._factors: OrderedDict = OrderedDict()
        self._bytes = 0

    def keeps(self, n: int) -> bool:
        """Whether the factor of an n x n system is worth keeping."""
        return n <= self.max_columns

    def get(self, key, make):
        """The factor under ``key``, made by ``make()`` (an array, or None where the system is not
        positive definite) when not kept."""
        if key in self._factors:
            self._factors.move_to_end(key)
            return self._factors[key]
        factor = make()
        size = 0 if factor is None else factor.nbytes
        if size <= self.max_bytes:
            self._factors[key] = factor
            self._bytes += size
            while self._bytes > self.max_bytes:
                _, old = self._factors.popitem(last=False)
                self._bytes -= 0 if old is None else old.nbytes
        return factor

    def clear(self) -> None:
        self._factors.clear()
        self._bytes = 0

    def nbytes(self) -> int:
        return int(self._bytes)
