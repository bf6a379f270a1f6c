"""Why the classifier two-sample test tells a condition from the reference: the test one feature at a time.

`c2st` says whether a classifier tells a condition's clips from the reference's; this module says how. Every value
of `c2st.clip_features` gets a name and a group (`feature_names`), and for each condition against the reference:
- each single feature's AUC: the chance that a random clip of the condition has a higher value than a random
  clip of the reference, read direction-free as max(a, 1 - a), with the direction (`higher` or `lower` in the
  condition) beside it. No classifier is fitted, so nothing is cross-validated; a feature's AUC is only the overlap
  of the two sets' values (with tens of items, about 0.6-0.65 arises by chance in a feature that does not differ);
- each group's AUC: the same cross-validated logistic regression as the whole test's (`c2st.grouped_cv`, folds
  grouped by item), on that group's features alone.
The groups follow the layout of `clip_features`: position mean, position spread (about the root on the floor),
speed, acceleration, jerk, bone length, bone length spread. It works for any skeleton: the names come from the
clips' joint names and parents. `make_stimuli` and a study of your own motion write it as `c2st_features.csv`
(CONTRACTS §4) and print the strongest features per condition.
"""

import numpy as np

from moglow_eval.core import study

from . import c2st

GROUPS = (
    "position mean",
    "position spread",
    "speed",
    "acceleration",
    "jerk",
    "bone length",
    "bone length spread",
)
FEATURE_COLUMNS = ("condition", "kind", "feature", "group", "auc", "direction")  # c2st_features.csv
KIND_FEATURE, KIND_GROUP = "feature", "group"
TOP = 3  # features printed per condition in a job's summary


def feature_names(joint_names, parents):
    """(names, groups): one name and one group (GROUPS) per value of `c2st.clip_features`, in its order."""
    joint_names, parents = [str(n) for n in joint_names], np.asarray(parents)
    names, groups = [], []

    def add(group, items):
        names.extend(items)
        groups.extend([group] * len(items))

    add(GROUPS[0], [f"{j} {a} mean" for j in joint_names for a in "xyz"])
    add(GROUPS[1], [f"{j} {a} spread" for j in joint_names for a in "xyz"])
    for group in GROUPS[2:5]:
        add(group, [f"{j} {group}" for j in joint_names])
    bones = [f"{joint_names[parents[k]]}-{joint_names[k]}" for k in np.nonzero(parents >= 0)[0]]
    if bones:
        add(GROUPS[5], [f"{b} length" for b in bones])
        add(GROUPS[6], [f"{b} length spread" for b in bones])
    return names, groups


def single_aucs(x, y):
    """Per column of x [N, F], the AUC of that value alone for labels y [N] (1: the condition): a [F] as is (above
    0.5: higher in the condition)."""
    x, y = np.asarray(x, float), np.asarray(y, bool)
    return np.array([c2st.auc(x[:, f], y) for f in range(x.shape[1])])


def feature_report(reference, other, names, groups, seeds=5):
    """Rows (kind, feature, group, auc, direction) of `other` against `reference` (each {item: features [F]}): a
    row per group (its cross-validated AUC, mean over `seeds` fold deals; feature and direction empty), then a row
    per feature (direction-free AUC and direction), strongest first within each kind."""
    x, y, item_groups = c2st.labelled(reference, other)
    if x.shape[1] != len(names):
        raise ValueError(f"feature_report: {x.shape[1]} features but {len(names)} names")
    groups = np.asarray(groups)
    rows = []
    for g in GROUPS:
        cols = groups == g
        if cols.any():
            a = np.mean([c2st.grouped_cv(x[:, cols], y, item_groups, seed=s)[0] for s in range(seeds)])
            rows.append(dict(kind=KIND_GROUP, feature="", group=g, auc=float(a), direction=""))
    rows.sort(key=lambda r: -r["auc"])
    a = single_aucs(x, y)
    feats = [
        dict(kind=KIND_FEATURE, feature=n, group=g, auc=float(max(v, 1 - v)), direction=_direction(v))
        for n, g, v in zip(names, groups, a)
        if np.isfinite(v)
    ]
    return rows + sorted(feats, key=lambda r: -r["auc"])


def _direction(a):
    """How the condition differs in a feature whose AUC is `a`: `higher`, `lower`, or empty when not at all."""
    return "higher" if a > 0.5 else "lower" if a < 0.5 else ""


def feature_table(feats, joint_names, parents):
    """c2st_features.csv's rows (CONTRACTS §4) from `c2st.collect`'s features: each condition's report against the
    reference, paired as in `c2st.c2st_table` (BAD against the reference clips of the test and catch items)."""
    names, groups = feature_names(joint_names, parents)
    rows = []
    for cond, ref, other in c2st.pairs(feats):
        rows += [dict(condition=cond, **r) for r in feature_report(ref, other, names, groups)]
    return [{k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows]


def feature_text(table, top=TOP):
    """Lines for a job's summary: per condition other than BAD, its strongest group and its `top` features."""
    lines = ["what tells each condition from the reference (c2st_features.csv): the strongest group, then features"]
    for cond in dict.fromkeys(r["condition"] for r in table):
        if cond == study.CATCH:
            continue
        rows = [r for r in table if r["condition"] == cond]
        best = [r for r in rows if r["kind"] == KIND_GROUP][:1]
        feats = [r for r in rows if r["kind"] == KIND_FEATURE][:top]
        words = [f"{r['group']} {r['auc']}" for r in best]
        words += [f"{r['feature']} {r['auc']} ({r['direction'] or 'no difference'})" for r in feats]
        lines.append(f"  {cond:<12} " + "; ".join(words))
    return "\n".join(lines)
