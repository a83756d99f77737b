"""Is a residual still predictable from the joint values, could the test have seen it, and is
there scatter beyond the instrument's?

* :class:`StructureDetector` -- the structure test (k-NN along joint subsets against a
  permutation null, ridge on smooth joint features against a paired z), set up once for a
  set of poses so that many residuals can be tested on the same neighbours and folds.
* :func:`smallest_detectable_structure` -- its power: the smallest leftover of a given
  shape that the test flags when added to the residual, found by injection. A test that
  finds nothing says little unless it could have found something of the size in question.
  :class:`ProbeLine` gives the test's verdict along noise + a x shape for every amplitude a
  from one pass of sparse products (the k-NN sums of squares are quadratic in a).
* :func:`structure_verdict` -- "yes", "no" or "cannot tell with N poses" from the test, its
  power and the scatter test.
* :func:`scatter_test` -- chi-square of the residual against a known instrument noise;
  :func:`scatter_beyond_noise` runs it on a fit when the noise is independent of it, and
  :func:`name_scatter` names what is found (clearance) only when the verdict allows.

Lengths in m inside; the returned dicts carry mm in ``_mm`` keys.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from ..analysis.semivariogram import empirical_semivariogram, fit_gaussian_variogram, nearest_neighbours, standardize
from .paired import stacked

#: Amplitudes [x the per-axis noise, RMS per axis] at which the power probe injects a
#: leftover, smallest first; beyond the last the test is said to see nothing of that shape.
PROBE_AMPLITUDES = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0)


def _smooth_features(q: np.ndarray, kinds) -> np.ndarray:
    """Smooth functions of the joints (N, F): per joint sin/cos of q and 2q (standardised
    value and its square for prismatic joints) and the pairwise products of the first
    harmonics, which is what a serial chain's kinematics is made of."""
    first, cols = [], []
    for j, kind in enumerate(kinds):
        v = q[:, j]
        if kind == "revolute":
            a = [np.sin(v), np.cos(v)]
            cols += a + [np.sin(2 * v), np.cos(2 * v)]
        else:  # a joint held still (every value equal) gives zeros: the spread numpy computes for it is the
            # rounding of its mean (0.4 m on 60 poses: 1.7e-16), which would standardise to +-1
            spread = v.std()
            z = (v - v.mean()) / spread if np.ptp(v) > 0 and spread > 0 else np.zeros_like(v)
            a = [z]
            cols += [z, z**2]
        first.append(a)
    for i in range(len(first)):
        for k in range(i + 1, len(first)):
            cols += [u * w for u in first[i] for w in first[k]]
    return np.stack(cols, axis=1)


def _nugget_ratio(semi, column) -> float:
    try:
        return float(fit_gaussian_variogram(semi, column).nugget_ratio)
    except (ValueError, np.linalg.LinAlgError):
        return 1.0


def _averaging(neighbours: np.ndarray):
    """The sparse (N, N) matrix whose row i averages the rows ``neighbours[i]`` (N, k)."""
    from scipy import sparse

    n, k = neighbours.shape
    return sparse.csr_matrix((np.full(n * k, 1.0 / k), neighbours.ravel(), np.arange(0, n * k + 1, k)), shape=(n, n))


