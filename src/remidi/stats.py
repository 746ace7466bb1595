"""Statistics over seeds, as the field reports them (Agarwal et al., NeurIPS 2021, "Deep RL at the
edge of the statistical precipice"; the ``rliable`` library).

Pure NumPy/SciPy functions of per-seed values. A *sample* is f[n]: one value per seed. Where a
metric is pooled over several tasks (strata, e.g. four Brax morphologies), the values come with
a label per value, and every resampling happens within each stratum (the stratified bootstrap).

- :func:`mean_and_sample_std`: mean and sample standard deviation (ddof 1).
- :func:`iqm`: interquartile mean, ``scipy.stats.trim_mean(x, 0.25)`` as in ``rliable``.
- :func:`bootstrap_ci`: percentile-bootstrap confidence interval (``scipy.stats.bootstrap``),
  stratified when strata are given.
- :func:`probability_of_improvement`: P(X > Y) + ½ P(X = Y), averaged over strata, with its
  stratified-bootstrap confidence interval.
- :func:`permutation_pvalue`: one-sided permutation p-value of the difference of means, exact
  for up to 10⁶ arrangements (every design with at most 10 seeds per group).
- :func:`holm`: Holm–Bonferroni adjusted p-values for the comparisons of one claim.

Undefined values (NaN) make every result NaN: a seed that did not produce a number is not
silently left out.

Why the *percentile* bootstrap (not BCa): it is ``rliable``'s default, so intervals compare with
the field's; it stays defined on discrete, tied data (solve rates of 0 on several seeds), where
BCa's jackknife acceleration is undefined or unstable and SciPy raises a degenerate-data warning;
and the same method serves the stratified case. With few seeds every bootstrap interval is too
narrow (it undercovers); a test's verdict should rest on the permutation p-value or the
probability of improvement's interval, not on overlapping intervals of means.
"""

from __future__ import annotations

import itertools
import math
from typing import Callable, NamedTuple, Sequence

import numpy as np
import scipy.stats

N_RESAMPLES = 10_000  # bootstrap resamples; Monte Carlo error of a 2.5% quantile ≈ 0.0016 of the spread
MAX_EXACT = 1_000_000  # permutation arrangements enumerated exactly (C(20, 10) = 184,756; 2^10 = 1,024)


class Estimate(NamedTuple):
    """A point estimate and its confidence interval [low, high]."""

    value: float
    low: float
    high: float


def _sample(values) -> np.ndarray:
    """``values`` as a float array f[n] (``None`` → NaN)."""
    return np.asarray([math.nan if v is None else v for v in np.ravel(np.asarray(values, dtype=object))],
                      dtype=float)


def mean_and_sample_std(values) -> tuple[float, float]:
    """Mean and sample standard deviation (ddof 1) of ``values`` f[n]. The std is NaN for one
    value (it is undefined), and both are NaN for none."""
    x = _sample(values)
    if x.size == 0:
        return math.nan, math.nan
    return float(x.mean()), float(x.std(ddof=1)) if x.size > 1 else math.nan


def iqm(values, axis: int = -1):
    """Interquartile mean of ``values`` f[..., n] along ``axis``: the mean of the middle 50%,
    ``scipy.stats.trim_mean(x, 0.25)`` as ``rliable`` defines it (⌊n/4⌋ values cut at each end:
    of 10 seeds the middle 6, of 4 seeds the middle 2)."""
    return scipy.stats.trim_mean(np.asarray(values, dtype=float), 0.25, axis=axis)


def _strata(values: np.ndarray, strata) -> list[np.ndarray]:
    """``values`` f[n] split by the labels ``strata`` [n] (in order of first appearance), or [values]."""
    if strata is None:
        return [values]
    labels = list(strata)
    if len(labels) != len(values):
        raise ValueError(f"strata: {len(labels)} labels for {len(values)} values")
    order = list(dict.fromkeys(labels))
    return [values[[i for i, s in enumerate(labels) if s == label]] for label in order]


