"""A classifier two-sample test (C2ST; Lopez-Paz & Oquab 2017, "Revisiting classifier two-sample tests", ICLR):
can a small classifier tell a condition's clips from the reference's?

Each clip becomes a vector of summary statistics that any skeleton has (`clip_features`): per joint, the mean and
spread of its position relative to the root, and its log mean speed, acceleration and jerk; per bone, its mean
length and log length spread, read to RESOLUTION (0.1 mm): finer differences are float rounding, not motion. An
L2-regularised logistic regression on standardised features is cross-validated with the folds grouped by item, so
that a clip is always judged by a classifier that saw no clip of its item (otherwise it could learn the items, not
the conditions). The out-of-fold AUC is the figure: 0.5 when the classifier cannot tell the two apart, 1.0 when it
always can. The accuracy at 0.5 is given too.

What it can say: a high AUC shows that the condition differs from the reference in a way these statistics catch, and
the test one feature at a time (`c2st_features`) says where (stretching bones, jerky hands, a posture). What it
cannot: a low AUC does not show that the motion is as good as the reference, only that this classifier, on these
statistics and this many items, finds no difference; a small study (tens of items) has little power, and differences
outside the statistics (timing, intent, how motion fits speech) are invisible to it. It never replaces the raters;
it is an objective check beside them.
"""

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit

from moglow_eval.core import ranks, study
from moglow_eval.core.blas import one_blas_thread

CATCH_ROLE = study.ROLES[1]
EPS = 1e-6
# Metres below which a clip's positions and lengths are taken as equal: a clip file holds float32 metres (about
# 0.1 micrometre of rounding), and a bone set to an actor's length by a fit and a bone of the mocap differ by that
# much. Without it the test told rigid bones apart by their rounding alone (bench/RESULTS.md#c2st).
RESOLUTION = 1e-4
L2 = 1.0  # penalty on the weights of standardised features (per sample), small data's usual choice
MAX_FOLDS = 5


def clip_features(joints, fps, parents):
    """Summary statistics [F] of one clip (joints [T, J, 3], metres, Y up, root first) for the C2ST."""
    joints = np.asarray(joints, dtype=np.float64)
    parents = np.asarray(parents)
    rel = joints.copy()
    rel[..., [0, 2]] -= joints[:, :1, [0, 2]]  # about the root on the floor
    feats = [rel.mean(0).ravel(), np.log(rel.std(0) + RESOLUTION).ravel()]
    for order in (1, 2, 3):
        d = np.linalg.norm(np.diff(joints, n=order, axis=0), axis=-1) * fps**order if len(joints) > order else None
        feats.append(np.log(d.mean(0) + EPS) if d is not None else np.zeros(joints.shape[1]))
    child = np.nonzero(parents >= 0)[0]
    if len(child):
        length = np.linalg.norm(joints[:, child] - joints[:, parents[child]], axis=-1)
        mean, spread = (np.round(v / RESOLUTION) * RESOLUTION for v in (length.mean(0), length.std(0)))
        feats += [mean, np.log(spread + RESOLUTION)]
    return np.concatenate(feats)


def _fit_logistic(x, y, l2=L2):
    """Weights [F + 1] (bias last) of an L2-regularised logistic regression; x standardised [N, F], y in {0, 1}."""
    n, f = x.shape
    xb = np.hstack([x, np.ones((n, 1))])

    def loss(w):
        z = xb @ w
        nll = np.logaddexp(0, z).sum() - y @ z
        g = xb.T @ (expit(z) - y)
        reg = 0.5 * l2 * (w[:f] @ w[:f])
        g[:f] += l2 * w[:f]
        return (nll + reg) / n, g / n

    return minimize(loss, np.zeros(f + 1), jac=True, method="L-BFGS-B").x


def auc(scores, labels):
    """Area under the ROC curve: the chance that a random positive scores above a random negative (ties half)."""
    scores, labels = np.asarray(scores, float), np.asarray(labels, bool)
    return ranks.auc(scores[labels], scores[~labels])


def grouped_cv(x, y, groups, seed=0, folds=MAX_FOLDS):
    """(out-of-fold AUC, accuracy) of the classifier on features x [N, F], labels y [N], folds grouped by
    `groups` [N] (items), the groups dealt to folds at random by `seed`."""
    x, y, groups = np.asarray(x, float), np.asarray(y, float), np.asarray(groups)
    names = np.unique(groups)
    k = min(folds, len(names))
    if k < 2:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    fold_of = dict(zip(names[rng.permutation(len(names))], np.arange(len(names)) % k))
    fold = np.array([fold_of[g] for g in groups])
    prob = np.empty(len(y))
    with one_blas_thread():  # small products, fitted hundreds of times a build (moglow_eval.core.blas)
        for f in range(k):
            train, test = fold != f, fold == f
            mu, sd = x[train].mean(0), x[train].std(0) + EPS
            w = _fit_logistic((x[train] - mu) / sd, y[train])
            prob[test] = expit(np.hstack([(x[test] - mu) / sd, np.ones((test.sum(), 1))]) @ w)
    return auc(prob, y), float(((prob > 0.5) == (y > 0.5)).mean())