def _banded(average) -> tuple[np.ndarray, object]:
    """(order, the averaging matrix with its rows and columns in that order): poses renumbered by
    reverse Cuthill-McKee (scipy) so that each pose's neighbours sit near it in memory. The sum of
    squares ||x - A x||^2 the test reads is the same for the renumbered rows (to rounding); the
    sparse product with a few hundred residual columns reads its neighbours' rows from cache
    instead of from all over the (N, 303) stack: a third faster."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    order = reverse_cuthill_mckee(average, symmetric_mode=False)
    return order, average[order][:, order].tocsr()


class StructureDetector:
    """The structure test on fixed poses q (N, n): is a residual (N, 3) predictable from q?

    Two predictors, each judged out of sample:

    * local: each residual predicted by the mean of its k nearest neighbours in
      standardised joint space (scipy's k-d tree), over all joints, each joint and each pair
      of joints, compared with the same statistic after shuffling residuals over poses (z
      against the permutation distribution, Bonferroni over the subsets);
    * global: ridge regression (scikit-learn ``RidgeCV``) on smooth joint features
      (:func:`_smooth_features`), k-fold cross-validated predictions, with a one-sided
      paired z-test of the cut in squared residuals.

    Structure remains when either predictor explains more than ``min_explained`` of the
    residual variance beyond chance (p < alpha, resp. z above the matching quantile).
    The permutations and folds are drawn once (from ``rng``, in that order) when it is set up; the
    neighbours, which draw nothing, are found when it first tests.
    """

    #: above this many poses the test runs on a random subset of this size: its cost is
    #: (subsets x permutations x poses), minutes at 10^5 poses, and 2 x 10^4 poses already
    #: see a leftover of a fraction of the noise
    MAX_POSES = 20_000

    def __init__(self, q: np.ndarray, rng: np.random.Generator, kinds=None, k: int = 10,
                 n_permutations: int = 100, alpha: float = 1e-3, min_explained: float = 0.05, folds: int = 5,
                 max_poses: int | None = None):
        from sklearn.model_selection import KFold

        max_poses = self.MAX_POSES if max_poses is None else max_poses
        self.n_total, self.rows = len(q), None
        if len(q) > max_poses:
            self.rows = np.sort(rng.choice(len(q), max_poses, replace=False))
            q = q[self.rows]
        self.q, self.k, self.alpha, self.min_explained = q, k, alpha, min_explained
        self.kinds = kinds if kinds is not None else ["revolute"] * q.shape[1]
        self.perms = [rng.permutation(len(q)) for _ in range(n_permutations)]
        self.split = KFold(n_splits=folds, shuffle=True, random_state=int(rng.integers(2**31 - 1)))
        # the neighbours, features and ridge folds are made when first tested: set up with the candidates,
        # the test runs after the selection, whose peak memory they joined (0.2 GB at 10^5 poses)
        self._made = None  # (subsets, their neighbours, features)
        self._ridge = None  # the ridge's folds, decomposed when first tested

    def _make(self) -> tuple:
        if self._made is None:
            qs, _, _ = standardize(self.q)
            # an unmodelled effect often depends on a few joints: in all of joint space 6-D
            # neighbours are far apart, along one joint or a pair they are close. Test all
            # joints, each joint and each pair; Bonferroni over the subsets.
            # (a joint moves when its values differ: np.std of equal values is the rounding of their mean, not 0)
            moving = [j for j in range(self.q.shape[1]) if np.ptp(self.q[:, j]) > 0]
            subsets = [tuple(moving)] + [(j,) for j in moving]
            subsets += [(a, b) for i, a in enumerate(moving) for b in moving[i + 1:]]
            banded = []  # per subset, the poses renumbered and the matrix averaging each one's k neighbours
            for subset in subsets:
                banded.append(_banded(_averaging(nearest_neighbours(qs[:, subset], min(self.k, len(self.q) - 1)))))
            self._made = (subsets, banded, _smooth_features(self.q, self.kinds))
        return self._made

    @property
    def subsets(self) -> list:
        """The joint subsets tested (all moving joints, each, each pair), as tuples of joint indices."""
        return self._make()[0]

    @property
    def neighbours(self) -> list:
        """Per subset tested, (order (N,), A): the poses renumbered so that neighbours sit together, and
        the sparse (N, N) matrix whose row i averages the k nearest neighbours of pose order[i] along the
        subset, in that numbering (:func:`_banded`): ``A @ x[order]`` is each pose's neighbours' mean."""
        return self._make()[1]

    @property
    def features(self) -> np.ndarray:
        """(N, F) the smooth joint features of the global predictor (:func:`_smooth_features`)."""
        return self._make()[2]

    def _leftovers(self, stack: np.ndarray):
        """Per subset tested, x - A x (N, C) for the columns x of stack (N, C): what each pose's k nearest
        neighbours along the subset leave of its value, in the subset's numbering of the poses (one sparse
        product per subset for all the columns)."""
        for order, average in self.neighbours:
            ordered = stack[order]
            error = average @ ordered
            np.subtract(ordered, error, out=error)
            yield error

    def _best(self, errors, total: float) -> dict:
        """The subset whose residual's k-NN share stands highest above its shuffles' (z), from the sums of
        squares ``errors``: per subset (1 + n_perms,) of the residual then of each shuffle, over the poses
        and the three axes."""
        best = None
        for subset, error in zip(self.subsets, errors):
            shares = 1.0 - error / total
            actual, null = float(shares[0]), shares[1:]
            gain = float(actual - null.mean())
            # a few hundred permutations cannot resolve small p by counting: use their spread
            z_sub = gain / max(float(null.std(ddof=1)), 1e-12)
            if best is None or z_sub > best["z"]:
                best = {"joints": list(subset), "explained_share": actual, "null_mean": float(null.mean()),
                        "null_std": float(null.std(ddof=1)), "gain": gain, "z": z_sub}
        return best

    def shares(self, residual: np.ndarray) -> dict:
        """Subset tested (tuple of joint indices) -> the share of the residual's (N, 3) variance that each
        pose's k nearest neighbours along it predict, out of sample (a pose is not its own neighbour): the
        test's statistic without its shuffles, on the poses the test runs on."""
        centred = self.restrict(residual)
        centred = centred - centred.mean(axis=0)
        total = float(np.sum(centred**2)) or 1.0
        return {subset: 1.0 - float(np.sum(left**2)) / total
                for subset, left in zip(self.subsets, self._leftovers(centred))}

    #: shuffles whose columns go through the sparse products at once: (N, 3 x 34) blocks, 16 MB at the
    #: test's 2 x 10^4 poses (the 101 side by side were three arrays of 48 MB); the same sums, column by column
    SHUFFLES_AT_ONCE = 34

    def _local(self, centred: np.ndarray, total: float, perms=None) -> dict:
        shuffles = [None] + list(self.perms if perms is None else perms)  # None: the residual itself
        errors = [[] for _ in self.neighbours]
        # the residual and its shuffles side by side, a block at a time: one sparse product per subset and block
        for start in range(0, len(shuffles), self.SHUFFLES_AT_ONCE):
            stack = np.concatenate([centred if perm is None else centred[perm]
                                    for perm in shuffles[start:start + self.SHUFFLES_AT_ONCE]], axis=1)
            for sums, error in zip(errors, self._leftovers(stack)):
                np.square(error, out=error)
                sums.append(error.sum(axis=0).reshape(-1, 3).sum(axis=1))
        return self._best([np.concatenate(sums) for sums in errors], total)

    def _global(self, centred: np.ndarray, total: float) -> tuple[float, float]:
        if self._ridge is None:
            self._ridge = RidgeFolds(self.features, self.split, RIDGE_ALPHAS)
        predicted = self._ridge.predict(centred)
        share = float(1.0 - np.sum((centred - predicted) ** 2) / total)
        d = np.sum(centred**2, axis=1) - np.sum((centred - predicted) ** 2, axis=1)
        z = float(d.mean() / (d.std(ddof=1) / math.sqrt(d.size))) if d.std() > 0 else 0.0
        return share, z

    #: permutations the power probe's tests use (of the test's own): the null's mean and
    #: spread to a few per cent, at a third of the cost
    PROBE_PERMUTATIONS = 30

    def remains(self, residual: np.ndarray) -> bool:
        """Only the verdict (no semivariogram, fewer permutations): what the power probe needs."""
        return self.test(residual, rng=None, perms=self.perms[:self.PROBE_PERMUTATIONS])["remains"]

    def probe(self, noise: np.ndarray, shape: np.ndarray) -> "ProbeLine":
        """:meth:`remains` of ``noise + a * shape`` (N, 3) [m] for any amplitude a, as a callable of a
        (:class:`ProbeLine`): the k-NN sums of squares are quadratic in a, so the sparse products are
        taken once for the line instead of once per amplitude tried."""
        return ProbeLine(self, self.restrict(noise), self.restrict(shape))

    def restrict(self, values: np.ndarray) -> np.ndarray:
        """Rows of all N poses -> the rows of the poses the test runs on."""
        values = np.asarray(values)
        return values[self.rows] if self.rows is not None and len(values) == self.n_total else values

    def test(self, residual: np.ndarray, rng: np.random.Generator | None = None, perms=None) -> dict:
        """The test's statistics and verdict for a residual (N, 3) [m]; with ``rng`` also the
        nugget ratio of the residual's semivariogram per axis (for the report)."""
        residual = self.restrict(residual)
        centred = residual - residual.mean(axis=0)
        total = float(np.sum(centred**2)) or 1e-300
        best = self._local(centred, total, perms)
        m = len(self.neighbours)
        p_knn = float(min(1.0, stats.norm.sf(best["z"]) * m))
        local = bool(p_knn < self.alpha and best["gain"] > self.min_explained)
        ridge_share, ridge_z = self._global(centred, total)
        z_crit = float(stats.norm.isf(self.alpha))
        global_ = bool(ridge_z > z_crit and ridge_share > self.min_explained)
        out = {"statistic": "share of residual variance predicted out of sample from the joint values: "
                            "k-NN (permutation test) and ridge on smooth joint features (paired z-test)",
               "k": self.k, "explained_share": best["explained_share"], "null_mean": best["null_mean"],
               "null_std": best["null_std"], "z": best["z"], "p_value": p_knn, "gain_over_null": best["gain"],
               "n_subsets": m, "n_poses_tested": int(self.q.shape[0]), "along_joints": best["joints"],
               "ridge_explained_share": ridge_share,
               "ridge_z": ridge_z, "z_critical": z_crit, "alpha": self.alpha, "min_explained": self.min_explained,
               "local": local, "global": global_, "remains": bool(local or global_)}
        if rng is not None:
            semi = empirical_semivariogram(self.q, residual, n_bins=12, rng=rng)
            out["semivariogram_nugget_ratio_xyz"] = [_nugget_ratio(semi, c) for c in range(3)]
        return out


