"""The items of a stimulus set: which held-out windows are shown, and as what (CONTRACTS.md §4).

Test items are held-out 4-s windows of the test split, balanced over locomotion categories (categories in
turn, a window of every take before a second of any), seeded. Catch and familiarisation items come from the
remaining held-out windows, other takes than the test items' first.
"""

import numpy as np

from moglow_eval.core import study
from moglow_eval.core.cli import UserError

TEST, CATCH, TRAINING = study.ROLES  # an item's role is the role of every clip made from it


class ItemError(UserError):
    """More items asked for than the held-out windows hold; the message names the option."""


def balanced_order(labels, takes, rng):
    """All window indices in pick order: categories in turn; within one, a window of every take before
    a second one of any take, takes and windows shuffled."""
    queues = []
    for cat in sorted(set(labels)):
        by_take = {}
        for i in rng.permutation(np.nonzero(labels == cat)[0]):
            by_take.setdefault(takes[i], []).append(int(i))
        groups = list(by_take.values())
        order = [g[r] for r in range(max(map(len, groups))) for g in groups if r < len(g)]
        queues.append(order)
    out = []
    for r in range(max(map(len, queues)) if queues else 0):
        out += [q[r] for q in queues if r < len(q)]
    return out


def select_items(splits, n_items, n_catch, n_training, seed):
    """Items as a list of dicts (id, role, split, index, category, take, start); test items come from the
    test split, catch and training items from its remaining windows, then from the valid split."""
    rng = np.random.default_rng(seed)
    pool = []
    for s in ("test", "valid"):
        if s in splits:
            pool += [(s, i) for i in balanced_order(splits[s]["labels"], splits[s]["take"], rng)]
    n_test_windows = len(splits["test"]["labels"])
    if n_items > n_test_windows:
        raise ItemError(f"--n-items {n_items}: the dataset's test split has only {n_test_windows} windows")
    need = n_items + n_catch + n_training
    if need > len(pool):
        raise ItemError(
            f"{need} items needed but the held-out splits have only {len(pool)} windows; "
            "lower --n-items/--n-catch/--n-training"
        )
    test = pool[:n_items]
    rest = pool[n_items:]
    # Catch and training items: other windows, preferring other takes than the test items'.
    used_takes = {splits[s]["take"][i] for s, i in test}
    rest.sort(key=lambda p: splits[p[0]]["take"][p[1]] in used_takes)  # stable: keeps the balanced order
    roles = [TEST] * n_items + [CATCH] * n_catch + [TRAINING] * n_training
    return [
        dict(
            id=f"{s}{i:04d}",
            role=role,
            split=s,
            index=i,
            category=str(splits[s]["labels"][i]),
            take=str(splits[s]["take"][i]),
            start=int(splits[s]["start"][i]),
        )
        for role, (s, i) in zip(roles, test + rest[: n_catch + n_training])
    ]


def item_arrays(splits, items):
    """Stacked window, control and history arrays of `items` (in order)."""

    def stacked(key):
        return np.stack([splits[it["split"]][key][it["index"]] for it in items])

    return {k: stacked(k) for k in ("x", "c", "hist", "hist_c")}


def positions(items, *roles):
    """Positions in `items` of the items with one of `roles`."""
    return [k for k, it in enumerate(items) if it["role"] in roles]


def category_counts(items, role=TEST):
    """'walk 5, run 4, ...': how many items of `role` each category has."""
    cats, counts = np.unique([it["category"] for it in items if it["role"] == role], return_counts=True)
    return ", ".join(f"{c} {n}" for c, n in zip(cats, counts))
