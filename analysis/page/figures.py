"""Figures of the report, drawn from the tables in stats/anova.py (no statistics computed here).

ratings_histogram: the paper's Fig. 5 (responses per scale point and condition, vertical lines at the means);
per_clip_means: Fig. 6 (mean rating of every clip, sorted worst to best within each condition);
condition_means: means with t and cluster-bootstrap 95% intervals, with and without the rater exclusion;
metric_scatter: each objective metric against the per-clip mean rating;
ordinal_fit: the ordinal mixed model's predicted rating distribution per condition beside the observed one;
power_curve: the power planner's estimated power against the number of raters.
"""

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from moglow_eval.core import study

# Okabe-Ito colour-blind-safe palette; the paper's three conditions keep fixed colours across figures.
FIXED = dict(zip(study.RESERVED, ("#009E73", "#0072B2", "#D55E00", "#7F7F7F")))  # NAT, MG, FL, BAD
EXTRA = ["#CC79A7", "#E69F00", "#56B4E9", "#F0E442", "#000000"]
STYLE = {
    "font.size": 9,
    "axes.titlesize": 10,
    "axes.labelsize": 9,
    "legend.fontsize": 8,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.linewidth": 0.8,
    "savefig.dpi": 200,
    "savefig.bbox": "tight",
    "font.family": "DejaVu Sans",
}


def text(label):
    """A name from the data as literal plot text: matplotlib would read "$...$" as mathematics (and stop on
    a malformed formula), so dollar signs are escaped."""
    return str(label).replace("$", r"\$")


def colours(conditions):
    out, extra = {}, iter(EXTRA * 10)
    for c in conditions:
        out[c] = FIXED.get(c) or next(extra)
    return out


def subplots(*args, **kwargs):
    """(figure, axes) as pyplot.subplots gives them, but a bare Figure: no pyplot state and no backend choice,
    which belong to the program that imports the analysis, not to the analysis."""
    fig = Figure(figsize=kwargs.pop("figsize", None))
    return fig, fig.subplots(*args, **kwargs)


def _save(fig, path):
    fig.savefig(path)
    return path


def legend_beside(ax, title):
    """The axes' legend outside them, to their right, top-aligned: it covers no data however the data fall."""
    ax.legend(frameon=False, loc="upper left", bbox_to_anchor=(1.01, 1.0), title=title, title_fontsize=8,
              alignment="left")  # fmt: skip


def ratings_histogram(hist, means, path, title=None):
    """hist: rating_histogram() table (rows conditions, columns 1..5); means: {condition: mean}."""
    conds = list(hist.index)
    col = colours(conds)
    scale = [int(s) for s in hist.columns]
    with matplotlib.rc_context(STYLE):
        fig, ax = subplots(figsize=(7.8, 3.4))
        width = 0.8 / len(conds)
        top = hist.to_numpy().max()
        for i, c in enumerate(conds):
            x = np.array(scale) + (i - (len(conds) - 1) / 2) * width
            ax.bar(
                x,
                hist.loc[c].to_numpy(),
                width=width * 0.95,
                color=col[c],
                alpha=0.85,
                label=f"{text(c)} (n={int(hist.loc[c].sum()):,}, mean {means[c]:.2f})",
                zorder=2,
            )
            ax.axvline(means[c], color=col[c], lw=1.6, ls="--", zorder=3)
            ax.text(
                means[c],
                top * (1.04 + 0.07 * i),
                f" {means[c]:.2f}",
                color=col[c],
                fontsize=7.5,
                ha="left",
                va="center",
            )
        ax.set_xticks(scale)
        ax.set_xticklabels(
            [f"{s}\n{lab}" for s, lab in zip(scale, ["very\nunnatural", "", "", "", "very\nnatural"])], linespacing=0.9
        )
        ax.set_xlabel("Rating")
        ax.set_ylabel("Number of responses")
        ax.set_ylim(0, top * (1.1 + 0.07 * len(conds)))
        ax.set_xlim(scale[0] - 0.6, scale[-1] + 0.6)
        ax.grid(axis="y", color="0.9", lw=0.6, zorder=0)
        legend_beside(ax, "Condition (dashed: mean)")  # inside, it would cover the mean lines and their labels
        if title:
            ax.set_title(title, loc="left")
        return _save(fig, path)