def labelled(reference, other):
    """(features [N, F], labels [N]: 0 the reference, 1 the other, items [N]) of two sets {item: features [F]},
    each in item order: what the classifier is cross-validated on, its folds grouped by item."""
    ref_items, items = sorted(reference), sorted(other)
    x = np.array([reference[i] for i in ref_items] + [other[i] for i in items], dtype=float)
    y = np.r_[np.zeros(len(ref_items)), np.ones(len(items))]
    return x, y, np.array(ref_items + items)


def c2st(reference, other, seeds=5):
    """C2ST of `other` against `reference`, each {item: features [F]}: an item's clips in both sit in one fold.

    Returns dict(n_items (of `other`), auc, auc_sd, accuracy): means (and the AUC's sd) over `seeds` random fold
    deals."""
    x, y, groups = labelled(reference, other)
    runs = np.array([grouped_cv(x, y, groups, seed=s) for s in range(seeds)])
    return dict(
        n_items=len(other),
        auc=float(runs[:, 0].mean()),
        auc_sd=float(runs[:, 0].std()),
        accuracy=float(runs[:, 1].mean()),
    )


def c2st_self(reference, seeds=10):
    """The reference against itself: its items split at random into two halves, labelled as two conditions, in
    grouped cross-validation; the mean AUC over `seeds` splits. Near 0.5 by design: the floor of the test."""
    items = sorted(reference)
    x = np.array([reference[i] for i in items])
    aucs = []
    for s in range(seeds):
        y = np.zeros(len(items))
        y[np.random.default_rng(1000 + s).permutation(len(items))[: len(items) // 2]] = 1
        aucs.append(grouped_cv(x, y, np.array(items), seed=s)[0])
    return dict(n_items=len(items), auc=float(np.mean(aucs)), auc_sd=float(np.std(aucs)), accuracy=float("nan"))


def collect(feats, condition, role, item, joints, fps, parents):
    """Add a clip's features to `feats` ({key: {item: features}}) where c2st_table needs them: test clips under
    their condition, and the catch items' NAT and BAD clips under `NAT:catch` and `BAD:catch`."""
    if role == study.ROLES[0]:
        feats.setdefault(condition, {})[item] = clip_features(joints, fps, parents)
    elif role == CATCH_ROLE and condition in (study.NATURAL, study.CATCH):
        feats.setdefault(f"{condition}:{CATCH_ROLE}", {})[item] = clip_features(joints, fps, parents)


def pairs(feats):
    """(condition, reference features, condition's features) of every test `collect` gathered: each condition's
    test clips against the reference's, then BAD against the reference clips of the test and catch items."""
    ref = feats.get(study.NATURAL, {})
    out = [(c, ref, feats[c]) for c in study.condition_order(k for k in feats if ":" not in k) if c != study.NATURAL]
    if f"{study.CATCH}:{CATCH_ROLE}" in feats:
        catch_ref = {**feats[f"{study.NATURAL}:{CATCH_ROLE}"], **ref}
        out.append((study.CATCH, catch_ref, feats[f"{study.CATCH}:{CATCH_ROLE}"]))
    return out


def c2st_table(feats):
    """c2st.csv's rows (CONTRACTS §4) from `collect`'s features: the tests of `pairs`, after the reference against
    itself split by item (the test's floor, named `NAT:split`)."""
    rows = [dict(condition=f"{study.NATURAL}:split", **c2st_self(feats.get(study.NATURAL, {})))]
    rows += [dict(condition=cond, **c2st(ref, other)) for cond, ref, other in pairs(feats)]
    return [{k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows]


def c2st_text(table):
    """c2st_table's rows as lines for a command's summary."""
    lines = [
        "classifier two-sample test against the reference (AUC: 0.5 = indistinguishable, 1 = always told apart; "
        "NAT:split is the reference against itself)"
    ]
    lines += [f"  {r['condition']:<12} AUC {r['auc']} (sd {r['auc_sd']}) over {r['n_items']} items" for r in table]
    return "\n".join(lines)