class ProbeLine:
    """The structure test's verdict along a line of residuals, noise + a * shape (N, 3) [m], as
    :meth:`StructureDetector.remains` gives it at each amplitude a: the k-NN test with the probe's
    permutations and the ridge.

    With x = P(c_n + a c_s) (c the centred noise and shape, P a shuffle or none) the k-NN sum of
    squares ||x - A x||^2 = ||u||^2 + 2 a u.v + a^2 ||v||^2 with u = (I - A) P c_n, v = (I - A) P c_s;
    the three sums per subset and shuffle come from one sparse product per subset with the noise's and
    the shape's columns side by side, and each amplitude costs a few hundred multiplications: the
    power probe's bisection tried three or four amplitudes per shape, each a product as wide as the
    noise's alone. The ridge is refitted at each amplitude (its penalty is chosen per amplitude).
    """

    def __init__(self, detector: StructureDetector, noise: np.ndarray, shape: np.ndarray):
        self.detector = detector
        self.noise, self.shape = noise, shape
        self.centred_noise = noise - noise.mean(axis=0)
        self.centred_shape = shape - shape.mean(axis=0)
        shuffles = [None] + list(detector.perms[:detector.PROBE_PERMUTATIONS])  # None: unshuffled
        sums = [([], [], []) for _ in detector.neighbours]
        for start in range(0, len(shuffles), detector.SHUFFLES_AT_ONCE):
            block = shuffles[start:start + detector.SHUFFLES_AT_ONCE]
            columns = [c if perm is None else c[perm] for c in (self.centred_noise, self.centred_shape)
                       for perm in block]
            width = 3 * len(block)
            for sum_, left in zip(sums, detector._leftovers(np.concatenate(columns, axis=1))):
                u, v = left[:, :width], left[:, width:]
                for into, (a, b) in zip(sum_, ((u, u), (u, v), (v, v))):
                    into.append(np.einsum("ij,ij->j", a, b).reshape(-1, 3).sum(axis=1))
        # per subset, (||u||^2, u.v, ||v||^2) per shuffle (1 + n_perms,), summed over the axes
        self.sums = [tuple(np.concatenate(part) for part in sum_) for sum_ in sums]
        self.totals = (float(np.sum(self.centred_noise**2)), float(np.sum(self.centred_noise * self.centred_shape)),
                       float(np.sum(self.centred_shape**2)))

    def local(self, amplitude: float) -> dict:
        """The k-NN test's best subset (as the structure test reports it) at noise + amplitude * shape."""
        a = float(amplitude)
        nn, ns, ss = self.totals
        total = (nn + 2 * a * ns + a * a * ss) or 1e-300
        return self.detector._best([uu + 2 * a * uv + a * a * vv for uu, uv, vv in self.sums], total)

    def __call__(self, amplitude: float) -> bool:
        """Whether structure remains in noise + amplitude * shape (the k-NN test, else the ridge)."""
        d = self.detector
        best = self.local(amplitude)
        p_knn = float(min(1.0, stats.norm.sf(best["z"]) * len(self.sums)))
        if p_knn < d.alpha and best["gain"] > d.min_explained:
            return True
        centred = self.centred_noise + amplitude * self.centred_shape
        total = float(np.sum(centred**2)) or 1e-300
        share, z = d._global(centred, total)
        return bool(z > float(stats.norm.isf(d.alpha)) and share > d.min_explained)