def per_clip_means(clips, path, title=None):
    """clips: per_clip_means() table (sorted within condition, with rank, mean, ci_low, ci_high)."""
    conds = list(dict.fromkeys(clips["condition"]))
    col = colours(conds)
    with matplotlib.rc_context(STYLE):
        fig, ax = subplots(figsize=(6.4, 3.4))
        most = clips.groupby("condition").size().max()
        ms = 3.5 if most <= 60 else 1.5 if most <= 400 else 0.0
        for c in conds:
            part = clips[clips["condition"] == c]
            x = part["rank"].to_numpy()
            ax.fill_between(
                x, part["ci_low"].clip(1, 5), part["ci_high"].clip(1, 5), color=col[c], alpha=0.13, lw=0, step=None
            )
            ax.plot(
                x,
                part["mean"],
                color=col[c],
                lw=1.3,
                marker="o" if ms else None,
                ms=ms,
                label=f"{text(c)} ({len(part)} clips)",
            )
        ax.set_xlabel("Clip, sorted from worst to best within condition")
        ax.set_ylabel("Mean rating")
        ax.set_ylim(0.9, 5.1)
        ax.set_yticks([1, 2, 3, 4, 5])
        ax.set_xlim(0.5, most + 0.5)
        ax.grid(axis="y", color="0.9", lw=0.6, zorder=0)
        # Inside, the corner left empty by rising lines is where a condition rated low on every clip draws its own
        # (a weak system, or a stochastic one with many samples).
        legend_beside(ax, "Shaded: 95% t interval per clip")
        if title:
            ax.set_title(title, loc="left")
        return _save(fig, path)


def condition_means(panels, path):
    """panels: list of (label, summary table with mean, t_low, t_high, boot_low, boot_high per condition)."""
    conds = list(dict.fromkeys(c for _, t in panels for c in t.index))
    col = colours(conds)
    with matplotlib.rc_context(STYLE):
        fig, ax = subplots(figsize=(6.4, 0.55 * len(conds) * len(panels) + 1.2))
        y, ticks, labels = 0, [], []
        markers = ["o", "s", "^", "D"]
        for c in conds:
            for j, (label, t) in enumerate(panels):
                if c not in t.index:
                    continue
                row = t.loc[c]
                ax.plot(
                    [row["t_low"], row["t_high"]], [y + 0.12, y + 0.12], color=col[c], lw=2.2, solid_capstyle="butt"
                )
                if "boot_low" in row and np.isfinite(row["boot_low"]):
                    ax.plot(
                        [row["boot_low"], row["boot_high"]],
                        [y - 0.12, y - 0.12],
                        color=col[c],
                        lw=2.2,
                        alpha=0.45,
                        solid_capstyle="butt",
                    )
                ax.plot(row["mean"], y, marker=markers[j % 4], color=col[c], mec="white", ms=6, zorder=3)
                ticks.append(y)
                labels.append(f"{text(c)} — {label}")
                y -= 1
            y -= 0.4
        ax.set_yticks(ticks)
        ax.set_yticklabels(labels)
        ax.set_xlabel("Mean rating (upper bar: t 95% CI; lower, faint: cluster-bootstrap 95% CI)")
        ax.grid(axis="x", color="0.9", lw=0.6, zorder=0)
        ax.spines["left"].set_visible(False)
        ax.tick_params(axis="y", length=0)
        return _save(fig, path)


