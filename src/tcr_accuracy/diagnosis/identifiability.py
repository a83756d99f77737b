"""Which parameters the measurements can tell apart: pivoted QR of the identification Jacobian.

Used by the diagnosis (per candidate model) and by the geometric calibration estimator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import linalg


#: poses whose rows one step of :func:`compressed`'s QR takes in (the rows of R of those before join them)
QR_CHUNK = 2048


@dataclass
class SensitivityColumns:
    """One block of parameters as :func:`identifiability` reads it (the diagnosis'
    ``EffectBasis`` and ``UnionBasis`` carry the same three fields).

    names : (P,) parameter names
    g : (N, r, P) TCP sensitivity per pose to each parameter [m per parameter unit]
    scales : (P,) typical size of each parameter [its unit]; the test takes ``g * scales``
    """

    names: list
    g: np.ndarray
    scales: np.ndarray
    #: the number of poses the columns' RMS is taken over (None: g's first dimension)
    n_poses: int | None = None


def compressed(bases: dict) -> dict:
    """The same columns with the poses folded away: each block's ``g * scales`` replaced by
    its rows in the triangular factor R of one QR of all blocks side by side (A = Q R).
    Q has orthonormal columns, so every inner product, norm, projection and pivoted QR that
    :func:`identifiability` takes is the same on R as on A, at a cost that no longer grows
    with the number of poses: one QR of the (rows x P) matrix instead of one per call.
    """
    if not bases:
        return {}
    names = list(bases)
    widths = [len(bases[e].names) for e in names]
    n_all = max(bases[names[0]].g.shape[0], 1)
    n_poses = n_all
    # R of A = [R of the poses before; the next chunk of poses' rows], chunk by chunk (a tall-skinny
    # QR): A whole was held three times over (the scaled blocks, their concatenation, LAPACK's copy),
    # 340 MB at 10^4 poses with the cyclic effect's 336 columns; a chunk of A is a few tens of MB
    r = np.zeros((0, sum(widths)))
    for start in range(0, n_all, QR_CHUNK):
        stop = min(start + QR_CHUNK, n_all)
        rows = (stop - start) * bases[names[0]].g.shape[1]
        stacked = np.empty((r.shape[0] + rows, r.shape[1]), order="F")
        stacked[:r.shape[0]] = r
        column = 0
        for e, width in zip(names, widths):
            chunk = bases[e].g[start:stop] * bases[e].scales
            stacked[r.shape[0]:, column:column + width] = chunk.reshape(rows, width)
            column += width
        r = linalg.qr(stacked, mode="r", overwrite_a=True, check_finite=False)[0][:min(stacked.shape)].copy()
    out, start = {}, 0
    for e, width in zip(names, widths):
        out[e] = SensitivityColumns(list(bases[e].names), r[:, None, start:start + width], np.ones(width), n_poses)
        start += width
    return out


def gram_factor(gram: np.ndarray, columns: dict, n_poses: int) -> dict:
    """The same compressed columns as :func:`compressed`, from the columns' Gram matrix A^T A (K, K)
    (the fit engine holds it, :mod:`~tcr_accuracy.diagnosis.gram`) instead of the rows: a factor F with
    F^T F = A^T A, by LAPACK's pivoted Cholesky (``dpstrf``) of the matrix scaled to a unit diagonal (so
    that every column keeps its own relative precision, ~1e-8 of its norm, far below the rank tolerance).
    ``columns``: effect -> (names, its K-columns); the result's blocks read as :func:`compressed`'s."""
    from scipy.linalg import lapack

    norms = np.sqrt(np.clip(np.diag(gram), 0.0, None))
    safe = np.where(norms > 0, norms, 1.0)
    scaled = gram / np.outer(safe, safe)
    factor, piv, rank, _ = lapack.dpstrf(scaled, tol=float(np.finfo(float).eps * gram.shape[0]), lower=0)
    upper = np.triu(factor[:rank])  # (rank, K): the rows of the factor in pivoted column order
    f = np.zeros((rank, gram.shape[0]))
    f[:, piv[:gram.shape[0]] - 1] = upper
    f *= norms  # back to the columns' own scale (a column of norm 0 stays 0)
    return {e: SensitivityColumns(list(names), f[:, None, cols], np.ones(len(cols)), n_poses)
            for e, (names, cols) in columns.items()}


def identifiability(bases: dict, order, rank_tol: float = 1e-6, min_motion: float | dict = 0.0,
                    report: bool = True, prefixes: dict | None = None) -> tuple[dict, dict | None]:
    """Kept columns per effect and a report of what was removed and why.

    Each parameter's column of the identification Jacobian (N poses x 3 rows) is taken
    at the parameter's typical scale, so its RMS norm over the poses is the TCP motion
    that parameter causes at its typical size. Effects are taken in ``order``; each
    block is projected off the span already kept and reduced by QR with column pivoting
    (as FIGAROH does): the pivot is the motion of the part of the column that no earlier
    column explains. A column is unidentifiable when that independent motion is below
    ``min_motion`` [m RMS] (the measurements cannot resolve it) or below ``rank_tol``
    times the column's own motion (a numerical duplicate). ``min_motion`` may be a dict
    (effect -> threshold [m]) when effects are judged at sizes other than their typical ones.
    With ``report=False`` only the kept columns (the report, what each dropped column duplicates
    and the condition number, is most of the cost): (keep, None); then ``prefixes`` (a dict the
    caller keeps for these bases) lets orders that start alike share their leading effects' work.
    With or without the report, ``prefixes`` also keeps the large blocks' own Gram matrices
    (:func:`_block_pivots`).
    """
    if not report:
        return _kept_columns(bases, order, rank_tol, min_motion, prefixes), None
    kept_q = None  # orthonormal basis of the kept span, (3N, r)
    kept_cols, kept_names = [], []  # normalised kept columns and names, for naming duplicates
    keep: dict = {}
    thresholds = min_motion if isinstance(min_motion, dict) else dict.fromkeys(order, min_motion)
    report: dict = {"rank_tol": rank_tol, "min_motion_mm": max(thresholds.values(), default=0.0) * 1e3,
                    "effects": {}}
    own_grams = _own_grams(bases, prefixes)
    for name in order:
        b = bases[name]
        threshold = thresholds.get(name, 0.0)
        n_pose, cols, norms, piv, diag, basis = _block_pivots(b, kept_q, own_grams, name)
        removed, kept_local = [], []
        independent = np.zeros(len(b.names))
        independent[piv[:diag.size]] = diag
        rank = 0
        for k in range(diag.size):
            col = piv[k]
            if diag[k] / math.sqrt(n_pose) > threshold and diag[k] > rank_tol * norms[col]:
                rank += 1
            else:
                break
        kept_local = sorted(piv[:rank].tolist())
        unit_all = cols / np.where(norms > 0, norms, 1.0)
        mat = np.stack(kept_cols + [unit_all[:, k] for k in kept_local], axis=1) if (kept_cols or kept_local) \
            else np.zeros((cols.shape[0], 0))
        span_names = kept_names + [b.names[k] for k in kept_local]
        dropped = sorted(int(k) for k in piv[rank:])  # in the effect's own order (the pivots' is round-off)
        # what each dropped column duplicates: one least-squares solve for all of them
        coefs = np.linalg.lstsq(mat, unit_all[:, dropped], rcond=None)[0] if (mat.shape[1] and dropped) else None
        for i, k in enumerate(dropped):
            motion = norms[k] / math.sqrt(n_pose)
            if motion < 1e-12:
                removed.append({"parameter": b.names[k], "reason": "does not move the TCP position",
                                "duplicates": []})
                continue
            dup = []
            if coefs is not None:
                coef = coefs[:, i]
                dup = [span_names[t] for t in np.argsort(-np.abs(coef))[:3] if abs(coef[t]) > 1e-2]
            free = independent[k] / math.sqrt(n_pose)
            if free < 1e-3 * motion and dup:
                reason = "linear combination of " + ", ".join(dup)
            else:
                reason = (f"only {free * 1e6:.3g} um RMS of its {motion * 1e6:.3g} um TCP motion (at its typical "
                          f"size) is its own: below what the measurements resolve"
                          + (f"; the rest duplicates {', '.join(dup)}" if dup else ""))
            removed.append({"parameter": b.names[k], "reason": reason, "duplicates": dup})
        if rank:
            new_q = basis(rank)
            kept_q = new_q if kept_q is None else np.hstack([kept_q, new_q])
            kept_cols += [unit_all[:, k] for k in kept_local]
            kept_names += [b.names[k] for k in kept_local]
        keep[name] = np.asarray(kept_local, dtype=int)
        report["effects"][name] = {"n_parameters": len(b.names), "n_identifiable": len(kept_local),
                                   "removed": removed}
    if kept_cols:
        mat = np.stack(kept_cols, axis=1)
        sv = np.linalg.svd(mat, compute_uv=False)
        report["rank"] = int(mat.shape[1])
        report["condition_number"] = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
        report["smallest_singular_value"] = float(sv[-1])
    return keep, report


#: the projections of this many leading effect sets kept for later sets that start alike
PREFIXES = 8


def _kept_columns(bases: dict, order, rank_tol: float, min_motion, prefixes: dict | None = None) -> dict:
    """The kept columns of :func:`identifiability`, by the same projections and pivoted QR.

    ``prefixes``: a dict kept by the caller for these bases: the state after each leading run of
    effects (the kept span and columns) is stored in it, and a later order that starts with the same
    effects at the same thresholds resumes from there (a candidate added to a model, a model of the
    selection's ladder: the same floats, without projecting and pivoting the leading effects again)."""
    kept_q = None
    keep: dict = {}
    thresholds = min_motion if isinstance(min_motion, dict) else dict.fromkeys(order, min_motion)
    key = [rank_tol]
    start = 0
    own_grams = _own_grams(bases, prefixes)
    if prefixes is not None:
        for i in range(len(order) - 1, 0, -1):  # the longest stored run of leading effects
            leading = tuple(key + [(n, thresholds.get(n, 0.0)) for n in order[:i]])
            if leading in prefixes:
                prefixes[leading] = stored = prefixes.pop(leading)  # to the end: the most recently used
                kept_q, keep, start = stored[0], dict(stored[1]), i
                break
        key += [(n, thresholds.get(n, 0.0)) for n in order[:start]]
    for name in order[start:]:
        b = bases[name]
        threshold = thresholds.get(name, 0.0)
        n_pose, _, norms, piv, diag, basis = _block_pivots(b, kept_q, own_grams, name)
        rank = 0
        for k in range(diag.size):
            if diag[k] / math.sqrt(n_pose) > threshold and diag[k] > rank_tol * norms[piv[k]]:
                rank += 1
            else:
                break
        if rank and name != order[-1]:  # the span the effects after it are projected off
            kept_q = basis(rank) if kept_q is None else np.hstack([kept_q, basis(rank)])
        keep[name] = np.asarray(sorted(piv[:rank].tolist()), dtype=int)
        if prefixes is not None and name != order[-1]:
            key.append((name, threshold))
            prefixes[tuple(key)] = (kept_q, dict(keep))
            while len(prefixes) > PREFIXES + len(_KEPT_ENTRIES):  # the least recently used go (not those)
                prefixes.pop(next(k for k in prefixes if k not in _KEPT_ENTRIES))
    return keep


#: the entries of ``prefixes`` that are not leading runs: the bases they belong to and the large blocks' own
#: Gram matrices (:func:`_block_pivots`)
_KEPT_ENTRIES = ("bases", "own_grams")


def _own_grams(bases: dict, prefixes: dict | None) -> dict:
    """The large blocks' own Gram matrices kept for these bases in ``prefixes`` (a new dict without it);
    ``prefixes`` is emptied when it was kept for other bases."""
    if prefixes is None:
        return {}
    if prefixes.get("bases") is not bases:
        prefixes.clear()
        prefixes["bases"] = bases
        prefixes["own_grams"] = {}
    return prefixes.setdefault("own_grams", {})


def _block_pivots(b, kept_q: np.ndarray | None, own_grams: dict | None = None, name=None) -> tuple:
    """One effect's block projected off the kept span ``kept_q`` (3N, r) and pivoted: (poses, its
    scaled columns (3N, P), their norms (P,), and :func:`_pivoted`'s pivots, diagonal and basis).

    A block of more than :data:`GRAM_PIVOTING` columns is pivoted through the Gram matrix of its
    projected columns, taken as its own Gram matrix (made once per bases and kept in ``own_grams``
    under ``name``) less X^T X, X = kept_q^T A the block's coordinates in the kept span: the projected
    columns themselves (3N x P, and their product) are never made, a third of the work of projecting
    them on a fine angle table. Its round-off is that of the own Gram matrix, eps times a column's
    norm squared, so a column that only duplicates the kept span keeps ~1e-8 of its norm, well below
    the rank tolerance (tests/test_identifiability_gram.py checks both against projecting the columns)."""
    n_pose = b.n_poses if getattr(b, "n_poses", None) else max(b.g.shape[0], 1)
    cols = (b.g * b.scales).reshape(-1, len(b.names))
    norms = np.linalg.norm(cols, axis=0)
    # columns of equal independent motion (two placement translations along one axis) tie: the
    # pivoting would then follow round-off, which differs between BLAS builds; weights within
    # 1e-9 of one make the earlier column win every exact tie and change nothing else
    tie_break = 1.0 + 1e-9 * np.arange(len(b.names), 0, -1) / max(len(b.names), 1)
    if own_grams is None or len(b.names) <= GRAM_PIVOTING:
        proj = cols if kept_q is None else cols - kept_q @ (kept_q.T @ cols)
        return (n_pose, cols, norms) + _pivoted(proj, tie_break)
    scaled = cols * tie_break
    if name not in own_grams:
        own_grams[name] = scaled.T @ scaled
    gram = own_grams[name]
    if kept_q is not None:
        coordinates = kept_q.T @ scaled
        gram = gram - coordinates.T @ coordinates

    def projected(which: np.ndarray) -> np.ndarray:  # the scaled projected columns ``which`` (3N, len(which))
        chosen = scaled[:, which]
        return chosen if kept_q is None else chosen - kept_q @ (kept_q.T @ chosen)

    return (n_pose, cols, norms) + _gram_pivoted(gram, tie_break, projected)


#: an effect of more columns than this (a fine angle table) is pivoted through the Gram matrix of its
#: projected columns (:func:`_pivoted`)
GRAM_PIVOTING = 256


def _pivoted(proj: np.ndarray, tie_break: np.ndarray):
    """QR with column pivoting of ``proj * tie_break`` (rows, P): (pivots, |R's diagonal| / the pivots'
    tie_break, and a function of the rank giving an orthonormal basis (rows, rank) of the first pivots'
    columns). Beyond :data:`GRAM_PIVOTING` columns, by LAPACK's pivoted Cholesky (``dpstrf``) of their
    Gram matrix: the same pivots (each step takes the column of largest remaining norm, Businger and
    Golub's rule), R's diagonal to ~eps times the largest norm squared over its own value (1e-6
    relative at the smallest of columns a hundredfold apart, tests/test_gram.py: below the rank
    tolerance, as the columns are scaled to their typical sizes), and a
    third of the work of ``dgeqp3`` on a thousand columns; its diagonal stops where the remaining
    columns are numerically zero."""
    if proj.shape[1] <= GRAM_PIVOTING:
        qmat, rmat, piv = linalg.qr(proj * tie_break, mode="economic", pivoting=True)
        return piv, np.abs(np.diag(rmat)) / tie_break[piv[:min(proj.shape)]], lambda rank: qmat[:, :rank]
    scaled = proj * tie_break
    return _gram_pivoted(scaled.T @ scaled, tie_break, lambda which: scaled[:, which])


def _gram_pivoted(gram: np.ndarray, tie_break: np.ndarray, columns):
    """:func:`_pivoted` from the Gram matrix (P, P) of the scaled projected columns; ``columns(which)``
    gives those columns (rows, len(which)) for the basis."""
    from scipy.linalg import lapack

    top = float(np.max(np.diag(gram))) if gram.size else 0.0
    factor, piv, rank_c, _ = lapack.dpstrf(gram, tol=float(np.finfo(float).eps * gram.shape[0] * top), lower=0)
    piv = piv - 1
    diag = np.abs(np.diag(factor))[:rank_c] / tie_break[piv[:rank_c]]

    def basis(rank: int) -> np.ndarray:  # Q = A_k R_k^-1 for the first rank pivots' columns A_k
        return linalg.solve_triangular(np.triu(factor[:rank, :rank]), columns(piv[:rank]).T, trans="T").T

    return piv, diag, basis