#: the ridge penalties the global predictor chooses among (on standardised features)
RIDGE_ALPHAS = np.logspace(-3, 3, 13)


class RidgeFolds:
    """Out-of-fold predictions of scikit-learn's ``make_pipeline(StandardScaler(), RidgeCV(alphas))``
    under ``cross_val_predict(..., cv=split)``, for any number of residuals on the same features.

    RidgeCV chooses alpha per training fold by its efficient leave-one-out error (the hat matrix's
    diagonal; mean over rows and targets; the first best alpha) and fits the ridge with an intercept
    on the fold's standardised features. The features are the same for every residual the structure
    test is asked about (nine per diagnosis, each with five folds), and RidgeCV decomposes them
    again each time (most of the test's cost); here each fold's standardised features are
    decomposed once (Z^T Z = V diag(s) V^T) and a residual costs a few products with Z V. The same
    formulas: hat diagonal 1/n + sum_j (Z V)_ij^2 / (s_j + alpha), prediction
    mean(y) + Z V diag(1 / (s + alpha)) V^T Z^T (y - mean(y)).
    """

    def __init__(self, features: np.ndarray, split, alphas: np.ndarray):
        self.n_rows = features.shape[0]
        self.alphas = np.asarray(alphas, dtype=float)
        self.folds = []
        for train, test in split.split(features):
            x = features[train]
            mean = x.mean(axis=0)
            scale = x.std(axis=0)
            scale[scale < 10 * np.finfo(float).eps * np.maximum(np.abs(mean), 1.0)] = 1.0  # StandardScaler's
            z = (x - mean) / scale
            values, vectors = np.linalg.eigh(z.T @ z)
            values = np.clip(values, 0.0, None)
            projected = z @ vectors  # (n_train, F)
            inverse = 1.0 / (values[:, None] + self.alphas[None, :])  # (F, n_alphas)
            hat = 1.0 / len(train) + (projected**2) @ inverse  # (n_train, n_alphas)
            self.folds.append((train, test, projected, inverse, hat, ((features[test] - mean) / scale) @ vectors))

    def predict(self, y: np.ndarray) -> np.ndarray:
        """(N, m) out-of-fold predictions of y (N, m)."""
        out = np.empty_like(y, dtype=float)
        n_alphas = self.alphas.size
        for train, test, projected, inverse, hat, projected_test in self.folds:
            target = y[train]
            offset = target.mean(axis=0)
            centred = target - offset
            moment = projected.T @ centred  # (F, m)
            # every penalty's fit in one product (n_train, n_alphas * m): thirteen products of m columns were
            # most of the test's ridge time
            fitted = projected @ (inverse[:, :, None] * moment[:, None, :]).reshape(moment.shape[0], -1)
            looe = centred[:, None, :] - fitted.reshape(-1, n_alphas, centred.shape[1])
            looe /= 1.0 - hat[:, :, None]
            scores = -np.mean(looe**2, axis=(0, 2))
            best = int(np.argmax(scores))  # the first of the best, as RidgeCV takes it
            out[test] = offset + projected_test @ (moment * inverse[:, best, None])
        return out


