"""The power of a rating study's decision for one pair of conditions, from whole studies simulated under the
linear mixed model (rating = condition mean + rater effect + clip effect + residual), as analysis.plan plans with
it: Tukey's HSD on the ratings (the report's decision) or on the clips' mean ratings."""

import math

import numpy as np

from . import anova


def simulate_power(design, pair, n_raters, n_sim=1000, alpha=0.05, seed=0, chunk=100, progress=None, unit="rating"):
    """The share of simulated studies with `n_raters` raters in which Tukey's HSD separates the two conditions of
    `pair`: on the ratings (`unit="rating"`, the report's decision) or on the clips' mean ratings (`unit="clip"`,
    a decision that counts the clips as the sample they are, as the mixed model does).

    Parameters
    ----------
    design : dict
        As from `pilot_design`.
    pair : tuple of str
        The two conditions compared.
    n_raters : int
        The raters of each simulated study.
    n_sim : int
        The number of studies simulated.
    alpha : float
        The family-wise error rate of the test.
    seed : int
        The seed of the simulation.
    chunk : int
        The studies simulated at once.
    progress : tqdm or None
        A progress bar updated by the studies simulated.
    unit : {"rating", "clip"}
        What Tukey's HSD takes as its observations.

    Returns
    -------
    power : float
        The share of studies in which the pair differs.
    low, high : float
        Its 95% Monte Carlo (Wilson) interval.

    Notes
    -----
    Tukey's decision for a pair (p_adj < alpha) is q > the studentized-range quantile at 1 - alpha, with
    q = |mean difference| / sqrt(MSE / 2 (1/n_i + 1/n_j)) and MSE the pooled within-condition variance,
    computed here from group sums for a whole chunk of studies at once. With `unit="clip"` the observations are
    the clips' mean ratings (each clip rated at least once), n_i the clips of condition i and the error's degrees
    of freedom the rated clips less K: its false-positive rate stays at alpha however many raters share a clip,
    where the ratings' rises with them (the ratings of one clip share its effect).
    """
    if unit not in ("rating", "clip"):
        raise ValueError(f"unit must be 'rating' or 'clip', got {unit!r}")
    conds = design["conditions"]
    K, C, m = len(conds), design["clips_per_condition"], design["clips_per_rater"]
    n_clips = K * C
    m = min(m, n_clips)
    mu = np.array([design["means"][c] for c in conds])
    a, b = conds.index(pair[0]), conds.index(pair[1])
    clip_cond = np.repeat(np.arange(K), C)
    N = n_raters * m
    df_w = N - K
    if df_w < 1 or (unit == "clip" and n_raters * m <= K):
        return 0.0, 0.0, 1.0
    rng = np.random.default_rng(seed)
    rejected = 0
    for start in range(0, n_sim, chunk):
        S = min(chunk, n_sim - start)
        # each rater's clips: the first m of a random permutation (all clips when m = n_clips)
        keys = rng.random((S, n_raters, n_clips))
        clips = (
            np.argpartition(keys, m - 1, axis=2)[:, :, :m]
            if m < n_clips
            else np.broadcast_to(np.arange(n_clips), (S, n_raters, n_clips))
        )
        u_r = rng.normal(0, design["sd_rater"], (S, n_raters, 1))
        u_c = rng.normal(0, design["sd_clip"], (S, n_clips))
        e = rng.normal(0, design["sd_residual"], (S, n_raters, m))
        cond = clip_cond[clips]
        y = mu[cond] + u_r + np.take_along_axis(u_c[:, None, :].repeat(n_raters, 1), clips, axis=2) + e
        if unit == "rating":
            idx = (np.arange(S)[:, None, None] * K + cond).ravel()
            yv = y.ravel()
            n = np.bincount(idx, minlength=S * K).reshape(S, K)
            s1 = np.bincount(idx, yv, minlength=S * K).reshape(S, K)
            s2 = np.bincount(idx, yv * yv, minlength=S * K).reshape(S, K)
            df = np.full(S, df_w)
        else:
            n, s1, s2, df = _clip_mean_sums(y, clips, clip_cond, K)
        rejected += _tukey_rejections(n, s1, s2, df, a, b, alpha)
        if progress is not None:
            progress.update(S)
    p = rejected / n_sim
    z = 1.959963984540054
    centre = (p + z * z / (2 * n_sim)) / (1 + z * z / n_sim)
    half = z * math.sqrt(p * (1 - p) / n_sim + z * z / (4 * n_sim**2)) / (1 + z * z / n_sim)
    return p, max(0.0, centre - half), min(1.0, centre + half)


def with_difference(design, pair, difference):
    """The design with the pair's means set `difference` apart (second minus first), others unchanged."""
    means = dict(design["means"])
    means[pair[1]] = means[pair[0]] + difference
    return {**design, "means": means}


def _clip_mean_sums(y, clips, clip_cond, K):
    """A chunk's studies (y, clips: [S, raters, m]) as Tukey's HSD on the clips' mean ratings sees them: per study
    and condition the rated clips, the sum and the sum of squares of their means [S, K], and the error's degrees of
    freedom [S] (the rated clips less K)."""
    S, n_clips = y.shape[0], len(clip_cond)
    at = (np.arange(S)[:, None, None] * n_clips + clips).ravel()
    count = np.bincount(at, minlength=S * n_clips).reshape(S, n_clips)
    total = np.bincount(at, y.ravel(), minlength=S * n_clips).reshape(S, n_clips)
    rated = count > 0
    clip_mean = np.where(rated, total / np.maximum(count, 1), 0.0)
    one_hot = clip_cond[None, :] == np.arange(K)[:, None]  # [K, clips]
    return rated.astype(float) @ one_hot.T, clip_mean @ one_hot.T, (clip_mean**2) @ one_hot.T, rated.sum(1) - K


def _tukey_rejections(n, s1, s2, df, a, b, alpha):
    """How many studies Tukey's HSD separates conditions a and b in, from each study's per-condition counts, sums
    and sums of squares [S, K] and its error's degrees of freedom [S]: q = |mean difference| / sqrt(MSE / 2
    (1/n_a + 1/n_b)) against the studentized-range quantile, one quantile per distinct df."""
    K = n.shape[1]
    with np.errstate(invalid="ignore", divide="ignore"):
        means = s1 / n
        mse = np.nansum(s2 - s1 * means, axis=1) / df
        q = np.abs(means[:, b] - means[:, a]) / np.sqrt(mse / 2 * (1 / n[:, a] + 1 / n[:, b]))
    rejected = 0
    for d in np.unique(df[df >= 1]):  # the ratings' one df; the clips' differ only where a clip went unrated
        rejected += int(np.sum(q[df == d] > anova.tukey_qcrit(alpha, K, int(d))))
    return rejected