def metric_scatter(clips, metrics, corr, path):
    """One panel per metric: metric value vs per-clip mean rating, coloured by condition, pooled Spearman rho."""
    merged = clips.set_index("clip_id").join(metrics, how="inner")
    names = list(metrics.columns)
    conds = list(dict.fromkeys(clips["condition"]))
    col = colours(conds)
    ncol = min(4, len(names))
    nrow = int(np.ceil(len(names) / ncol))
    with matplotlib.rc_context(STYLE):
        fig, axes = subplots(nrow, ncol, figsize=(1.75 * ncol + 0.6, 1.9 * nrow + 0.4), sharey=True, squeeze=False)
        for ax, m in zip(axes.ravel(), names):
            for c in conds:
                part = merged[merged["condition"] == c]
                ax.scatter(part[m], part["mean"], s=9, color=col[c], alpha=0.8, lw=0, label=text(c))
            row = corr[(corr["metric"] == m) & (corr["scope"] == "all")]
            rho = row["spearman_rho"].iloc[0] if len(row) else np.nan
            ax.set_title(f"{text(m)}\nSpearman ρ = {rho:.2f}" if np.isfinite(rho) else text(m), fontsize=8.5)
            ax.set_ylim(0.9, 5.1)
            ax.grid(color="0.92", lw=0.5)
            ax.tick_params(labelsize=7)
        for ax in axes.ravel()[len(names) :]:
            ax.set_visible(False)
        for ax in axes[:, 0]:
            ax.set_ylabel("Clip mean rating")
        axes.ravel()[0].legend(frameon=False, fontsize=7, loc="lower left", handletextpad=0.1)
        fig.tight_layout()
        return _save(fig, path)


def ordinal_fit(model, path):
    """model: rating_models.ordinal_model() dict. One panel per condition: observed share of each rating (bars) and the
    fitted population-averaged distribution (dots), so a misfit of the cumulative-logit model shows at a glance."""
    conds = list(model["observed_distribution"])
    col = colours(conds)
    levels = list(next(iter(model["observed_distribution"].values())))
    x = np.arange(len(levels))
    with matplotlib.rc_context(STYLE):
        fig, axes = subplots(1, len(conds), figsize=(2.3 * len(conds) + 0.6, 2.6), sharey=True, squeeze=False)
        for ax, c in zip(axes[0], conds):
            obs = [model["observed_distribution"][c][k] for k in levels]
            fit = [model["fitted_distribution"][c][k] for k in levels]
            ax.bar(x, obs, width=0.7, color=col[c], alpha=0.75, label="observed", zorder=2)
            ax.plot(x, fit, "o-", color="black", ms=4, lw=1, label="fitted", zorder=3)
            ax.set_xticks(x)
            ax.set_xticklabels(levels)
            ax.set_title(text(c), loc="left")
            ax.set_xlabel("Rating")
            ax.grid(axis="y", color="0.9", lw=0.6, zorder=0)
        axes[0, 0].set_ylabel("Share of responses")
        axes[0, -1].legend(frameon=False, loc="upper left", bbox_to_anchor=(1.0, 1.0))
        return _save(fig, path)


def power_curve(curve, target, path, title=None):
    """curve: analysis.plan.plan()'s table (raters, ratings_per_clip, power, low, high, and where planned the clips'
    decision's clip_power, clip_low, clip_high); target: the power asked."""
    with matplotlib.rc_context(STYLE):
        fig, ax = subplots(figsize=(6.0, 3.4))
        ax.fill_between(
            curve["raters"],
            curve["low"],
            curve["high"],
            color="#0072B2",
            alpha=0.18,
            lw=0,
            label="95% Monte Carlo interval",
        )
        on_ratings = "Tukey HSD on the ratings (the report's)" if "clip_power" in curve else "estimated power"
        ax.plot(curve["raters"], curve["power"], "o-", color="#0072B2", ms=3.5, lw=1.4, label=on_ratings)
        if "clip_power" in curve:  # the decision that counts the clips: more raters lift it only so far
            ax.fill_between(curve["raters"], curve["clip_low"], curve["clip_high"], color="#009E73", alpha=0.18, lw=0)
            ax.plot(
                curve["raters"], curve["clip_power"], "s-", color="#009E73", ms=3, lw=1.4,
                label="Tukey HSD on the clips' means",
            )  # fmt: skip
        ax.axhline(target, color="#D55E00", ls="--", lw=1, label=f"target {target:g}")
        ax.set_xlabel("Raters in total")
        ax.set_ylabel("Power")
        ax.set_ylim(0, 1.02)
        ax.grid(color="0.92", lw=0.5)
        top = ax.secondary_xaxis(
            "top",
            functions=(
                lambda r: r * curve.attrs["per_clip_per_rater"],
                lambda k: k / curve.attrs["per_clip_per_rater"],
            ),
        )
        top.set_xlabel("Ratings per clip")
        ax.legend(frameon=False, loc="best")  # the clips' curve can lie flat along the bottom
        if title:
            ax.set_title(text(title), loc="left", fontsize=9)
        return _save(fig, path)