def smooth_shape(detector: StructureDetector, rng: np.random.Generator) -> np.ndarray:
    """(N, 3) a random smooth function of the joints (the detector's smooth features with
    normal weights): a generic leftover for the power probe when no effect suggests one."""
    features = detector.features - detector.features.mean(axis=0)
    features = features / np.where(features.std(axis=0) > 0, features.std(axis=0), 1.0)
    return features @ rng.standard_normal((features.shape[1], 3))


def smallest_detectable_structure(detector: StructureDetector, shapes: dict, noise_per_axis: float,
                                  rng: np.random.Generator) -> dict:
    """Power of the structure test: the smallest leftover of each shape it flags on top of
    the measurement noise.

    shapes : name -> (N, 3) pattern (any scale), e.g. the TCP motion an effect that is not
        in the model would leave once the model's own parameters have absorbed what they
        can. Each is scaled to RMS per axis a x ``noise_per_axis`` for a in
        :data:`PROBE_AMPLITUDES`, added to Gaussian noise of ``noise_per_axis`` [m] and
        tested; the smallest amplitude flagged (found by bisection: detection grows with
        the amplitude) is that shape's detectable size. The result's
        ``smallest_detectable_mm`` is the largest over the shapes (RMS of the 3-D leftover):
        a leftover of any of them at least that large would have been seen; None when some
        shape was not seen even at the largest amplitude.
    """
    noise = rng.standard_normal((detector.q.shape[0], 3)) * noise_per_axis
    per_shape = {}
    for name, shape in shapes.items():
        shape = detector.restrict(shape)
        rms = math.sqrt(float(np.mean(shape**2)))
        if rms == 0:
            continue
        seen_at = detector.probe(noise, shape * (noise_per_axis / rms))  # a -> the verdict at a x the noise
        # detection grows with the amplitude: bisect over the ladder (3 tests for 8 levels)
        lo, hi = -1, len(PROBE_AMPLITUDES)  # not seen at lo (or below the ladder), seen at hi (or never)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if seen_at(PROBE_AMPLITUDES[mid]):
                hi = mid
            else:
                lo = mid
        seen = PROBE_AMPLITUDES[hi] * noise_per_axis * math.sqrt(3.0) if hi < len(PROBE_AMPLITUDES) else None
        per_shape[name] = None if seen is None else seen * 1e3
        if seen is None:
            break  # some leftover goes unseen: the answer is None whatever the other shapes give
    sizes = list(per_shape.values())
    worst = None if (not sizes or any(s is None for s in sizes)) else max(sizes)
    return {"smallest_detectable_mm": worst, "per_shape_mm": per_shape,
            "largest_probed_mm": PROBE_AMPLITUDES[-1] * noise_per_axis * math.sqrt(3.0) * 1e3,
            "n_poses": int(detector.q.shape[0]), "of_poses": int(detector.n_total),
            "method": f"each shape added to Gaussian noise of {noise_per_axis * 1e3:.3g} mm per axis at RMS "
                      "0.5, 1, 2, ... 64 x that and tested; the smallest flagged size, largest over the shapes"}


