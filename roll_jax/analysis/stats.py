"""The statistics of the analyses: rank correlations, how well latents locate the object
(affine, cross-validated, non-linear fits), paired differences; numpy only."""

from __future__ import annotations

import numpy as np


def distance_unit(task: str) -> tuple[str, float]:
    """(unit, scale) in which results show `task`'s distances: the metrics are in m, shown in
    cm; the door's are angles in rad, shown as they are."""
    return ("rad", 1.0) if task == "door_open" else ("cm", 100.0)


def format_distance(task: str, x: float, sign: str = "") -> str:
    """`x` (m, or rad on the door) in `task`'s unit: "4.31 cm", "0.104 rad"; `sign` "+" signs it."""
    unit, scale = distance_unit(task)
    digits = 3 if unit == "rad" else 2
    return f"{x * scale:{sign}.{digits}f} {unit}"


def rankdata(x) -> np.ndarray:
    """Ranks 1..n of a 1-D array, ties get the average of the ranks they span (like
    scipy.stats.rankdata(method="average"))."""
    x = np.asarray(x, np.float64).ravel()
    n = x.size
    order = np.argsort(x, kind="mergesort")
    xs = x[order]
    starts = np.r_[0, np.flatnonzero(np.diff(xs)) + 1]
    ends = np.r_[starts[1:], n]
    avg = (starts + ends + 1) / 2.0  # mean of the 1-based ranks starts+1 .. ends
    ranks = np.empty(n, np.float64)
    ranks[order] = np.repeat(avg, ends - starts)
    return ranks


def pearson(x, y) -> float:
    """Pearson correlation; NaN when either input is constant."""
    x = np.asarray(x, np.float64).ravel()
    y = np.asarray(y, np.float64).ravel()
    dx, dy = x - x.mean(), y - y.mean()
    den = np.sqrt(np.sum(dx * dx) * np.sum(dy * dy))
    return float(np.sum(dx * dy) / den) if den > 0 else float("nan")


def spearman(x, y) -> float:
    """Spearman rank correlation = Pearson correlation of the (average-tie) ranks."""
    x = np.asarray(x, np.float64).ravel()
    y = np.asarray(y, np.float64).ravel()
    if x.shape != y.shape:
        raise ValueError(f"spearman: x and y must have the same length, got {x.size} and {y.size}")
    if x.size < 2:
        raise ValueError(f"spearman needs at least 2 points, got {x.size}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("spearman: inputs must be finite")
    return pearson(rankdata(x), rankdata(y))


def _r2(predicted, y) -> float:
    """R^2 of predictions of y [n, k], all coordinates pooled."""
    return float(1.0 - np.sum((predicted - y) ** 2) / np.sum((y - y.mean(0)) ** 2))


def _with_bias(z) -> np.ndarray:
    return np.concatenate([z, np.ones((len(z), 1))], 1)


def position_r2(latents, positions) -> float:
    """R^2 of a least-squares affine fit of the object states [n, k] from latents [n, d]
    (all coordinates pooled): how linearly the latents encode where the object is."""
    x = _with_bias(np.asarray(latents, np.float64))
    y = np.asarray(positions, np.float64)
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    return _r2(x @ coef, y)


def affine_cv_r2(features, y, folds: int) -> float:
    """Held-out R^2 of an affine least-squares fit, `folds`-fold cross-validated (fold = index
    mod folds)."""
    x = _with_bias(features)
    fold = np.arange(len(y)) % folds
    predicted = np.empty_like(y)
    for f in range(folds):
        coef, *_ = np.linalg.lstsq(x[fold != f], y[fold != f], rcond=None)
        predicted[fold == f] = x[fold == f] @ coef
    return _r2(predicted, y)


def position_r2_nonlinear(latents, positions, folds: int = 5, k: int = 10) -> dict:
    """Whether the latents hold the object's state although an affine fit misses it: held-out
    R^2 of an affine fit ("affine_cv", `position_r2` without the in-sample fit), of an affine
    fit on the latents and their pairwise products ("quadratic_cv"), and of the mean state of
    each latent's k nearest other latents ("knn"). A curved code scores low on the first and
    high on the other two; a code without the state scores low on all three."""
    z = np.asarray(latents, np.float64)
    y = np.asarray(positions, np.float64)
    if len(z) <= max(folds, k) or len(z) != len(y):
        raise ValueError(f"need matching latents and states, more than max(folds, k) = "
                         f"{max(folds, k)}; got {len(z)} latents and {len(y)} states")
    i, j = np.triu_indices(z.shape[1])
    quad = np.concatenate([z, z[:, i] * z[:, j]], 1)
    sq = np.sum(z * z, 1)
    d = sq[:, None] + sq[None] - 2.0 * z @ z.T  # [n, n], not [n, n, d]: --n may be large
    np.fill_diagonal(d, np.inf)
    knn = y[np.argpartition(d, k, axis=1)[:, :k]].mean(1)
    return {"affine_cv": affine_cv_r2(z, y, folds), "quadratic_cv": affine_cv_r2(quad, y, folds),
            "knn": _r2(knn, y)}


def pairwise_spearman(latents, positions, max_n: int = 300) -> float:
    """Spearman of latent distance vs object-state distance over all pairs of the first
    `max_n` observations."""
    z = np.asarray(latents, np.float64)[:max_n]
    y = np.asarray(positions, np.float64)[:max_n]
    i, j = np.triu_indices(len(z), 1)
    return spearman(np.linalg.norm(y[i] - y[j], axis=-1), np.linalg.norm(z[i] - z[j], axis=-1))


def paired_difference(a, b) -> list[float]:
    """[mean, standard error] of a - b over paired per-query errors."""
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    return [float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else 0.0]


def finite_or_none(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


def rounded_list(a) -> list:
    return [round(float(v), 6) for v in np.asarray(a).ravel()]
