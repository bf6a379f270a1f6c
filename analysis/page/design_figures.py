"""Figures of the pairwise and parallel reports, drawn from the tables of
analysis.designs.pairwise.preference and analysis.designs.parallel.mushra.

preference_bars: one horizontal bar per pair of conditions, split into the five answer levels (as in the GENEA
challenge reports): the left condition's clear and slight wins, no preference, the right condition's slight and
clear wins; bradley_terry: log strengths with bootstrap intervals; parallel_boxplot: the 0-100 ratings per
condition, with the means marked.
"""

import textwrap

import matplotlib

from .figures import STYLE, _save, colours, subplots, text

LEVEL_COLOURS = ("#1b7837", "#7fbf7b", "#d9d9d9", "#af8dc3", "#762a83")
LEVEL_NAMES = ("clearly", "slightly", "no preference", "slightly", "clearly")


def preference_bars(pairs, path, title=None):
    """Stacked shares of the five answer levels per pair; `pairs` from pairwise.pair_counts."""
    keys = ("share_a_clearly", "share_a_slightly", "share_none", "share_b_slightly", "share_b_clearly")
    with matplotlib.rc_context(STYLE):
        fig, ax = subplots(figsize=(6.4, 0.55 * len(pairs) + 1.2))
        for row_i, (_, r) in enumerate(pairs.iloc[::-1].iterrows()):
            left = 0.0
            for k, (key, colour) in enumerate(zip(keys, LEVEL_COLOURS)):
                share = float(r[key])
                ax.barh(
                    row_i,
                    share,
                    left=left,
                    color=colour,
                    edgecolor="white",
                    linewidth=0.5,
                    label=None
                    if row_i
                    else (f"{'left' if k < 2 else 'right'} {LEVEL_NAMES[k]}" if k != 2 else LEVEL_NAMES[k]),
                )
                if share >= 0.07:
                    ax.text(
                        left + share / 2,
                        row_i,
                        f"{100 * share:.0f}",
                        ha="center",
                        va="center",
                        fontsize=7,
                        color="white" if k in (0, 4) else "black",
                    )
                left += share
            ax.text(-0.01, row_i, text(r["condition_a"]), ha="right", va="center")
            ax.text(1.01, row_i, f"{text(r['condition_b'])}  (n={int(r['n'])})", ha="left", va="center")
        ax.set_yticks([])
        ax.set_xlim(0, 1)
        ax.set_xlabel("share of answers (%): preferred the left condition ... preferred the right condition")
        ax.set_xticks([0, 0.25, 0.5, 0.75, 1])
        ax.set_xticklabels(["0", "25", "50", "75", "100"])
        ax.axvline(0.5, color="black", lw=0.6, ls=":")
        ax.spines["left"].set_visible(False)
        ax.legend(ncol=5, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False, fontsize=7)
        if title:
            ax.set_title(text(title), pad=24)
        return _save(fig, path)


def bradley_terry(bt, path, title=None):
    """Log strengths (reference 0) with their bootstrap intervals, strongest on top."""
    order = sorted(bt["strengths"], key=bt["strengths"].get)
    col = colours(order)
    with matplotlib.rc_context(STYLE):
        fig, ax = subplots(figsize=(5.0, 0.45 * len(order) + 1.0))
        for i, c in enumerate(order):
            lo, hi = bt["ci"][c]
            ax.plot([lo, hi], [i, i], color=col[c], lw=2)
            ax.plot(bt["strengths"][c], i, "o", color=col[c])
        ax.set_yticks(range(len(order)))
        ax.set_yticklabels([text(c) for c in order])
        ax.axvline(0, color="black", lw=0.6, ls=":")
        ax.set_xlabel(
            f"log strength (Bradley-Terry-Davidson), {text(bt['reference'])} = 0; "
            f"{round(100 * bt['level'])}% bootstrap over raters"
        )
        if title:
            ax.set_title(text(title))
        return _save(fig, path)