def structure_verdict(structure: dict, power: dict, scatter: dict, noise_floor: float, residual_rms: float) -> dict:
    """"yes" (structure found), "no" (none, and the test could have seen a leftover of the
    size the data leave beyond the noise), or "cannot tell" (none found, but a leftover of
    that size could hide from it with these poses). Sizes in m (noise floor and residual
    RMS are 3-D RMS)."""
    n = power.get("n_poses")
    if structure["remains"]:
        return {"verdict": "yes", "reason": "the structure test found it"}
    smallest = power.get("smallest_detectable_mm")
    excess = math.sqrt(max(residual_rms**2 - noise_floor**2, 0.0)) * 1e3
    beyond_noise = bool(scatter.get("detected")) if scatter.get("tested") else False
    if smallest is None:
        blind = f"the test saw none of the probed leftovers even at {power.get('largest_probed_mm', 0):.3g} mm"
        if beyond_noise or not scatter.get("tested"):
            return {"verdict": "cannot tell", "reason": f"{blind} with {n} poses"}
        return {"verdict": "no", "reason": f"no scatter beyond the noise to explain ({blind})"}
    if beyond_noise and excess < smallest:
        return {"verdict": "cannot tell",
                "reason": f"{excess:.3g} mm RMS are left beyond the noise, but with {n} poses the test only sees "
                          f"structure from {smallest:.3g} mm"}
    if not scatter.get("tested") and smallest > noise_floor * 1e3:
        return {"verdict": "cannot tell",
                "reason": f"the noise was estimated from this residual, and with {n} poses the test only sees "
                          f"structure from {smallest:.3g} mm, above the {noise_floor * 1e3:.3g} mm noise floor"}
    return {"verdict": "no", "reason": f"the test would have seen a leftover from {smallest:.3g} mm RMS"}