def _interval(samples: list[np.ndarray], statistic: Callable, confidence: float, n_resamples: int,
              seed: int, method: str) -> tuple[float, float]:
    """``scipy.stats.bootstrap`` over ``samples`` (each resampled independently, with its own
    size: the stratified bootstrap); ``statistic(*samples, axis)`` vectorised along ``axis``."""
    if any(s.size < 2 for s in samples) or any(np.isnan(s).any() for s in samples):
        return math.nan, math.nan  # one value per stratum gives no spread to resample; NaN is undefined
    if all(np.all(s == s[0]) for s in samples):  # every resample is the sample itself (BCa would fail)
        value = float(statistic(*samples, axis=-1))
        return value, value
    res = scipy.stats.bootstrap(tuple(samples), statistic, n_resamples=n_resamples, vectorized=True,
                                axis=-1, confidence_level=confidence, method=method,
                                rng=np.random.default_rng(seed))
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def bootstrap_ci(values, statistic: Callable = np.mean, *, strata=None, confidence: float = 0.95,
                 n_resamples: int = N_RESAMPLES, seed: int = 0, method: str = "percentile") -> tuple[float, float]:
    """Bootstrap confidence interval ``(low, high)`` of ``statistic(values)`` over seeds.

    ``values`` f[n]; ``statistic(x, axis)`` vectorised along ``axis`` (``np.mean``, :func:`iqm`).
    ``strata`` [n]: a label per value (the task each seed ran on): resamples then draw seeds with
    replacement within each stratum, keeping its size, and ``statistic`` is taken over all of
    them pooled (rliable's stratified bootstrap). SciPy's ``bootstrap`` does this itself: each
    stratum is passed as its own sample, and SciPy resamples samples independently; no resampler
    is written here. Without strata (one algorithm on one task) it is the ordinary bootstrap.

    ``method``: ``"percentile"`` (default; module docstring for why) or ``"BCa"``. A sample
    whose every stratum is constant gives ``(v, v)`` with ``v`` the statistic (no resample
    differs); a stratum of fewer than two values, or a NaN, gives ``(nan, nan)``. Deterministic
    for a given ``seed``.
    """
    samples = _strata(_sample(values), strata)

    def pooled(*xs, axis=-1):
        return statistic(np.concatenate(xs, axis=axis), axis=axis)

    return _interval(samples, pooled, confidence, n_resamples, seed, method)