def parallel_boxplot(t, summary, path, title=None):
    """Box plot of the 0-100 test ratings per condition (means as white diamonds)."""
    conds = list(summary.index)
    col = colours(conds)
    with matplotlib.rc_context(STYLE):
        fig, ax = subplots(figsize=(1.0 + 0.9 * len(conds), 3.6))
        data = [t.loc[t["condition"] == c, "rating"].to_numpy() for c in conds]
        box = ax.boxplot(
            data,
            patch_artist=True,
            widths=0.6,
            medianprops={"color": "black"},
            flierprops={"markersize": 2, "alpha": 0.4},
        )
        for patch, c in zip(box["boxes"], conds):
            patch.set_facecolor(col[c])
            patch.set_alpha(0.75)
        ax.plot(
            range(1, len(conds) + 1),
            summary["mean"],
            "D",
            color="white",
            markeredgecolor="black",
            markersize=5,
            label="mean",
        )
        ax.set_xticks(range(1, len(conds) + 1))
        ax.set_xticklabels([text(c) for c in conds])
        ax.set_ylim(-2, 102)
        ax.set_ylabel("rating (0-100)")
        ax.legend(frameon=False, loc="lower left")
        if title:
            ax.set_title(text(title))
        return _save(fig, path)


LABEL_CHARS = 44  # characters of an axis label a line, in one of mas_bars's two 4.5-inch panels


def mas_bars(table, path, title=None, score="mean appropriateness score (MAS)"):
    """Appropriateness (and the dyadic and semantic designs, whose `score` is named for what they ask): each
    system's mean score with its 95% interval (0 = chance), and beside it the shares of answers preferring the
    matched motion, no preference and the mismatched one, as GENEA 2023 draws them."""
    order = list(table["condition"])[::-1]
    col = colours(order)
    rows = table.set_index("condition")
    with matplotlib.rc_context(STYLE):
        fig, (ax, bx) = subplots(1, 2, figsize=(9.0, 0.45 * len(order) + 1.2), sharey=True)
        for i, c in enumerate(order):
            ax.plot([rows.at[c, "ci_low"], rows.at[c, "ci_high"]], [i, i], color=col[c], lw=2)
            ax.plot(rows.at[c, "mas"], i, "o", color=col[c])
            left = 0.0
            for key, colour in zip(
                ("matched", "tie", "mismatched"), (LEVEL_COLOURS[0], LEVEL_COLOURS[2], LEVEL_COLOURS[4])
            ):
                bx.barh(i, rows.at[c, key], left=left, color=colour, height=0.6)
                left += rows.at[c, key]
        ax.set_yticks(range(len(order)))
        ax.set_yticklabels([text(c) for c in order])
        ax.axvline(0, color="black", lw=0.6, ls=":")
        # Each label wrapped to its own axis's width: a long score name (the dyadic design's) ran into its neighbour.
        ax.set_xlabel(textwrap.fill(f"{score}, 95% interval; 0 = chance", LABEL_CHARS))
        bx.set_xlim(0, 1)
        bx.axvline(0.5, color="black", lw=0.6, ls=":")
        bx.set_xlabel(textwrap.fill("share: matched preferred | no preference | mismatched preferred", LABEL_CHARS))
        if title:
            fig.suptitle(text(title))
        return _save(fig, path)


def win_rate_figure(rate, p, conds, path, alpha=0.05):
    """Heat map of the win rate of each row condition over each column condition (ties half), strongest first;
    a star marks a pair whose Holm-adjusted sign test rejects at `alpha`; grey where two conditions never met."""
    import numpy as np

    k = len(conds)
    with matplotlib.rc_context(STYLE):
        fig, ax = subplots(figsize=(1.0 + 0.62 * k, 0.8 + 0.55 * k))
        shown = np.ma.masked_invalid(rate)
        cmap = matplotlib.colormaps["RdBu"].with_extremes(bad="#eeeeee")
        im = ax.imshow(shown, cmap=cmap, vmin=0, vmax=1)
        for i in range(k):
            for j in range(k):
                if i != j and np.isfinite(rate[i, j]):
                    star = "*" if np.isfinite(p[i, j]) and p[i, j] < alpha else ""
                    dark = abs(rate[i, j] - 0.5) > 0.3
                    ax.text(j, i, f"{100 * rate[i, j]:.0f}{star}", ha="center", va="center", fontsize=7,
                            color="white" if dark else "black")  # fmt: skip
        labels = [text(c) for c in conds]
        ax.set_xticks(range(k), labels, rotation=45, ha="right")
        ax.set_yticks(range(k), labels)
        ax.set_xlabel("against (column)")
        ax.set_ylabel("wins of (row)")
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="win rate (ties half)")
        ax.set_title(text(f"win rate, row over column, % (* Holm-adjusted sign test p < {alpha:g})"), fontsize=8)
        return _save(fig, path)