def scatter_test(residual: np.ndarray, n_parameters: int, tracker_noise: float, alpha: float = 1e-3,
                 min_ratio: float = 1.1) -> dict:
    """Random scatter beyond the tracker noise (chi-square on the in-sample residual)."""
    dof = max(residual.size - n_parameters, 1)
    rss = float(np.sum(residual**2))
    sigma = math.sqrt(rss / dof)
    chi2_stat = rss / tracker_noise**2 if tracker_noise > 0 else math.inf
    p = float(stats.chi2.sf(chi2_stat, dof)) if tracker_noise > 0 else 0.0
    ratio = sigma / tracker_noise if tracker_noise > 0 else math.inf
    extra = math.sqrt(max(sigma**2 - tracker_noise**2, 0.0))
    return {"estimated_noise_per_axis_mm": sigma * 1e3, "tracker_noise_per_axis_mm": tracker_noise * 1e3,
            "ratio": ratio, "p_value": p, "extra_per_axis_mm": extra * 1e3,
            "detected": bool(p < alpha and ratio > min_ratio)}


def scatter_beyond_noise(noise, final, stochastic) -> dict:
    """Scatter beyond the instrument's noise in the final fit's residual (chi-square), when the
    noise comes from outside that residual (given, or repeated poses); else why not tested."""
    if not noise.independent:
        return {"tested": False, "detected": False,
                "why": "the noise was estimated from this residual; give the instrument's noise or "
                       "measure repeated poses to test for scatter beyond it",
                "estimated_noise_per_axis_mm": noise.per_axis * 1e3}
    scatter = scatter_test(stacked(final["train_residual"]), final["n_parameters"], noise.per_axis)
    scatter["tested"] = True
    if stochastic:
        scatter["stochastic_effects"] = stochastic
    return scatter

def predictable_leftover(detector: StructureDetector, residual: np.ndarray) -> float:
    """RMS per axis [m] of what is left of a residual (N, 3) once it is predicted out of
    sample from the joint values: the better of k-nearest neighbours (in all joints, along
    each joint and each pair, as the structure test) and ridge regression on smooth joint
    features, each scored on held-out folds."""
    from sklearn.linear_model import RidgeCV
    from sklearn.model_selection import cross_val_predict

    residual = detector.restrict(residual)
    centred = residual - residual.mean(axis=0)
    best = float(np.mean(centred**2))
    for order, averaging in detector.neighbours:  # leave-one-out: a pose's own value is not among its neighbours
        ordered = centred[order]
        best = min(best, float(np.mean((ordered - averaging @ ordered) ** 2)))
    ridge = cross_val_predict(RidgeCV(alphas=np.logspace(-6, 3, 10)), detector.features, centred, cv=detector.split)
    best = min(best, float(np.mean((centred - ridge) ** 2)))
    return math.sqrt(best)