def difference_ci(x, y, *, confidence: float = 0.95, n_resamples: int = N_RESAMPLES,
                  seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval ``(low, high)`` of mean(x) − mean(y), the two groups
    (independent seeds, f[n] and f[m]) resampled independently; ``(nan, nan)`` as
    :func:`bootstrap_ci` for a group of fewer than two values or a NaN."""
    return _interval([_sample(x), _sample(y)], _mean_difference, confidence, n_resamples, seed, "percentile")


def _poi(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """P(X > Y) + ½ P(X = Y) over all pairs, f[...] from x f[..., n] and y f[..., m]."""
    x, y = x[..., :, None], y[..., None, :]
    return np.mean((x > y) + 0.5 * (x == y), axis=(-2, -1))


def probability_of_improvement(x, y, *, x_strata=None, y_strata=None, confidence: float = 0.95,
                               n_resamples: int = N_RESAMPLES, seed: int = 0) -> Estimate:
    """Probability that a run of X beats a run of Y, with its bootstrap confidence interval.

    ``x`` f[n], ``y`` f[m] (e.g. an algorithm's and a baseline's per-seed scores). The estimate is
    P(X > Y) + ½ P(X = Y) over all n·m pairs, i.e. the Mann–Whitney U statistic / (n·m)
    (rliable's ``probability_of_improvement``). With strata (``x_strata`` [n], ``y_strata`` [m],
    the same labels on both sides), it is the average over strata of the per-stratum value.
    The interval resamples x and y independently, within each stratum (stratified percentile
    bootstrap, :func:`bootstrap_ci`). 0.5 means no difference; a lower bound above 0.5 is
    rliable's sense of "X is better than Y".
    """
    xs, ys = _strata(_sample(x), x_strata), _strata(_sample(y), y_strata)
    if (x_strata is None) != (y_strata is None) or (
            x_strata is not None and list(dict.fromkeys(x_strata)) != list(dict.fromkeys(y_strata))):
        raise ValueError("x_strata and y_strata must name the same strata in the same order")
    k = len(xs)
    if any(s.size == 0 for s in xs + ys) or any(np.isnan(s).any() for s in xs + ys):
        return Estimate(math.nan, math.nan, math.nan)

    def statistic(*samples, axis=-1):
        samples = [np.moveaxis(s, axis, -1) for s in samples]
        return np.mean([_poi(a, b) for a, b in zip(samples[:k], samples[k:])], axis=0)

    low, high = _interval(xs + ys, statistic, confidence, n_resamples, seed, "percentile")
    return Estimate(float(statistic(*xs, *ys)), low, high)


def _mean_difference(x, y, axis=-1):
    return np.mean(x, axis=axis) - np.mean(y, axis=axis)


def permutation_count(n: int, m: int, paired: bool) -> int:
    """How many arrangements an exact permutation test enumerates: 2ⁿ sign flips for n pairs;
    C(n+m, n) relabellings of two independent groups."""
    return 2 ** n if paired else math.comb(n + m, n)


def permutation_pvalue(x, y, paired: bool = False, alternative: str = "greater", *, max_exact: int = MAX_EXACT,
                       n_resamples: int = 99_999, seed: int = 0) -> float:
    """One-sided permutation p-value of mean(x) − mean(y) (``alternative="greater"``: X > Y).

    ``x`` f[n], ``y`` f[m]. ``paired`` (same seeds, x[i] and y[i] from seed i, n = m): the null
    swaps x[i] and y[i] within each pair (``permutation_type="samples"``); otherwise it
    relabels the pooled values (``"independent"``). ``scipy.stats.permutation_test`` enumerates
    every arrangement (``n_resamples=np.inf``: exact) when there are at most ``max_exact``
    (:func:`permutation_count`; always for ≤ 10 seeds per group), else draws ``n_resamples``
    of them with ``seed``; the exact independent case is SciPy's count computed at once
    (:func:`_exact_independent_pvalue`). The p-value counts the observed arrangement: full separation of 3
    against 3 gives 1/20, four pairs all in favour 1/16. NaN anywhere gives NaN.
    """
    x, y = _sample(x), _sample(y)
    if paired and x.size != y.size:
        raise ValueError(f"paired: {x.size} values against {y.size}; pairs need the same seeds")
    if x.size == 0 or y.size == 0 or np.isnan(x).any() or np.isnan(y).any():
        return math.nan
    exact = permutation_count(x.size, y.size, paired) <= max_exact
    if exact and not paired:
        return _exact_independent_pvalue(x, y, alternative)
    res = scipy.stats.permutation_test((x, y), _mean_difference, vectorized=True, alternative=alternative,
                                       permutation_type="samples" if paired else "independent",
                                       n_resamples=np.inf if exact else n_resamples,
                                       rng=np.random.default_rng(seed))
    return float(res.pvalue)


def _exact_independent_pvalue(x: np.ndarray, y: np.ndarray, alternative: str) -> float:
    """``scipy.stats.permutation_test``'s exact independent-samples p-value, computed at once.

    SciPy builds its C(n+m, n) relabellings one by one in Python (2.5 s for 10 seeds against 10,
    and the results page makes two dozen such tests); here the same relabellings (x's indices
    in increasing order, the rest in increasing order, as SciPy's) are one index array, their
    statistics one vectorised mean difference, and the p-value counts them as SciPy does
    (values within 100 ulps of the observed one count as equal to it). Checked against SciPy in
    tests/test_stats.py.
    """
    pooled, n = np.concatenate([x, y]), x.size
    total, count = pooled.size, math.comb(pooled.size, x.size)
    first = np.fromiter(itertools.chain.from_iterable(itertools.combinations(range(total), n)),
                        dtype=np.intp, count=count * n).reshape(count, n)  # [count, n]
    chosen = np.zeros((count, total), dtype=bool)
    np.put_along_axis(chosen, first, True, axis=1)
    rest = np.nonzero(~chosen)[1].reshape(count, total - n)  # [count, m], increasing in each row
    null = _mean_difference(pooled[first], pooled[rest])  # f[count]
    observed = _mean_difference(x, y)
    gamma = abs(np.finfo(observed.dtype).eps * 100 * observed)
    greater = np.count_nonzero(null >= observed - gamma) / count
    less = np.count_nonzero(null <= observed + gamma) / count
    p = {"greater": greater, "less": less, "two-sided": 2 * min(greater, less)}[alternative]
    return float(min(p, 1.0))


def holm(pvalues: Sequence[float]) -> np.ndarray:
    """Holm–Bonferroni adjusted p-values f[k] of the k comparisons of one claim.

    Sorted ascending, the i-th smallest (i = 0 … k−1) is multiplied by k − i, and each adjusted
    value is raised to the largest before it (capped at 1): reject comparison j at level α when
    its adjusted value is < α. This controls the family-wise error rate like Bonferroni (p·k)
    under any dependence between the comparisons and is never more conservative than it, which
    is why it is used here. NaN entries (comparisons not made) stay NaN and do not count in k.
    """
    p = np.asarray(pvalues, dtype=float)
    out = np.full(p.shape, math.nan)
    idx = np.flatnonzero(np.isfinite(p))
    order = idx[np.argsort(p[idx], kind="stable")]
    k = order.size
    out[order] = np.minimum(1.0, np.maximum.accumulate((k - np.arange(k)) * p[order]))
    return out