def predictable_from_context(features: np.ndarray, residual: np.ndarray, split) -> float:
    """RMS per axis [m] of what is left of a residual (N, 3) once a ridge regression on the rows'
    context (F columns: temperature, time or measurement order, payload, approach directions)
    predicts it out of sample (k-fold ``split``)."""
    from sklearn.linear_model import RidgeCV
    from sklearn.model_selection import cross_val_predict
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    centred = residual - residual.mean(axis=0)
    model = make_pipeline(StandardScaler(), RidgeCV(alphas=np.logspace(-6, 3, 10)))
    predicted = cross_val_predict(model, features, centred, cv=split)
    return math.sqrt(min(float(np.mean(centred**2)), float(np.mean((centred - predicted) ** 2))))


def name_scatter(scatter, structure, stochastic, noise, notes, detector: StructureDetector | None = None,
                 residual: np.ndarray | None = None, context: dict | None = None) -> None:
    """Scatter beyond the instrument without structure is named only when the structure
    test could have seen a leftover of its size, and when neither the joints nor the rows'
    context (``context``: name -> (N,) or (N, k) values, e.g. temperature, measurement order)
    predict it out of sample: a leftover that k-NN or a ridge on joint features, or a ridge on
    the context, predicts to within half of its excess variance over the instrument's is
    structure, not scatter."""
    if not scatter["detected"]:
        return
    if detector is not None and residual is not None:
        sigma = scatter["estimated_noise_per_axis_mm"] * 1e-3
        after = predictable_leftover(detector, residual)
        excess_before = max(sigma**2 - noise.per_axis**2, 0.0)
        excess_after = max(after**2 - noise.per_axis**2, 0.0)
        scatter["predicted_from_joints_left_per_axis_mm"] = after * 1e3
        if excess_before > 0 and excess_after < 0.5 * excess_before:
            scatter["named"] = None
            notes.append(f"{sigma * 1e3:.4f} mm per axis is left against {noise.per_axis * 1e3:.4f} mm of noise, "
                         f"but predicted from the joint values out of sample it leaves {after * 1e3:.4f} mm: "
                         "structure the vocabulary does not express, not random scatter")
            return
        varying = {k: np.asarray(v, dtype=float).reshape(len(residual), -1) for k, v in (context or {}).items()}
        varying = {k: v for k, v in varying.items() if np.any(np.std(v, axis=0) > 0)}
        if varying:
            features = np.concatenate(list(varying.values()), axis=1)
            after = predictable_from_context(detector.restrict(features), detector.restrict(residual),
                                             detector.split)
            excess_after = max(after**2 - noise.per_axis**2, 0.0)
            scatter["predicted_from_context_left_per_axis_mm"] = after * 1e3
            if excess_before > 0 and excess_after < 0.5 * excess_before:
                scatter["named"] = None
                notes.append(f"{sigma * 1e3:.4f} mm per axis is left against {noise.per_axis * 1e3:.4f} mm of noise, "
                             f"but predicted out of sample from the rows' {', '.join(varying)} it leaves "
                             f"{after * 1e3:.4f} mm: structure along them that the vocabulary does not express, "
                             "not random scatter")
                return
    if structure["verdict"] == "no":
        scatter["named"] = "clearance" if "clearance" in stochastic else "random scatter"
        notes.append(f"random scatter beyond the tracker noise: {scatter['estimated_noise_per_axis_mm']:.4f} mm "
                     f"per axis vs {noise.per_axis * 1e3:.4f} mm, without spatial structure: joint play "
                     "(clearance) or a noisier instrument")
    elif structure["verdict"] == "cannot tell":
        notes.append(f"{scatter['estimated_noise_per_axis_mm']:.4f} mm per axis left against "
                     f"{noise.per_axis * 1e3:.4f} mm of noise: whether it is structure or scatter cannot be told "
                     f"({structure['reason']}); measure more poses")
